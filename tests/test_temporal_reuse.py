"""Temporal reuse of the hybrid's multiple-scattering paths between consecutive frames of one shot.

A frame that starts from the previous frame's paths keeps its expectation where the scene did not change (z-tests
against a frame rendered alone) and carries their variance away; another shot, or a changed pixel, starts
afresh."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, image_sum_sigma, look_rotation, write_stage

from warpsky.render.plan import make_plan
from warpsky.techniques.hybrid import history
from warpsky.usd.stage import StageReader


def puff_scene(tmp_path, extinction_scale: float = 0.4):
    """A 16^3 Gaussian puff of optical depth ~8 across its core (at the default scale), camera along -z, sun from
    the side."""
    axis = (np.arange(16) + 0.5) / 16 - 0.5
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    grid = tmp_path / "puff.npy"
    np.save(grid, np.exp(-(x**2 + y**2 + z**2) / 0.06).astype(np.float32))
    spec = StageSpec(volume_file=grid, extinction_scale=extinction_scale, camera_position=(0.0, 0.0, 32.0),
                     camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(1.0, 0.15, 0.05),
                     phase="hg", g=0.85)
    return StageReader(write_stage(tmp_path / f"puff_{extinction_scale}.usda", spec)).scene_at(None)


@pytest.fixture
def puff(tmp_path):
    return puff_scene(tmp_path)


def hybrid(scene, device, size, **settings):
    values = {"target_error": 0, "denoise": 0, "step_length": 0.05, "shadow_step_length": 0.05} | settings
    plan = make_plan(scene, technique="hybrid", settings={k: str(v) for k, v in values.items()},
                     resolution=(size, size), device=device)
    return plan.renderer.render(scene, size, size)


@pytest.fixture(autouse=True)
def no_history():
    history.forget()
    yield
    history.forget()


def test_a_static_frame_keeps_its_light_and_carries_the_previous_frames_variance_away(puff, device):
    """Frame 2 of a static shot (weight 0.99: nearly all of frame 1's paths kept) against a frame rendered alone:
    the same light within noise, about half the variance."""
    first = hybrid(puff, device, 12, spp=256, seed=1, temporal=0.99)
    second = hybrid(puff, device, 12, spp=256, seed=1, temporal=0.99)
    alone = hybrid(puff, device, 12, spp=256, seed=2)
    variance = second.aovs["variance"] + alone.aovs["variance"]
    lit = variance > 0.0
    assert lit.sum() > 100
    difference = second.aovs["multiple_scatter"] - alone.aovs["multiple_scatter"]
    assert np.max(np.abs(difference[lit] / np.sqrt(variance[lit]))) < 5.0  # ~400 values
    assert abs(difference.sum() / image_sum_sigma(variance)) < 4.0
    ratio = second.aovs["variance"][lit].sum() / first.aovs["variance"][lit].sum()
    assert 0.4 < ratio < 0.6  # 512 paths' worth against 256 (the same streams never repeat)
    assert not np.array_equal(first.aovs["multiple_scatter"], second.aovs["multiple_scatter"])


def test_a_cut_to_a_denser_cloud_drops_the_history_where_it_changed(puff, tmp_path, device):
    """Frame 2 is a cloud 2.5 times as dense under the same camera: every pixel it covers starts afresh, so the frame
    matches the denser cloud rendered alone within noise (and not the first cloud's light)."""
    hybrid(puff, device, 12, spp=256, seed=1, temporal=0.99)
    dense = puff_scene(tmp_path, extinction_scale=1.0)
    after = hybrid(dense, device, 12, spp=256, seed=1, temporal=0.99)
    alone = hybrid(dense, device, 12, spp=256, seed=2)
    variance = after.aovs["variance"] + alone.aovs["variance"]
    lit = variance > 0.0
    difference = after.aovs["multiple_scatter"] - alone.aovs["multiple_scatter"]
    assert np.max(np.abs(difference[lit] / np.sqrt(variance[lit]))) < 5.0
    assert abs(difference.sum() / image_sum_sigma(variance)) < 4.0
    first = hybrid(puff, device, 12, spp=256, seed=3)  # the light the history held differs from the dense cloud's
    changed = first.aovs["variance"] + alone.aovs["variance"]
    assert abs((first.aovs["multiple_scatter"] - alone.aovs["multiple_scatter"]).sum()) > 10.0 * image_sum_sigma(
        changed)


def test_another_shot_starts_afresh(puff, device):
    """A different image size is another shot: the frame is the one rendered alone, bit for bit."""
    hybrid(puff, device, 12, spp=16, seed=1, temporal=0.9)
    after = hybrid(puff, device, 10, spp=16, seed=1, temporal=0.9)
    history.forget()
    alone = hybrid(puff, device, 10, spp=16, seed=1, temporal=0.9)
    assert np.array_equal(after.aovs["multiple_scatter"], alone.aovs["multiple_scatter"])


def test_without_reuse_no_history_is_kept(puff, device):
    hybrid(puff, device, 10, spp=4, seed=1)
    assert history.take(history._last.key if history._last else ()) is None


def test_the_history_is_dropped_where_the_frame_changed():
    """Pixels whose single scattering changed by more than the tolerance (5% here; and their margin) keep nothing; a
    change in the coverage alone drops them too; the rest keep the weight."""
    single = np.full((20, 30, 3), 2.0, np.float32)
    coverage = np.full((20, 30, 3), 0.5, np.float32)
    kept = history.ShotHistory((), [], [], single, coverage, 0)
    moved = single.copy()
    moved[5, 7] *= 1.1
    thinner = coverage.copy()
    thinner[15, 25] -= 2.0 * history.COVERAGE_TOLERANCE
    weights = history.kept_weights(kept, moved, thinner, 1, 0.8, 0.05)
    margin = history.CHANGE_MARGIN
    dropped = np.zeros((20, 30), bool)
    dropped[5 - margin:5 + margin + 1, 7 - margin:7 + margin + 1] = True
    dropped[15 - margin:15 + margin + 1, 25 - margin:25 + margin + 1] = True
    assert np.array_equal(weights == 0.0, dropped)
    assert np.all(weights[~dropped] == np.float32(0.8))
    small = single * 1.025
    assert np.all(history.kept_weights(kept, small, coverage, 1, 0.8, 0.05) == np.float32(0.8))
    assert np.all(history.kept_weights(kept, moved, coverage, 1, 0.8, 0.2) == np.float32(0.8))  # a looser tolerance
    # on a film of 4x4-pixel blocks a block with one changed pixel is dropped, with its margin of blocks
    coarse = history.kept_weights(kept, moved, coverage, 4, 0.8, 0.05)
    assert coarse.shape == (5, 8) and coarse[1, 1] == 0.0 and coarse[4, 7] == np.float32(0.8)


def test_a_batchs_second_frame_starts_from_the_first_and_says_so_in_its_header(tmp_path, homogeneous_npy, capsys):
    """``warpsky render --frames 1:2 --set temporal=0.5``: frames rendered one after another in the process; the
    second's header records the first frame's paths it started from, the first's none."""
    from conftest import run_cli

    from warpsky.output.exr import read_exr

    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    out = tmp_path / "out" / "f.####.exr"
    code, _, _ = run_cli(["render", stage, out, "--frames", "1:2", "--res", "16", "--device", "cpu", "--spp", "8",
                          "--set", "target_error=0", "--set", "temporal=0.5"], capsys)
    assert code == 0
    first, second = (read_exr(tmp_path / "out" / f"f.000{frame}.exr").metadata for frame in (1, 2))
    assert first["reusedSpp"] == 0.0
    assert second["reusedSpp"] == pytest.approx(0.5 * 8, rel=1e-6)  # a static scene: every pixel kept


def test_a_slow_drift_is_measured_against_the_frames_the_history_holds():
    """Frames whose single scattering grows 4% a frame: each is within the tolerance of the frame before, but the
    third differs by more than it from the path-weighted mean of the two frames the history holds, so it starts
    afresh."""
    from types import SimpleNamespace

    from warpsky.techniques.path_tracer.path_tracer import pixel_sums

    shape = (6, 6)
    scene = SimpleNamespace(camera="camera", sun="sun", extra_suns=(), dome=None)
    settings = SimpleNamespace(temporal=0.5, temporal_tolerance=0.05)
    paths = SimpleNamespace(shot=(scene, 6, 6), scale=1, device="cpu", settings=settings)
    coverage = np.full(shape + (3,), 0.9, np.float32)
    kept = []
    for frame, level in enumerate((1.0, 1.04, 1.08)):
        paths.halves = [pixel_sums(shape, "cpu") for _ in (0, 1)]
        paths.pixel_counts = [np.zeros(shape, np.float32) for _ in (0, 1)]
        single = np.full(shape + (3,), level, np.float32)
        reuse = history.warm_start(paths, single, coverage)
        kept.append(reuse.stats()["reused_spp"])
        for half in (0, 1):  # this frame's own 4 paths per pixel and half
            paths.pixel_counts[half] += 4.0
        history.keep_frame(paths, reuse, single, coverage, reuse.first + 8)
        if frame == 1:  # the history's frames, weighted as their paths: 4 of frame 1's, 8 of frame 2's
            assert history._last.single[0, 0, 0] == pytest.approx((4.0 * 1.0 + 8.0 * 1.04) / 12.0, rel=1e-6)
    assert kept == [0.0, 4.0, 0.0]
    assert 1.08 / 1.04 - 1.0 < 0.05  # the frame before alone would have been kept
