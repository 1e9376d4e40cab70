"""``warpsky simulate``: a small run writes per-frame NanoVDB grids and a stage warpsky reads, frame by frame; a run
that fails part way keeps the frames it finished; bad arguments exit 2 naming the culprit."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.cli.main import main

SMALL = ["--grid", "12x12x16", "--dx", "1000", "--dz", "500", "--time-step", "10", "--device", "cpu"]


def test_simulate_writes_frames_and_a_stage_that_renders(tmp_path, capsys):
    """Two frames over 4 minutes: every field's grid per frame, the sounding, and a stage whose Volume has the
    species, the velocity (time-sampled per frame) and render-time detail, with the overview camera and the rainbow
    shot, its default; ``warpsky info`` reads it."""
    assert main(["simulate", *SMALL, "--frames", "2", "--minutes", "4", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr()
    assert "2 frames over 4.0 min" in out.out and "frame 2/2" in out.err
    names = sorted(p.name for p in (tmp_path / "storm").iterdir())
    assert names == sorted(f"{f}.{n:04d}.nvdb" for f in ("cloud", "rain", "ice", "snow", "velocity") for n in (1, 2))
    assert (tmp_path / "storm.input_sounding").read_text().split()[:3] == ["1000.000", "300.0000", "14.00000"]
    text = (tmp_path / "storm.usda").read_text()
    assert "field:velocity" in text and "storm/cloud.0002.nvdb" in text and "endTimeCode = 2" in text
    assert "warpsky:detail:amplitude = 0.35" in text and "def Camera \"Camera\"" in text
    assert main(["info", str(tmp_path / "storm.usda")]) == 0
    info = capsys.readouterr().out
    assert "/World/Weather:cloud" in info and "RainbowCam" in info


@pytest.mark.parametrize("speed", [(0.0, 0.0), (4.0, -2.0)])
def test_a_frame_holds_the_solvers_wind_on_meteorological_axes_around_the_media(tmp_path, speed):
    """The solver's (x, up, z) fields become the stage's (east, north, up) grids: a cloud blob at solver cell
    (5, 3, 7) is at east 5, north 7, level 3 in the cloud grid, and the velocity file holds (u, v, w) = the solver's
    (x, z, up) components within 2 cells of the blob and nothing far from it (the sparse velocity grid). On a grid
    moving at (u, v) along (x, z) the frame at t = 60 s lies (60 u, 60 v) further on and its wind is the solver's
    plus (u, v)."""
    from warpsky.media.voxels.fields import load_field, load_vector_field
    from warpsky.simulate.frames import FrameWriter, weather_state
    from warpsky.simulate.sounding import base_state, weisman_klemp

    shape = (10, 8, 12)
    base = base_state(weisman_klemp(), shape[1], 500.0)
    fields = {"theta": np.broadcast_to(base.theta[None, :, None], shape).copy(),
              "vapour": np.broadcast_to(base.vapour[None, :, None], shape).copy(),
              "cloud": np.zeros(shape), "rain": np.zeros(shape)}
    fields["cloud"][5, 3, 7] = 1.0e-3
    fields["velocity"] = np.broadcast_to(np.array([1.0, 2.0, 3.0], np.float32), (*shape, 3)).copy()
    state = weather_state(fields, base, (1000.0, 500.0), 60.0, speed)
    FrameWriter(tmp_path / "f", tmp_path / "f.usda", 60.0).write(state)
    cloud = load_field(tmp_path / "f" / "cloud.0001.nvdb")
    lit = np.argwhere(cloud.values > 0.0)
    assert len(lit) == 1
    centre = cloud.local_from_index @ np.r_[lit[0], 1.0]
    moved = [60.0 * speed[0], 60.0 * speed[1], 0.0]
    np.testing.assert_allclose(centre[:3], np.add([500.0, 1500.0, 1750.0], moved))  # east 5.5 - 5, north 7.5 - 6 km
    velocity = load_vector_field(tmp_path / "f" / "velocity.0001.nvdb")
    moving = np.argwhere(np.linalg.norm(velocity.values, axis=-1) > 0.0)
    wind = [1.0 + speed[0], 3.0 + speed[1], 2.0]
    np.testing.assert_allclose(velocity.values[tuple(moving.T)], np.tile(wind, (len(moving), 1)), rtol=1e-6)
    spread = np.abs(moving - lit[0]).max(axis=0)
    np.testing.assert_array_equal(spread, [2, 2, 2])


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
                                           (["--dz", "2000"], "the sounding ends at"),
                                           (["--domain-speed", "10"], "--domain-speed takes U,V")])
def test_bad_arguments_exit_2_naming_them(tmp_path, capsys, args, message):
    assert main(["simulate", *SMALL, *args, "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_a_frame_records_each_species_water_and_its_extinction_agrees(tmp_path):
    """The stage records the cloud's peak water content and total water per frame; the peak agrees with the
    written extinction grid's peak through beta = 3 W / (2 rho_w r_e) (droplets of 10 um), and the total with one
    cell of 1 km x 1 km x 500 m holding it."""
    from warpsky.media.voxels.fields import load_field
    from warpsky.simulate.frames import FrameWriter, weather_state
    from warpsky.simulate.sounding import base_state, weisman_klemp
    from warpsky.usd.stage import StageReader

    shape = (10, 8, 12)
    base = base_state(weisman_klemp(), shape[1], 500.0)
    fields = {"theta": np.broadcast_to(base.theta[None, :, None], shape).copy(),
              "vapour": np.broadcast_to(base.vapour[None, :, None], shape).copy(),
              "cloud": np.zeros(shape), "rain": np.zeros(shape),
              "velocity": np.zeros((*shape, 3), np.float32)}
    fields["cloud"][5, 3, 7] = 1.0e-3
    FrameWriter(tmp_path / "f", tmp_path / "f.usda", 60.0).write(weather_state(fields, base, (1000.0, 500.0), 60.0))
    beta = float(load_field(tmp_path / "f" / "cloud.0001.nvdb").values.max())
    peak = beta * 2.0 * 1000.0 * 10.0e-6 / 3.0
    (cloud,) = [m for m in StageReader(str(tmp_path / "f.usda")).read_media(1.0) if m.species == "cloud"]
    np.testing.assert_allclose(cloud.water, [peak, peak * 1000.0 * 1000.0 * 500.0], rtol=1e-5)
