"""Optics tables for a batch are built once, by the client, before any frame is dispatched, and say so."""

from __future__ import annotations

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
