"""The air's multiple scattering (warpsky.media.air.multiple_kernels): energy conservation of the table's sky, the sky
pass against the path tracer's air, the view table against per-ray integration, front + back = the whole ray, host and
device alike."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from conftest import look_rotation

from warpsky.light.sun import sunlight
from warpsky.media.air import multiple_kernels as air_multiple
from warpsky.media.air.analytic import transmittance
from warpsky.model.camera_rays import PinholeCamera, pinhole_camera, primary_ray
from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun


def sun_at(elevation_deg: float) -> np.ndarray:
    e = math.radians(elevation_deg)
    return np.array([0.0, math.sin(e), -math.cos(e)])


def view_at(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """A view ``elevation_deg`` above the horizon, ``azimuth_deg`` from the sun's azimuth (-z)."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)])


def sky_scene(sun_elevation: float, albedo: float, view=(0.0, 1.0, -1.0), focal: float = 50.0, height: float = 1.0,
              **atmosphere):
    camera = Camera("cam", np.array([0.0, height, 0.0]), look_rotation(view), focal, 36.0, 36.0)
    ground = Ground(0.0, albedo=np.full(3, albedo)) if albedo > 0.0 else None
    return Scene(camera, Sun(sun_at(sun_elevation), np.ones(3), angular_diameter=0.0), ground=ground,
                 atmosphere=Atmosphere(**atmosphere))


def sphere(count: int = 128):
    """Upper-hemisphere unit directions with solid-angle weights (Gauss-Legendre in sqrt(mu) x uniform azimuth)."""
    mu, w = air_multiple._half_sphere(count)
    phi = (np.arange(2 * count) + 0.5) / (2 * count) * 2.0 * np.pi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    up = np.stack([np.sqrt(1.0 - m * m) * np.cos(p), m, np.sqrt(1.0 - m * m) * np.sin(p)], -1).reshape(-1, 3)
    return up, (w[:, None] * np.full(2 * count, np.pi / count)).reshape(-1)


def energy_ratio(sun_elevation: float, albedo: float, multiple: bool) -> np.ndarray:
    """(light leaving the top of the air + light the floor absorbs) / sunlight in, RGB, for the sky the sky pass
    draws (air of albedo 1 over a Lambertian floor, no media)."""
    scene = sky_scene(sun_elevation, albedo, multiple_scattering=multiple)
    light, atm = sunlight(scene), scene.atmosphere
    up, w = sphere()
    down = up * np.array([1.0, -1.0, 1.0])
    direct = light.irradiance * light.direction[1] * np.exp(-atm.beta_sea_level / (atm.gamma * light.air_sine))
    floor = direct + (air_multiple.air_radiance(scene, light, 0.0, up) * (up[:, 1] * w)[:, None]).sum(axis=0)
    top = 24.0 * atm.scale_height
    distance = top / up[:, 1]
    upward = air_multiple.air_radiance(scene, light, top, down, distance)
    upward += transmittance(atm.beta_sea_level[None, :], atm.gamma, top, down[:, 1:2], distance[:, None]) * (
        albedo / np.pi * floor)
    leaving = (upward * (up[:, 1] * w)[:, None]).sum(axis=0)
    return (leaving + (1.0 - albedo) * floor) / (light.irradiance * light.direction[1])


@pytest.mark.parametrize("sun_elevation", [90.0, 20.0, 5.0])
@pytest.mark.parametrize("albedo", [0.0, 0.9])
def test_the_skys_energy_is_conserved(sun_elevation, albedo):
    """Sunlight in = light leaving the top + light the floor absorbs, within 1 %, in every channel; the
    single-scattering sky alone loses a measurable part of it (blue most), which this balance detects."""
    ratio = energy_ratio(sun_elevation, albedo, True)
    np.testing.assert_allclose(ratio, 1.0, atol=0.01)
    single = energy_ratio(sun_elevation, albedo, False)
    assert single[2] < 0.95 and np.all(single < ratio)


def test_table_builds_fast_and_vanishes_with_the_air():
    """A table builds in well under a second; with the air 1000x thinner the multiple-scattering part of the
    zenith sky relative to the single-scattering part falls as tau log(1 / tau) (a second order whose first
    scattering comes from near the horizon): at least 250x."""
    scene = sky_scene(30.0, 0.3)
    light = sunlight(scene)
    table = air_multiple.build(scene.atmosphere, 0.0, np.full(3, 0.3), float(light.direction[1]),
                               float(light.air_sine))
    assert table.seconds < 1.0
    assert np.all(np.isfinite(table.values)) and table.values.min() > 0.0
    zenith = np.array([[0.0, 1.0, 0.0]])
    ratios = []
    for scale in (1.0, 1e-3):
        thin = sky_scene(30.0, 0.0, beta_sea_level=scene.atmosphere.beta_sea_level * scale)
        both = air_multiple.air_radiance(thin, sunlight(thin), 1.0, zenith)
        single = air_multiple.air_radiance(sky_scene(30.0, 0.0, multiple_scattering=False,
                                                     beta_sea_level=thin.atmosphere.beta_sea_level),
                                           sunlight(thin), 1.0, zenith)
        ratios.append((both - single) / single)
    assert np.all(ratios[1] < 4e-3 * ratios[0]) and np.all(ratios[1] > 0.0)


