"""The sky pass takes out the air's single scattering where the scenery shades it (:mod:`warpsky.passes.sky.
shadowed_air`): under an opaque roof that hides the sun, the front air's light falls by Riley's closed-form single
scattering of that stretch; without anything in the sun's way it is unchanged."""

from __future__ import annotations

import math

import numpy as np
from conftest import look_rotation

from warpsky.light.background import pixel_directions
from warpsky.light.sun import sunlight
from warpsky.media.air.analytic import inscatter
from warpsky.model.scene import Atmosphere, Camera, Scene, Sun
from warpsky.model.terrain import TerrainMesh
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan

WIDTH, HEIGHT = 12, 8


def quad(name: str, corners) -> TerrainMesh:
    return TerrainMesh(name, np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]]), (0.3, 0.3, 0.3))


def scene_with(roof: bool) -> Scene:
    """A wall 2 km ahead of a camera 100 m up looking level (2.3 deg half-height), the sun 30 deg up behind it;
    with ``roof`` an opaque plane 150 m up, 10 km across, hides the sun from all the air the camera sees."""
    wall = quad("wall", [(-3000, 0, -2000), (3000, 0, -2000), (3000, 3000, -2000), (-3000, 3000, -2000)])
    meshes = [wall]
    if roof:
        # facing down: the eye under it sees its front, so it is not taken to be buried
        meshes.append(quad("roof", [(-5000, 150, -5000), (5000, 150, -5000), (5000, 150, 5000), (-5000, 150, 5000)]))
    camera = Camera("cam", np.array([0.0, 100.0, 0.0]), look_rotation((0.0, 0.0, -1.0)), 50.0, 6.0, 4.0, far=1e5)
    elevation = math.radians(30.0)
    sun = Sun(np.array([0.0, math.sin(elevation), math.cos(elevation)]), np.ones(3))
    return Scene(camera, sun, meshes=tuple(meshes), atmosphere=Atmosphere())


def front_air(scene: Scene):
    plan = make_plan(scene, technique="single_scatter", resolution=(WIDTH, HEIGHT))
    assert plan.passes == ("surfaces", "sky")
    _, layers = render_layers(plan, scene)
    depth = np.min([layer.depth for layer in layers[1:-1]], axis=0)
    return layers[0], depth


def test_air_under_a_roof_loses_its_single_scattering():
    """On the rays that meet the wall below the roof, front air without the roof minus with it equals Riley's
    closed-form single scattering of the stretch to the wall (per pixel, within 0.5 %: 8 midpoints on a nearly
    uniform integrand); the air's transmittance is unchanged."""
    open_air, depth = front_air(scene_with(roof=False))
    roofed, roof_depth = front_air(scene_with(roof=True))
    assert open_air.stats.get("shadowed_air", 0.0) == 0.0 and roofed.stats["shadowed_air"] > 0.0
    scene = scene_with(roof=False)
    camera = scene.camera.conformed(WIDTH, HEIGHT)
    rays = pixel_directions(camera, WIDTH, HEIGHT)
    same = np.abs(roof_depth - depth) < 1e-3 * depth  # rays that meet the wall below the roof in both
    assert same.sum() >= WIDTH * HEIGHT // 2
    distance = depth / -rays[..., 2]
    atm = scene.atmosphere
    light = sunlight(scene)
    cos_theta = rays @ np.asarray(light.direction)
    single = inscatter(atm.beta_sea_level[None, None, :], atm.gamma, 100.0 + atm.altitude, rays[..., 1:2],
                       light.air_sine, distance[..., None])
    expected = single * (3.0 / (16.0 * math.pi) * (1.0 + cos_theta**2))[..., None] * light.irradiance
    removed = open_air.radiance.astype(np.float64) - roofed.radiance
    print(f"\nremoved {removed.mean():.4e}, closed form {expected.mean():.4e}, "
          f"front air {open_air.radiance.mean():.4e}")
    np.testing.assert_allclose(removed[same], expected[same], rtol=5e-3)
    assert np.all(roofed.radiance >= 0.0) and removed[same].mean() > 0.3 * open_air.radiance[same].mean()
    np.testing.assert_allclose(open_air.transmittance[same], roofed.transmittance[same], rtol=1e-6)
