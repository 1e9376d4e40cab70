"""The sky pass in frames: USD atmosphere prim, composition with media, the sun's disk, night, no banding."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, add_atmosphere, look_rotation, write_stage

from warpsky.core.errors import SceneError
from warpsky.usd.stage import StageReader


def frame(stage_path, device, width=16, height=16):
    from warpsky.passes.composite import composite
    from warpsky.passes.frame import render_layers
    from warpsky.render.plan import make_plan
    from warpsky.techniques.single_scatter.single_scatter import SingleScatter

    scene = StageReader(stage_path).scene_at(None)
    plan = make_plan(scene, technique="single_scatter", resolution=(width, height), device=device)
    _, layers = render_layers(plan, scene, SingleScatter(plan.settings, device=device))
    return scene, composite(layers, far=scene.camera.far)


def test_atmosphere_prim_is_read_and_validated(tmp_path, homogeneous_npy):
    path = write_stage(tmp_path / "a.usda", StageSpec(volume_file=homogeneous_npy))
    assert StageReader(path).scene_at(None).atmosphere is None
    add_atmosphere(path, scaleHeight=7000.0, altitude=250.0)
    atm = StageReader(path).scene_at(None).atmosphere
    assert atm.scale_height == 7000.0 and atm.altitude == 250.0
    np.testing.assert_allclose(atm.beta_sea_level, [5.8e-6, 1.35e-5, 3.31e-5])  # Riley Table 3
    add_atmosphere(path, enabled=False)
    assert StageReader(path).scene_at(None).atmosphere is None
    bad = write_stage(tmp_path / "b.usda", StageSpec(volume_file=homogeneous_npy))
    add_atmosphere(bad, scaleHight=1.0)
    with pytest.raises(SceneError, match="scaleHight"):
        StageReader(bad).scene_at(None)


def test_zero_density_medium_leaves_the_sky_unchanged(tmp_path, device):
    zero = tmp_path / "zero.npy"
    np.save(zero, np.zeros((4, 4, 4), np.float32))
    spec = StageSpec(volume_file=zero, camera_position=(0.0, 50.0, 40.0),
                     camera_rotation=look_rotation((0.0, 0.2, -1.0)), sun_direction=(0.2, 0.5, -0.6))
    with_medium = add_atmosphere(write_stage(tmp_path / "m.usda", spec))
    spec.volume_file = None
    without = add_atmosphere(write_stage(tmp_path / "n.usda", spec))
    _, a = frame(with_medium, device)
    _, b = frame(without, device)
    np.testing.assert_allclose(a.rgba, b.rgba, rtol=1e-6, atol=1e-12)
    assert b.rgba[..., :3].min() > 0.0 and np.all(b.rgba[..., 3] == 1.0)  # the sky covers every pixel


def test_sky_scales_with_irradiance_and_night_is_black(tmp_path, device):
    images = []
    for intensity in (1.0, 4.0):
        spec = StageSpec(sun_intensity=intensity, camera_position=(0.0, 10.0, 0.0),
                         camera_rotation=look_rotation((0.0, 0.3, -1.0)), sun_direction=(0.0, 0.4, 1.0))
        images.append(frame(add_atmosphere(write_stage(tmp_path / f"s{intensity}.usda", spec)), device)[1].rgba)
    np.testing.assert_allclose(images[1][..., :3], 4.0 * images[0][..., :3], rtol=1e-5)
    spec = StageSpec(camera_position=(0.0, 10.0, 0.0), sun_direction=(0.0, -0.1, 1.0))
    _, night = frame(add_atmosphere(write_stage(tmp_path / "night.usda", spec)), device)
    assert np.all(np.isfinite(night.rgba)) and np.all(night.rgba[..., :3] == 0.0)


def test_sun_disk_is_seen_through_the_air(tmp_path, device):
    from warpsky.media.air.analytic import transmittance

    sun = np.array([0.0, 0.5, -1.0]) / np.linalg.norm([0.0, 0.5, -1.0])
    spec = StageSpec(camera_position=(0.0, 0.0, 0.0), camera_rotation=look_rotation(sun), focal_length=2000.0,
                     aperture=(30.0, 30.0), sun_direction=tuple(sun))
    scene, image = frame(add_atmosphere(write_stage(tmp_path / "sun.usda", spec)), device, 9, 9)
    centre = image.rgba[4, 4, :3]
    solid = 2 * np.pi * (1 - np.cos(0.5 * scene.sun.angular_diameter))
    disk = scene.sun.irradiance / solid * transmittance(scene.atmosphere.beta_sea_level, scene.atmosphere.gamma,
                                                          0.0, sun[1], np.inf)
    np.testing.assert_allclose(centre, disk, rtol=1e-3)  # the in-scattered sky is 1e-5 of the disk
    assert image.rgba[0, 0, 1] < 1e-3 * centre[1]  # the corner is 0.6 deg off the sun: sky, not disk


def test_horizon_column_has_no_banding(device):
    from warpsky.model.scene import Atmosphere, Camera, Scene, Sun
    from warpsky.passes.sky.sky import Sky

    camera = Camera("cam", np.array([0.0, 10.0, 0.0]), look_rotation((0.0, 0.0, -1.0)), 50.0, 36.0, 36.0)
    scene = Scene(camera, Sun(np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0]), np.ones(3)),
                  atmosphere=Atmosphere())
    front, _ = Sky(device=device).render(scene, 1, 4096)
    column = front.radiance[:, 0, :].astype(np.float64)
    assert np.all(np.isfinite(column)) and column.min() >= 0.0
    # a flat earth's horizon is a steep but continuous cusp (optical depth ~ 1/elevation): away from its 16
    # nearest rows the column is smooth to float32 precision, with no stair steps (banding)
    second = np.abs(np.diff(column, 2, axis=0)).max(axis=1)
    rows = np.arange(len(second)) + 1
    away = np.abs(rows - 2048) > 16
    assert second[away].max() < 3e-4 * column.max()


def test_path_tracer_single_scattering_matches_the_analytic_sky(device):
    """The path tracer with the air as a medium, one bounce: Riley's analytic single-scattering sky within noise,
    and the analytic transmittance of the air to space."""
    from warpsky.model.scene import Atmosphere, Camera, Scene, Sun
    from warpsky.passes.sky.sky import Sky
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    camera = Camera("cam", np.array([0.0, 10.0, 0.0]), look_rotation((0.3, 0.9, -1.0)), 24.0, 36.0, 36.0)
    sun = Sun(np.array([-0.4, 0.25, -1.0]) / np.linalg.norm([-0.4, 0.25, -1.0]), np.ones(3))
    scene = Scene(camera, sun, atmosphere=Atmosphere(multiple_scattering=False))
    front, _ = Sky(device=device).render(scene, 8, 8)
    layer = PathTracer(PathTracerSettings(spp=4096, max_bounces=1, seed=9), device=device).render(scene, 8, 8)
    variance = layer.aovs["variance"]
    z = (layer.radiance - front.radiance) / np.sqrt(variance + 1e-30)
    assert np.max(np.abs(z)) < 5.0, np.max(np.abs(z))
    z_sum = (layer.radiance - front.radiance).sum() / np.sqrt(variance.sum())
    assert abs(z_sum) < 4.0, z_sum
    np.testing.assert_allclose(layer.transmittance, front.transmittance, atol=0.03)
    assert front.radiance.min() > 0.0


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_front_air_transmittance_is_the_sky_passs_bit_for_bit(device, projection):
    """The front-air kernel and the sky pass share the ray's air: same transmittance to the last bit, looking up
    and down at a ground plane, with media at random depths in some pixels and none in others."""
    from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun
    from warpsky.passes.sky.front import front_air_transmittance
    from warpsky.passes.sky.sky import Sky

    aperture = (36.0, 36.0) if projection == "perspective" else (900.0, 600.0)  # [mm] film, [m] view window
    camera = Camera("cam", np.array([0.0, 400.0, 0.0]), look_rotation((0.2, -0.1, -1.0)), 18.0, *aperture,
                    far=50000.0, projection=projection)
    sun = Sun(np.array([-0.4, 0.25, -1.0]) / np.linalg.norm([-0.4, 0.25, -1.0]), np.ones(3))
    scene = Scene(camera, sun, ground=Ground(120.0), atmosphere=Atmosphere(altitude=300.0))
    rng = np.random.default_rng(4)
    depth = np.where(rng.random((12, 20)) < 0.3, camera.far, rng.random((12, 20)) * 8000.0).astype(np.float32)
    front, _ = Sky(device=device).render(scene, 20, 12, media_depth=depth)
    mine = front_air_transmittance(scene, 20, 12, depth, device)
    assert mine.shape == (12, 20, 3) and mine.dtype == np.float32
    assert np.array_equal(mine, front.transmittance)
    assert np.ptp(mine) > 0.01
