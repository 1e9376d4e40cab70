"""``warpsky simulate``: a small run writes per-frame NanoVDB grids and a stage warpsky reads, frame by frame; a run
that fails part way keeps the frames it finished; bad arguments exit 2 naming the culprit."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.cli.main import main

SMALL = ["--grid", "12x12x16", "--dx", "1000", "--dz", "500", "--time-step", "10", "--device", "cpu"]


def test_simulate_writes_frames_and_a_stage_that_renders(tmp_path, capsys):
    """Two frames over 4 minutes: every field's grid per frame, the sounding, and a stage whose Volume has the
    species and the velocity, time-sampled per frame; ``warpsky info`` reads it."""
    assert main(["simulate", *SMALL, "--frames", "2", "--minutes", "4", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr()
    assert "2 frames over 4.0 min" in out.out and "frame 2/2" in out.err
    names = sorted(p.name for p in (tmp_path / "storm").iterdir())
    assert names == sorted(f"{f}.{n:04d}.nvdb" for f in ("cloud", "rain", "ice", "snow", "velocity") for n in (1, 2))
    assert (tmp_path / "storm.input_sounding").read_text().split()[:3] == ["1000.000", "300.0000", "14.00000"]
    text = (tmp_path / "storm.usda").read_text()
    assert "field:velocity" in text and "storm/cloud.0002.nvdb" in text and "endTimeCode = 2" in text
    assert main(["info", str(tmp_path / "storm.usda")]) == 0
    assert "/World/Weather:cloud" in capsys.readouterr().out


def test_a_velocity_frame_holds_the_solvers_wind(tmp_path):
    """The velocity grid is the solver's wind on the meteorological axes: the sounding's 15 tanh(z / 3 km) m/s
    along +x far from the bubble, read back from the NanoVDB file."""
    from warpsky.media.voxels.fields import load_vector_field

    assert main(["simulate", *SMALL, "--frames", "1", "--minutes", "1", "--out", str(tmp_path)]) == 0
    grid = load_vector_field(tmp_path / "storm" / "velocity.0001.nvdb")
    values = grid.values
    assert values.shape[-1] == 3
    z_index = np.arange(values.shape[2])
    heights = (grid.local_from_index @ np.c_[np.zeros((len(z_index), 2)), z_index, np.ones(len(z_index))].T)[2]
    corner = values[2, 2, :, 0]  # the first data column (the file pads the grid), far from the bubble
    inside = (heights > 0.0) & (heights < 8000.0)
    np.testing.assert_allclose(corner[inside], 15.0 * np.tanh(heights[inside] / 3000.0), atol=0.5)


def test_a_failed_frame_keeps_the_finished_ones(tmp_path, monkeypatch):
    """A write that fails on frame 2 leaves frame 1's grids and a stage of frame 1, and no temporary files."""
    from warpsky.simulate import frames

    real = frames.write_grid
    calls = []

    def failing(path, *args):
        calls.append(path)
        if ".0002." in path.name:
            raise OSError(28, "No space left on device")
        return real(path, *args)

    monkeypatch.setattr(frames, "write_grid", failing)
    with pytest.raises(OSError):
        from warpsky.simulate.run import simulate
        from warpsky.simulate.solver import SimulationSettings
        from warpsky.simulate.sounding import weisman_klemp

        simulate(weisman_klemp(), SimulationSettings(nx=12, ny=16, nz=12, dx=1000.0, dy=500.0, time_step=10.0),
                 frames=3, minutes=3.0, out=tmp_path, device="cpu")
    files = sorted(p.name for p in tmp_path.rglob("*") if p.is_file())
    assert "cloud.0001.nvdb" in files and "velocity.0001.nvdb" in files and not any("tmp" in f for f in files)
    text = (tmp_path / "storm.usda").read_text()
    assert "cloud.0001.nvdb" in text and ".0002.nvdb" not in text and "endTimeCode = 1" in text


@pytest.mark.parametrize("args, message", [(["--grid", "12x12"], "--grid takes"),
                                           (["--grid", "4x12x12"], "at least 8 cells"),
                                           (["--frames", "0"], "--frames must be"),
                                           (["--dz", "2000"], "the sounding ends at")])
def test_bad_arguments_exit_2_naming_them(tmp_path, capsys, args, message):
    assert main(["simulate", *SMALL, *args, "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err
