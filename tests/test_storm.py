"""The storm stage (cloud, rain, snow, ice) written by tools/make_storm.py renders with slicing by default."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from warpsky.cli.main import main
from warpsky.output.exr import read_exr

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import make_storm  # noqa: E402


@pytest.mark.slow
def test_storm_stage_renders_with_slicing(tmp_path, species_phase, capsys):
    for name in ("cloud", "rain", "snow", "ice"):
        species_phase(name)  # tables from the session cache
    frames = 4
    make_storm.write_frames(tmp_path / "data", frames, res=16, only=[frames])  # the last frame: every field present
    stage = make_storm.write_stage(tmp_path / "storm.usda", tmp_path / "data", frames)
    assert main(["info", str(stage), "--time", str(frames)]) == 0
    info = capsys.readouterr().out
    assert "technique   hybrid" in info  # the default; make storm asks for slicing, as below
    for name in ("cloud", "rain", "snow", "ice"):
        assert name in info
    out = tmp_path / "out" / "storm.####.exr"
    assert main(["render", str(stage), str(out), "--frames", str(frames), "--res", "48x32", "--device", "cpu",
                 "--technique", "slicing"]) == 0
    image = read_exr(tmp_path / "out" / f"storm.{frames:04d}.exr")
    assert image.metadata["technique"] == "slicing" and image.metadata["camera"] == "/World/RainbowCam"
    rgba = image.rgba()
    assert np.all(np.isfinite(rgba)) and rgba.min() >= 0.0
    assert rgba[..., :3].mean() > 0.0 and '"light_equation": 0' in image.metadata["settings"]
