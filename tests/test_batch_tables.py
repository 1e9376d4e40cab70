"""Optics tables for a batch are built once, by the client, before any frame is dispatched, and say so."""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import StageSpec, add_field, write_stage

from warpsky.batch.run import FrameJob, InProcessExecutor, run_batch
from warpsky.optics import tables
from warpsky.optics.grid import angle_grid
from warpsky.optics.species import Species
from warpsky.render.options import RenderOptions


class DispatchRecorder(InProcessExecutor):
    """Runs frames in this process and records, when the frames are handed over, which tables are cached."""

    def __init__(self, kinds):
        self.kinds = kinds
        self.cached_at_dispatch = []

    def map(self, jobs, attempt):
        self.cached_at_dispatch.append({kind: tables.is_cached("cloud", kind, extra) for kind, extra in self.kinds})
        yield from super().map(jobs, attempt)


@pytest.mark.parametrize(("technique", "settings", "kinds"), [
    ("single_scatter", {}, [("phase", "")]),
    ("slicing", {"orders": "4", "slice_count": "8", "light_resolution": "8"}, [("phase", ""), ("ams", "4")]),
])


def test_two_frame_batch_builds_each_table_once_before_dispatch(tmp_path, monkeypatch, capsys, homogeneous_npy,
                                                                technique, settings, kinds):
    """A fresh cache, a stage with a cloud field and two frames: the client builds the cloud tables the plan
    needs (a cheap isotropic phase stands in for Mie) before handing frames over, each once, with a progress line;
    the frames then load them. Workers used to build them on their first frame, all at once."""
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    built = []

    def isotropic_phase(species):
        built.append(species.name)
        return np.full((3, angle_grid().size), 1.0 / (4.0 * np.pi))

    monkeypatch.setattr(Species, "build_phase", isotropic_phase)
    monkeypatch.setattr(tables, "BUILD_LOG", [])
    stage = write_stage(tmp_path / "cloud.usda", StageSpec(volume_file=homogeneous_npy, extinction_scale=0.0))
    add_field(stage, "cloud", homogeneous_npy, scale=0.1)
    options = RenderOptions(technique=technique, settings=settings, resolution=(8, 8))
    jobs = [FrameJob(str(stage), float(t), str(tmp_path / f"out.{t}.exr"), options) for t in (1, 2)]
    executor = DispatchRecorder(kinds)
    result = run_batch(str(stage), jobs, executor, log=tmp_path / "out.log.json")
    assert [r.status for r in result.records] == ["done", "done"], [r.error for r in result.records]
    assert executor.cached_at_dispatch == [{kind: True for kind, _ in kinds}]
    assert built == ["cloud"]
    assert sorted(kind for _, kind, _ in tables.BUILD_LOG) == sorted(kind for kind, _ in kinds)
    err = capsys.readouterr().err
    assert err.count("warpsky: building cloud phase table (≈ ") == 1 and "s, once; then loaded from" in err, err
    if technique == "slicing":
        assert err.count("building cloud multiple-scattering (Ams) table (about a second, once;") == 1, err


def test_first_run_says_it_compiles_kernels(tmp_path, monkeypatch):
    """With no variant of slicing's kernels in Warp's kernel cache the first run says it compiles them; one cached
    variant is enough to stay quiet."""
    import warp as wp

    from warpsky.render.kernel_cache import compile_notice, technique_kernel_modules, variant_module_names
    from warpsky.render.registry import technique_names

    assert all(technique_kernel_modules(name) for name in technique_names())

    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    notice = compile_notice("slicing")
    assert notice is not None and notice.startswith("compiling Warp kernels for slicing (first run"), notice
    # the estimate: Warp's generated C++ of slicing's two kernel factories, measured at 0.8 and 0.5 s on 2 cores
    seconds = float(re.search(r"about (\d+) s on this CPU", notice).group(1))
    assert 0 <= seconds <= 10, notice
    (tmp_path / f"wp_{variant_module_names('slicing')[0]}_0123abc").mkdir()
    assert compile_notice("slicing") is None
    assert compile_notice("no_such_technique") is None
