"""Golden images: every shipped stage rendered small by every technique matches tests/golden/ to 1e-6 relative.

The goldens are written by ``python tools/make_goldens.py`` (see its docstring); this test never rewrites them. A
change meant to keep pixels (a refactor) must pass it untouched; a change meant to alter them regenerates the
goldens in the same commit and says why.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import make_goldens  # noqa: E402

#: Largest difference allowed, relative to the golden's largest magnitude in each output (RGBA, transmittance,
#: depth); arithmetic unchanged in order gives 0.
TOLERANCE = 1e-6


def _params():
    """Every case; the storm's and the stratocumulus' are marked slow (they build the rain, snow and ice tables, and
    the stratus phase and modified Mie tables: about 30 s)."""
    return [pytest.param(c, id=c.name, marks=[pytest.mark.slow] if c.stage in ("storm", "stratocumulus") else [])
            for c in make_goldens.CASES]


@pytest.fixture(scope="module")
def golden_inputs(tmp_path_factory, optics_cache):
    folder = tmp_path_factory.mktemp("golden")
    return folder, make_goldens.write_inputs(folder)


@pytest.mark.parametrize("case", _params())
def test_golden_image(case, golden_inputs, species_phase):
    if case.stage == "storm":
        for name in make_goldens.SPECIES:
            species_phase(name)  # tables from the session cache
    folder, stages = golden_inputs
    stored = dict(np.load(make_goldens.GOLDEN / f"{case.name}.npz"))
    actual = make_goldens.render_case(case, stages, folder)
    for key, expected in stored.items():
        assert actual[key].shape == expected.shape, key
        assert np.all(np.isfinite(actual[key])), key
    assert make_goldens.largest_difference(actual, stored) <= TOLERANCE
