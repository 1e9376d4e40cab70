"""The error-vs-time report: a cached reference, ladders, metrics and its files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import StageSpec, add_atmosphere, look_rotation, write_stage

from evaluation.error_vs_time import error_metrics, run_report, write_outputs
from warpsky.core.errors import UsageError
from warpsky.usd.stage import StageReader


def test_error_metrics_closed_forms():
    reference = np.ones((4, 4, 3))
    covered = np.zeros((4, 4), dtype=bool)
    covered[1:3, 1:3] = True
    image = reference * 1.1
    m = error_metrics(image, reference, covered)
    assert m["rel_rmse"] == pytest.approx(0.1) and m["bias"] == pytest.approx(0.1)
    assert m["mean_rel"] == pytest.approx(0.1) and m["p95_rel"] == pytest.approx(0.1)
    assert np.isnan(m["net_rmse"])
    # a reference whose own noise explains the whole difference: no error is left
    net = error_metrics(image, reference, covered, reference_variance=np.full((4, 4, 3), 0.01))
    assert net["net_rmse"] == pytest.approx(0.0, abs=1e-6) and net["rel_rmse"] == pytest.approx(0.1)
    half = error_metrics(image, reference, covered, reference_variance=np.full((4, 4, 3), 0.0075))
    assert half["net_rmse"] == pytest.approx(0.05)
    with pytest.raises(UsageError, match="covers no pixel"):
        error_metrics(image, reference, np.zeros((4, 4), dtype=bool))


def test_report_on_a_box(tmp_path, homogeneous_npy, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.3, camera_position=(0.0, 0.0, 40.0),
                     camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(0.3, 0.8, 0.5))
    scene = StageReader(write_stage(tmp_path / "box.usda", spec)).scene_at(None)
    logs = []
    report = run_report(scene, techniques=["single_scatter", "path_tracer"], width=12, height=12, device="cpu",
                        budget=2.0, reference_spp=256, log=logs.append)
    assert "reference: path_tracer 256 spp" in logs[0] and "cache" not in logs[0]
    techniques = {r.technique for r in report.rows}
    assert techniques == {"single_scatter", "path_tracer"}
    single = [r for r in report.rows if r.technique == "single_scatter"]
    # optical thickness 6 at albedo 1: single scattering misses most of the light, whatever its step
    assert all(r.bias < -0.3 for r in single)
    traced = [r for r in report.rows if r.technique == "path_tracer"]
    assert abs(traced[-1].bias) < 0.1 and traced[-1].rel_rmse < traced[0].rel_rmse
    paths = write_outputs(report, tmp_path / "out")
    assert [p.suffix for p in paths] == [".csv", ".json", ".png"] and all(p.stat().st_size > 0 for p in paths)
    blob = json.loads(paths[1].read_text())
    assert blob["rows"][0]["technique"] == "single_scatter" and "first-compile" in blob["note"]
    again = run_report(scene, techniques=["single_scatter"], width=12, height=12, device="cpu", budget=0.1,
                       reference_spp=256, log=logs.append)
    assert again.reference["cached"] and "loaded from cache" in logs[-len(again.rows) - 1]


def test_report_refuses_unknown_techniques(tmp_path, homogeneous_npy):
    scene = StageReader(write_stage(tmp_path / "b.usda", StageSpec(volume_file=homogeneous_npy))).scene_at(None)
    with pytest.raises(UsageError, match="raymarch_fast"):
        run_report(scene, techniques=["raymarch_fast"], width=8, height=8, device="cpu")


def test_report_on_a_scene_with_sky(tmp_path, homogeneous_npy, monkeypatch):
    """With an atmosphere the techniques compare on frames: single scattering + sky pass vs the path tracer that
    traces the air; the sky pixels agree, so the error comes from the cloud."""
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.02, camera_position=(0.0, 30.0, 40.0),
                     camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(0.3, 0.8, 0.5))
    scene = StageReader(add_atmosphere(write_stage(tmp_path / "sky.usda", spec))).scene_at(None)
    report = run_report(scene, techniques=["single_scatter"], width=8, height=8, device="cpu", budget=0.5,
                        reference_spp=256, log=lambda text: None)
    assert report.reference["covered_pixels"] >= 48  # the sky covers the frame (rows looking at the sea: dark)
    assert all(np.isfinite(r.rel_rmse) for r in report.rows)
    assert abs(report.rows[-1].bias) < 0.5
