"""Half-angle slicing: the optically thin limit, extreme cases, the low-albedo mode and convergence."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, render_layer, write_stage

from warpsky.plan import make_plan
from warpsky.scene.usd import StageReader
from warpsky.techniques.slicing.technique import Slicing


def sliced(stage, device, size, **settings):
    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique="slicing", settings={k: str(v) for k, v in settings.items()},
                     resolution=(size, size), device=device)
    return Slicing(plan.settings, device=device).render(scene, size, size)


@pytest.mark.parametrize("sun", [(0.4, 0.8, 0.3), (0.3, 0.5, -0.8)])  # behind the camera, then ahead of it
def test_optically_thin_limit_equals_single_scattering(tmp_path, homogeneous_npy, device, sun):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=5e-5, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=sun, phase="hg", g=0.7)
    stage = write_stage(tmp_path / "thin.usda", spec)
    _, reference = render_layer(stage, device, 16, 16, step_length=0.05, shadow_step_length=0.05,
                                min_transmittance=0.0)
    layer = sliced(stage, device, 16, slice_count=512)
    # per-slice optical depth is ~1e-6 here: 1 - e^-tau must be taken without float32 cancellation
    interior = reference.radiance[..., 1] > 0.5 * reference.radiance[..., 1].max()
    np.testing.assert_allclose(layer.radiance[interior], reference.radiance[interior], rtol=0.01)
    assert layer.radiance.sum() == pytest.approx(reference.radiance.sum(), rel=0.01)
    np.testing.assert_allclose(layer.transmittance, reference.transmittance, rtol=1e-3)


@pytest.mark.parametrize("scale", [0.0, 1e-9, 1.0, 1e4])
def test_extreme_optical_depths_stay_finite(tmp_path, homogeneous_npy, device, scale):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=scale, camera_position=(0.0, 0.0, 40.0),
                     camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(0.0, 1e-6, -1.0))
    layer = sliced(write_stage(tmp_path / f"x{scale}.usda", spec), device, 8, slice_count=16)
    for values in (layer.radiance, layer.transmittance, layer.depth):
        assert np.all(np.isfinite(values)) and values.min() >= 0.0
    assert layer.transmittance.max() <= 1.0
    if scale == 0.0:
        assert np.all(layer.radiance == 0.0) and np.all(layer.transmittance == 1.0)


def test_camera_inside_the_cloud_and_sun_along_the_view(tmp_path, homogeneous_npy, device):
    for sun in [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (1e-6, 0.0, 1.0)]:
        spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.1, camera_position=(0.0, 0.0, 0.0),
                         sun_direction=sun)
        layer = sliced(write_stage(tmp_path / "inside.usda", spec), device, 8, slice_count=32)
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
        assert layer.radiance.max() > 0.0 and layer.transmittance.max() < 1.0


def test_low_albedo_mode_is_darker(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.3, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, 0.8, 0.5), phase="hg", g=0.85)
    stage = write_stage(tmp_path / "dark.usda", spec)
    full = sliced(stage, device, 8, slice_count=64)
    low = sliced(stage, device, 8, slice_count=64, low_albedo=1)
    assert low.radiance.sum() < full.radiance.sum()


def test_slice_count_convergence(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.15, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3),
                     phase="hg", g=0.8)
    stage = write_stage(tmp_path / "conv.usda", spec)
    images = {n: sliced(stage, device, 12, slice_count=n).radiance for n in (128, 256, 512)}
    coarse = np.abs(images[256] - images[128]).mean()
    fine = np.abs(images[512] - images[256]).mean()
    assert fine <= 0.5 * coarse + 1e-9, (coarse, fine)


def test_both_light_equations_render_and_differ(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.3, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, 0.8, 0.5), phase="hg", g=0.85)
    stage = write_stage(tmp_path / "eq.usda", spec)
    eq24 = sliced(stage, device, 8, slice_count=64, light_equation=24)
    eq25 = sliced(stage, device, 8, slice_count=64, light_equation=25)
    for layer in (eq24, eq25):
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
    assert not np.allclose(eq24.radiance, eq25.radiance)


def test_sun_below_the_ground_lights_nothing(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.1, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, -0.2, 0.5), ground=(-30.0, 0.5))
    layer = sliced(write_stage(tmp_path / "night.usda", spec), device, 8, slice_count=16)
    assert np.all(layer.radiance == 0.0) and np.all(np.isfinite(layer.transmittance))
    assert layer.transmittance.min() < 0.5  # the cloud still hides what lies behind it
