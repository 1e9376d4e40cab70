"""warpsky's path tracer against Mitsuba 3 (volpath, llvm_ad_rgb) on the same heterogeneous medium."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, image_sum_sigma, look_rotation, path_traced, write_stage

from warpsky.usd.stage import StageReader

mitsuba = pytest.importorskip("mitsuba", reason="the compare extra (pip install warpsky[compare]) is not installed")


def test_path_tracer_agrees_with_mitsuba_volpath(tmp_path):
    from evaluation import mitsuba as bridge

    rng = np.random.default_rng(0)
    density = (0.2 + rng.random((8, 8, 8))).astype(np.float32)
    density[:, :4] *= 0.2  # a thin lower half: asymmetric, so a mirrored camera would show
    np.save(tmp_path / "grid.npy", density)
    spec = StageSpec(volume_file=tmp_path / "grid.npy", extinction_scale=0.15, camera_position=(6.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.12, -0.06, -1.0)), sun_direction=(0.5, 0.8, 0.3),
                     phase="hg", g=0.6)
    stage = write_stage(tmp_path / "grid.usda", spec)
    scene = StageReader(stage).scene_at(None)
    size = 12
    reference, reference_variance, _ = bridge.render(scene, size, size, spp=4096, runs=16)
    layer = path_traced(stage, "cpu", size, spp=4096, pixel_jitter=1, seed=3)
    variance = layer.aovs["variance"] + reference_variance
    z = (layer.radiance - reference) / np.sqrt(variance + 1e-30)
    # 432 values: |z| > 5.5 has probability ~2e-5 under agreement, even with 16-run variance estimates
    assert np.max(np.abs(z)) < 5.5, np.max(np.abs(z))
    z_sum = (layer.radiance.sum() - reference.sum()) / image_sum_sigma(variance)
    assert abs(z_sum) < 4.0, z_sum
    assert reference.mean() > 0.005  # the scene is lit and seen


def test_export_refuses_what_it_cannot_express(tmp_path, homogeneous_npy):
    from evaluation.mitsuba import scene_dict
    from warpsky.core.errors import UsageError

    spec = StageSpec(volume_file=homogeneous_npy, ground=(-20.0, 0.3))
    scene = StageReader(write_stage(tmp_path / "g.usda", spec)).scene_at(None)
    with pytest.raises(UsageError, match="ground"):
        scene_dict(scene, 8, 8, 4)
