"""``warpsky bench speed``: the rows it plans per device, the table's columns, the JSON, and its usage errors."""

from __future__ import annotations

import json
import re

from conftest import StageSpec, look_rotation, write_stage

from evaluation.speed import STRATIFORM, monte_carlo, plan_rows
from evaluation.speed_table import COLUMNS, format_table
from warpsky.cli.main import main
from warpsky.core.image import ImageLayer


def _box_stage(tmp_path, volume):
    spec = StageSpec(volume_file=volume, extinction_scale=0.3, camera_position=(0.0, 0.0, 40.0),
                     camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(0.3, 0.8, 0.5))
    return write_stage(tmp_path / "box.usda", spec)


def test_speed_table_and_json(tmp_path, homogeneous_npy, device, capsys):
    stage = _box_stage(tmp_path, homogeneous_npy)
    out = tmp_path / "speed.json"
    code = main(["bench", "speed", "--stages", str(stage), "--techniques", "single_scatter,path_tracer",
                 "--devices", device, "--res", "8", "--gpu-res", "8", "--frames", "1", "--spp", "2", "--threads", "1",
                 "--json", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    header = printed.splitlines()[0].split()
    assert " ".join(header) == " ".join(COLUMNS)
    rows = json.loads(out.read_text())["rows"]
    assert [r["technique"] for r in rows] == ["single_scatter", "path_tracer"]
    for row in rows:
        assert row["device"] == device and row["warm_ms"] > 0.0 and row["cold_ms"] > 0.0
        assert re.fullmatch(r"cache: \d+ modules?|compiled \d+ of \d+ modules?", row["cold_kernels"])
        assert (row["threads"] == 1) == (device == "cpu")
        assert (row["kernel_ms"] is None) == (device == "cpu")
    traced = rows[1]
    assert traced["settings"] == {"spp": "2", "seed": "0"} and traced["resolved_settings"]["spp"] == 2
    assert traced["paths_per_frame"] == 2 * traced["width"] * traced["height"] and traced["paths_per_s"] > 0.0
    per_path = traced["per_path"]
    assert per_path["steps"] >= per_path["shadow_steps"] > 0.0 and per_path["events"] > 0.0
    assert rows[0]["paths_per_s"] is None and rows[0]["per_path"] is None
    assert str(out) in printed


def test_unknown_technique_is_a_usage_error(capsys):
    code = main(["bench", "speed", "--techniques", "slicing,raymarcher", "--devices", "cpu"])
    assert code == 2
    assert "raymarcher" in capsys.readouterr().err
    assert main(["bench", "speed", "--techniques", "slicing", "--devices", "cuda:64"]) == 2
    assert "cuda:64" in capsys.readouterr().err


def test_rows_per_device_and_thread_count(tmp_path, homogeneous_npy):
    """CUDA rows take the GPU size and no thread count; the stratiform pass is skipped on a stage without layers."""
    stage = _box_stage(tmp_path, homogeneous_npy)
    logs = []
    rows = plan_rows([stage], ["slicing", "hybrid", STRATIFORM], ["cpu", "cuda:0"], cpu_res=(16, None),
                     gpu_res=(64, 32), threads=[1, 2], frames=1, spp=4, log=logs.append)
    assert [(r.device, r.threads, r.technique) for r in rows] == [
        ("cpu", 1, "slicing"), ("cpu", 1, "hybrid"), ("cpu", 2, "slicing"), ("cpu", 2, "hybrid"),
        ("cuda:0", None, "slicing"), ("cuda:0", None, "hybrid")]
    assert {(r.width, r.height) for r in rows if r.device == "cuda:0"} == {(64, 32)}
    assert rows[1].settings == {"spp": "4", "target_error": "0", "seed": "0"} and rows[0].settings == {}
    assert any("stratiform" in line and "no stratiform layers" in line for line in logs)


def test_table_cells_by_device():
    base = {"stage": "/x/cumulus.usda", "technique": "hybrid", "width": 8, "height": 6, "cold_ms": 900.0,
            "cold_kernels": "cache: 3 modules", "warm_ms": 20.0, "fps": 50.0, "peak_mib": 300.0,
            "paths_per_s": 2.5e6, "settings": {"spp": "16"}}
    cpu = {**base, "device": "cpu", "threads": 2, "kernel_ms": None, "copy_ms": None}
    gpu = {**base, "device": "cuda:0", "threads": None, "kernel_ms": 1.25, "copy_ms": 0.5}
    failed = {**base, "device": "cpu", "threads": 1, "error": "exit 1: boom"}
    lines = format_table([cpu, gpu, failed]).splitlines()
    assert "n/a" in lines[1] and "2.50" in lines[1] and "spp=16" in lines[1]
    assert "1.25" in lines[2] and "0.50" in lines[2] and "n/a" not in lines[2]
    assert "failed" in lines[3] and "boom" in lines[3]


def test_monte_carlo_time_of_hybrid_leaves_out_the_march_and_the_denoiser():
    layer = ImageLayer(None, None, None, stats={"paths": 1000, "seconds": 1.0, "single_scatter_seconds": 0.25,
                                           "denoise_seconds": 0.25})
    assert monte_carlo(layer) == (1000, 0.5)
    assert monte_carlo(ImageLayer(None, None, None, stats={"seconds": 1.0})) is None


def test_stratiform_row_times_the_pass_alone(tmp_path, capsys):
    """The stratiform row renders the stratiform pass on its own and reports it like a technique's row."""
    from test_stratiform_scene import write_layer_stage

    stage = write_layer_stage(tmp_path / "layer.usda")
    out = tmp_path / "speed.json"
    code = main(["bench", "speed", "--stages", str(stage), "--techniques", STRATIFORM, "--devices", "cpu",
                 "--res", "8", "--frames", "1", "--threads", "1", "--json", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    (row,) = json.loads(out.read_text())["rows"]
    assert row["technique"] == STRATIFORM and "error" not in row and row["warm_ms"] > 0.0, row
    assert row["paths_per_s"] is None