@pytest.mark.parametrize("sun_elevation,view,albedo,height", [
    (60.0, (90.0, 0.0), 0.0, 1.0), (20.0, (10.0, 90.0), 0.3, 1.0), (5.0, (3.0, 120.0), 0.9, 1.0),
    (15.0, (-20.0, 60.0), 0.5, 6000.0),  # from 6 km, looking down at the air over a bright ground
])
def test_sky_pass_matches_the_path_traced_air(device, sun_elevation, view, albedo, height):
    """The sky pass (single scattering in closed form + the table) against the path tracer, which traces the same
    air with every order: within 2.5 % per channel plus 4 standard errors, on 8x8 pixels 1 deg across."""
    from warpsky.passes.sky.sky import Sky
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    scene = sky_scene(sun_elevation, albedo, view=view_at(*view), focal=2000.0, height=height)
    front, _ = Sky(device=device).render(scene, 8, 8)
    layer = PathTracer(PathTracerSettings(spp=2048, seed=11), device=device).render(scene, 8, 8)
    traced = layer.radiance.reshape(-1, 3).mean(axis=0)
    noise = np.sqrt(layer.aovs["variance"].reshape(-1, 3).sum(axis=0)) / 64
    table = front.radiance.reshape(-1, 3).mean(axis=0)
    if view[0] < 0.0:  # the ground behind the air: albedo / pi (sunlight + the sky's irradiance), as the passes take
        light, atm = sunlight(scene), scene.atmosphere
        up, w = sphere()
        sky = (air_multiple.air_radiance(scene, light, 0.0, up) * (up[:, 1] * w)[:, None]).sum(axis=0)
        direct = light.irradiance * light.direction[1] * np.exp(-atm.beta_sea_level / (atm.gamma * light.air_sine))
        ground = albedo / np.pi * (direct + sky)
        table = table + (front.transmittance * ground).reshape(-1, 3).mean(axis=0)
    assert np.all(np.abs(table - traced) < 0.025 * traced + 4.0 * noise), (table / traced, noise / traced)
    if view[0] < 0.0:
        return  # the ground dominates that view; the sky alone is checked above
    # the single-scattering sky is far outside that (the test can fail)
    single, _ = Sky(device=device).render(sky_scene(sun_elevation, albedo, view=view_at(*view), focal=2000.0,
                                                    height=height, multiple_scattering=False), 8, 8)
    assert single.radiance.reshape(-1, 3).mean(axis=0)[2] < 0.93 * traced[2]


@wp.kernel
def _directions(cam: PinholeCamera, out: wp.array2d(dtype=wp.vec3)):
    row, col = wp.tid()
    out[row, col] = primary_ray(cam, row, col, 0.5, 0.5).direction


def test_view_table_split_and_host_agree(device, monkeypatch):
    """The sky pass's view table gives the per-ray integration's sky; with media at random depths, front +
    T_front back is the whole ray's light; the host's air_radiance (which lights the media and the ground) is the
    device's sky."""
    from warpsky.passes.sky import sky as sky_module
    from warpsky.passes.sky.sky import Sky

    scene = sky_scene(25.0, 0.5, view=(0.3, 0.15, -1.0), focal=12.0)
    width, height = 24, 16
    whole, _ = Sky(device=device).render(scene, width, height)
    rng = np.random.default_rng(3)
    depth = np.where(rng.random((height, width)) < 0.5, scene.camera.far,
                     rng.uniform(100.0, 20000.0, (height, width))).astype(np.float32)
    front, back = Sky(device=device).render(scene, width, height, media_depth=depth)
    joined = front.radiance + front.transmittance * back.radiance
    np.testing.assert_allclose(joined, whole.radiance, rtol=2e-3)
    monkeypatch.setattr(sky_module, "view_rays", lambda scene, camera, light: None)
    direct, _ = Sky(device=device).render(scene, width, height)
    np.testing.assert_allclose(direct.radiance, whole.radiance, rtol=2e-3)
    direct_front, direct_back = Sky(device=device).render(scene, width, height, media_depth=depth)
    np.testing.assert_allclose(direct_front.radiance + direct_front.transmittance * direct_back.radiance,
                               whole.radiance, rtol=2e-3)
    camera = scene.camera.conformed(width, height)
    out = wp.zeros((height, width), dtype=wp.vec3, device=device)
    wp.launch(_directions, dim=(height, width), inputs=[pinhole_camera(camera, width, height), out], device=device)
    directions = out.numpy().reshape(-1, 3).astype(np.float64)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    upward = directions[:, 1] > 0.02
    host = air_multiple.air_radiance(scene, sunlight(scene), 1.0, directions[upward])
    np.testing.assert_allclose(whole.radiance.reshape(-1, 3)[upward], host, rtol=3e-3)


def test_the_far_clip_does_not_end_the_air(device):
    """The far clip bounds what the camera sees of media and surfaces, not the air: a low view traced with a 1 km
    and a 200 km far clip gives the same paths, bit for bit (the air beyond 1 km holds most of the horizon's
    light), and matches the sky pass, which never clipped the air."""
    from warpsky.passes.sky.sky import Sky
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    images = []
    for far in (1.0e3, 2.0e5):
        camera = Camera("cam", np.array([0.0, 1.0, 0.0]), look_rotation(view_at(3.0, 90.0)), 2000.0, 36.0, 36.0,
                        far=far)
        scene = Scene(camera, Sun(sun_at(20.0), np.ones(3), angular_diameter=0.0), atmosphere=Atmosphere())
        images.append(PathTracer(PathTracerSettings(spp=256, seed=4), device=device).render(scene, 4, 4))
    np.testing.assert_array_equal(images[0].radiance, images[1].radiance)
    front, back = Sky(device=device).render(scene, 4, 4)
    sky = (front.radiance + front.transmittance * back.radiance).reshape(-1, 3).mean(axis=0)
    traced = images[1].radiance.reshape(-1, 3).mean(axis=0)
    noise = np.sqrt(images[1].aovs["variance"].reshape(-1, 3).sum(axis=0)) / 16
    assert np.all(np.abs(sky - traced) < 0.03 * traced + 4.0 * noise)
