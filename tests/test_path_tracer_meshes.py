"""The path tracer's triangle meshes: Lambertian bounces inside the paths, against closed forms (a tilted plane
under the sun, a wall's shadow, the second bounce between two facing plates by their view factor), against the
ground plane (a flat mesh under a medium), a volume cut by a mesh, and a camera under a mesh."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.model.scene import Camera, Ground, Scene, Sun, VoxelMedium
from warpsky.model.stratiform import GroundTexture
from warpsky.model.terrain import TerrainMesh
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan
from warpsky.techniques.path_tracer.path_tracer import PathTracer

UP = (0.0, 1.0, 0.0)
DOWN = (0.0, -1.0, 0.0)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def quad(name: str, corners, albedo=(0.3, 0.3, 0.3)) -> TerrainMesh:
    """Two triangles over four corners given counter-clockwise seen from the front."""
    return TerrainMesh(name, np.asarray(corners, float), np.array([[0, 1, 2], [0, 2, 3]]), albedo)


def square(y: float, half: float, albedo=(0.3, 0.3, 0.3), name="floor") -> TerrainMesh:
    """A horizontal square of half-size ``half`` at height ``y``, facing up."""
    return quad(name, [[-half, y, -half], [-half, y, half], [half, y, half], [half, y, -half]], albedo)


def ortho_camera(position, forward, view: float, near: float = 0.5) -> Camera:
    """An orthographic camera showing a ``view`` x ``view`` metre window."""
    return Camera("ortho", np.asarray(position, float), look_rotation(forward), 50.0, view, view, near=near,
                  far=1.0e4, projection="orthographic")


def perspective_camera(position, forward) -> Camera:
    return Camera("persp", np.asarray(position, float), look_rotation(forward), 30.0, 36.0, 36.0, near=0.5,
                  far=1.0e4)


def pixel_points(camera: Camera, size: int) -> np.ndarray:
    """World (x, y, z) of the orthographic window's pixel centres, (size, size, 3)."""
    s = (np.arange(size) + 0.5) / size - 0.5
    sx, sy = s[None, :] * camera.horizontal_aperture, -s[:, None] * camera.vertical_aperture
    return camera.position + sx[..., None] * camera.rotation[:, 0] + sy[..., None] * camera.rotation[:, 1]


def traced(scene: Scene, device: str, size: int, **settings):
    """The path tracer's layer of ``scene`` at ``size`` x ``size`` (its plan must not be refused)."""
    plan = make_plan(scene, technique="path_tracer", settings={k: str(v) for k, v in settings.items()},
                     resolution=(size, size), device=device)
    return PathTracer(plan.settings, device=device).render(scene, size, size)


def z_scores(a, b) -> tuple[np.ndarray, float]:
    """Per-pixel z of two independent path-traced layers' difference, and the image mean's z."""
    variance = a.aovs["variance"] + b.aovs["variance"]
    difference = a.radiance - b.radiance
    return difference / np.sqrt(variance + 1e-30), float(difference.sum() / np.sqrt(variance.sum()))


def corner_view_factor(a: float, b: float, c: float) -> float:
    """The view factor from a differential area to a parallel a x b rectangle at distance c, over one of its
    corners (Howell, A Catalog of Radiation Heat Transfer Configuration Factors, B-3)."""
    x, y = a / c, b / c
    return (x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x))
            + y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))) / (2.0 * math.pi)


def square_view_factor(px: float, pz: float, half: float, c: float) -> float:
    """The view factor from a differential area at distance ``c`` above (px, pz) to the parallel square
    [-half, half]^2 under it: the four rectangles meeting under the point."""
    return sum(corner_view_factor(half - sx * px, half - sz * pz, c) for sx in (-1, 1) for sz in (-1, 1))


# ------------------------------------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("case", ["front", "back", "sun_behind", "grazing", "far_from_origin"])
def test_tilted_plane_is_lambert_under_the_sun(device, case):
    """A plane tilted 30 deg about z, no air: every path gives albedo / pi E max(n.l, 0) (the sun's next event,
    n turned to the camera's side) plus albedo L_env (its bounce escapes into the uniform environment); exact,
    seen from the front or the back (two-sided), with the sun behind the face (0), at 0.5 deg over it, and 300 km
    from the world's origin (points relative to the eye)."""
    tilt = math.radians(30.0)
    normal = np.array([math.sin(tilt), math.cos(tilt), 0.0])
    along, z = np.array([math.cos(tilt), -math.sin(tilt), 0.0]), np.array([0.0, 0.0, 1.0])
    offset = np.array([2.0e5, 0.0, -2.2e5]) if case == "far_from_origin" else np.zeros(3)
    corners = [offset + s * along * 500 + t * z * 500 for s, t in ((-1, -1), (-1, 1), (1, 1), (1, -1))]
    mesh = quad("tilted", corners, (0.5, 0.25, 0.125))
    side = -1.0 if case == "back" else 1.0  # the camera's side of the plane
    sun_direction = {"sun_behind": -normal + 0.3 * along,
                     "grazing": math.cos(math.radians(0.5)) * along + math.sin(math.radians(0.5)) * normal
                     }.get(case, side * normal + 0.4 * along + 0.2 * z)
    sun = Sun(unit(sun_direction), np.array([2.0, 1.5, 1.0]))
    camera = perspective_camera(offset + side * normal * 200.0 + (1.0, 2.0, 3.0), -side * normal)
    layer = traced(Scene(camera=camera, sun=sun, meshes=(mesh,)), device, 8, spp=4, environment=0.25)
    cosine = max(float(side * normal @ sun.direction), 0.0)
    expected = mesh.albedo / math.pi * sun.irradiance * cosine + mesh.albedo * 0.25
    assert (case == "sun_behind") == (cosine == 0.0)
    assert np.all(layer.transmittance == 0.0)
    np.testing.assert_allclose(layer.radiance, np.broadcast_to(expected, layer.radiance.shape), rtol=1e-5)
    assert np.all(layer.aovs["variance"] <= 1e-6 * expected.max() ** 2)  # every path the same


def test_albedo_map_is_read_at_world_x_z(device):
    """A floor mesh with a 2 x 2 albedo map over [-40, 40]^2 m under a zenith sun, 100 km from the origin: the first
    bounce is each texel's albedo / pi E at the texel centres (x, z = +-20 m) and beyond the map (+-60 m, edge
    texels continued), as the surfaces pass reads it."""
    texels = np.array([[[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]], [[0.7, 0.8, 0.9], [0.9, 0.1, 0.5]]])
    far = np.array([1.0e5, 0.0, -1.0e5])
    texture = GroundTexture(texels, (far[0] - 40.0, far[2] - 40.0), (80.0, 80.0))
    floor = square(0.0, 100.0)
    floor = TerrainMesh("floor", floor.points + far, floor.triangles, floor.albedo, albedo_map=texture)
    camera = ortho_camera(far + (0.0, 30.0, 0.0), DOWN, 160.0)
    layer = traced(Scene(camera=camera, sun=Sun(np.array(UP), np.ones(3)), meshes=(floor,)), device, 4, spp=1,
                   max_bounces=1)
    where = pixel_points(camera, 4) - far
    expected = texels[(where[..., 0] > 0).astype(int), (where[..., 2] > 0).astype(int)] / math.pi
    np.testing.assert_allclose(layer.radiance, expected, rtol=1e-5)


@pytest.mark.parametrize("floor_kind", ["ground_plane", "mesh"])
def test_wall_shadows_the_floor_where_the_geometry_says(device, floor_kind):
    """A wall 20 m high along x = 0 under a sun at 30 deg from +x, seen from above: the floor's first bounce is
    albedo / pi E sin e outside the shadow -H / tan e < x < 0 and exactly 0 inside it (the wall's any-hit shadow
    ray, from the ground plane's events or from a floor mesh's). With every bounce, the shadow gets only the light
    the wall and the lit floor send into it, and every lit pixel at least the direct term."""
    height, elevation, albedo = 20.0, math.radians(30.0), 0.3
    wall = quad("wall", [[0, 0, -200], [0, 0, 200], [0, height, 200], [0, height, -200]])
    sun = Sun(np.array([math.cos(elevation), math.sin(elevation), 0.0]), np.ones(3))
    camera = ortho_camera((0.0, 100.0, 0.0), DOWN, 128.0)
    floor = {"ground_plane": {"ground": Ground(0.0, np.full(3, albedo))},
             "mesh": {"meshes": (square(0.0, 400.0, (albedo,) * 3),)}}[floor_kind]
    scene = Scene(camera=camera, sun=sun, **{**floor, "meshes": floor.get("meshes", ()) + (wall,)})
    x = pixel_points(camera, 32)[..., 0]
    shadowed = (x > -height / math.tan(elevation)) & (x < 0.0)
    assert shadowed.sum() == 9 * 32  # pixel columns at x = -34 .. -2 m
    direct = albedo / math.pi * math.sin(elevation)
    first = traced(scene, device, 32, spp=1, max_bounces=1).radiance[..., 0]
    np.testing.assert_array_equal(first[shadowed], 0.0)
    np.testing.assert_allclose(first[~shadowed], direct, rtol=1e-5)
    every = traced(scene, device, 32, spp=16).radiance[..., 0]
    assert np.all(every[~shadowed] >= direct * (1 - 1e-5))
    assert 0.0 < every[shadowed].mean() < 0.1 * direct


def test_second_bounce_between_facing_plates_is_the_view_factor(device):
    """Two parallel 2 x 2 m plates 1 m apart, the sun at 20 deg (the upper plate's shadow falls beside the lower
    one), seen from between them looking up. Two bounces: the upper plate's underside returns
    a_up a_low E sin e / pi F(P), F the view factor from its point P to the lower plate (Howell B-3 over four
    rectangles); z-tested per pixel and over the image."""
    half, gap, elevation = 1.0, 1.0, math.radians(20.0)
    low, high = 0.6, 0.8
    lower = square(0.0, half, (low,) * 3, name="lower")
    upper = square(gap, half, (high,) * 3, name="upper")
    sun = Sun(np.array([math.cos(elevation), math.sin(elevation), 0.0]), np.ones(3))
    assert 1.0 / math.tan(elevation) - half > half  # the shadow misses the lower plate
    camera = ortho_camera((0.0, 0.5, 0.0), UP, 1.6, near=0.01)
    size = 12
    layer = traced(Scene(camera=camera, sun=sun, meshes=(lower, upper)), device, size, spp=256, max_bounces=2)
    points = pixel_points(camera, size)
    factor = np.vectorize(lambda px, pz: square_view_factor(px, pz, half, gap))(points[..., 0], points[..., 2])
    expected = high * low * math.sin(elevation) / math.pi * factor
    z = (layer.radiance[..., 1] - expected) / np.sqrt(layer.aovs["variance"][..., 1])
    z_mean = (layer.radiance[..., 1] - expected).sum() / np.sqrt(layer.aovs["variance"][..., 1].sum())
    assert np.max(np.abs(z)) < 4.5  # 144 pixels: a false alarm ~1e-3
    assert abs(z_mean) < 4.0
    assert factor.min() < 0.35 and factor.max() > 0.5  # the closed form varies across the plate


# ------------------------------------------------------------------------------------- against other surfaces


def slab(y0: float, y1: float, half: float, sigma: float, albedo: float = 0.9) -> VoxelMedium:
    """A homogeneous box over [-half, half] in x and z, from y0 to y1, isotropic, 4 voxels per axis."""
    shape = np.array([4, 4, 4])
    size = np.array([2 * half, y1 - y0, 2 * half]) / shape
    world_from_index = np.diag([*size, 1.0])
    world_from_index[:3, 3] = np.array([-half, y0, -half]) + size / 2
    return VoxelMedium("slab", np.ones(tuple(shape), np.float32), world_from_index, np.full(3, sigma),
                       np.full(3, albedo))


def test_flat_mesh_under_a_medium_equals_the_ground_plane(device):
    """Under a box of optical depth 1 (albedo 0.9) in a uniform environment, a flat mesh at the ground plane's
    height with its albedo gives the plane's image: light bouncing between the medium and either surface agrees
    within the paths' noise (independent streams: the two bounces turn their draws differently)."""
    albedo = np.array([0.2, 0.4, 0.6])
    camera = perspective_camera((0.0, 60.0, 40.0), unit((0.0, -1.0, -0.6)))
    sun = Sun(unit((0.4, 0.8, 0.3)), np.ones(3))
    media = (slab(2.0, 22.0, 10.0, 0.05),)
    plane = Scene(camera=camera, sun=sun, media=media, ground=Ground(0.0, albedo))
    mesh = Scene(camera=camera, sun=sun, media=media, meshes=(square(0.0, 1.0e5, albedo),))
    a = traced(plane, device, 12, spp=64, environment=0.3)
    b = traced(mesh, device, 12, spp=64, environment=0.3, seed=1)
    z, z_mean = z_scores(a, b)
    assert np.max(np.abs(z)) < 5.0  # 432 values
    assert abs(z_mean) < 4.0
    assert np.all(a.transmittance == 0.0) and np.all(b.transmittance == 0.0)  # both opaque everywhere


WALL_SIZE = 16


def box(z0: float, z1: float, sigma: float = 0.05) -> VoxelMedium:
    """A homogeneous 20 x 20 m box (x, y in -10..10 m) from z0 to z1, one voxel deep per 5 m, albedo 0.5."""
    depth = int(round((z1 - z0) / 5.0))
    world_from_index = np.diag([5.0, 5.0, 5.0, 1.0])
    world_from_index[:3, 3] = [-10.0 + 2.5, -10.0 + 2.5, z0 + 2.5]
    return VoxelMedium("box", np.ones((4, 4, depth), np.float32), world_from_index, np.full(3, sigma),
                       np.full(3, 0.5))


def wall_frame(media, device: str, seed: int = 0):
    """The path tracer's layer of ``media`` before a grey wall at z = 0, 60 m from the camera, the sun behind the
    camera, through the frame's passes (the plan, the media pass)."""
    wall = quad("wall", [[-60.0, -60.0, 0.0], [60.0, -60.0, 0.0], [60.0, 60.0, 0.0], [-60.0, 60.0, 0.0]],
                (0.4, 0.4, 0.4))
    camera = perspective_camera((0.0, 0.0, 60.0), (0.0, 0.0, -1.0))
    scene = Scene(camera=camera, sun=Sun(unit((0.0, 0.3, 1.0)), np.ones(3)), media=tuple(media), meshes=(wall,))
    plan = make_plan(scene, technique="path_tracer", settings={"spp": "64", "seed": str(seed)},
                     resolution=(WALL_SIZE, WALL_SIZE), device=device)
    assert plan.passes == ("media",)  # the path tracer draws the wall: no surfaces pass
    main, _ = render_layers(plan, scene)
    return main


def test_a_volume_cut_by_a_wall_shows_its_front_part(device):
    """A box from z = -15 to 5 m through the wall renders as its front part alone (z = 0..5 m: z-tests per pixel
    and over the box's centre), a box wholly behind the wall as the bare wall (whose every path is the same
    Lambertian next event, so exactly), and the front part does show over the wall."""
    cut = wall_frame([box(-15.0, 5.0)], device)
    front = wall_frame([box(0.0, 5.0)], device, seed=1)
    behind = wall_frame([box(-15.0, 0.0)], device, seed=2)
    bare = wall_frame([], device, seed=3)
    centre = (slice(WALL_SIZE // 2 - 3, WALL_SIZE // 2 + 3),) * 2
    z, _ = z_scores(cut, front)
    variance = (cut.aovs["variance"] + front.aovs["variance"])[centre].sum()
    z_centre = (cut.radiance - front.radiance)[centre].sum() / np.sqrt(variance)
    assert np.max(np.abs(z)) < 5.0 and abs(z_centre) < 4.0
    np.testing.assert_allclose(behind.radiance, bare.radiance, rtol=1e-5)
    shown = (front.radiance - bare.radiance)[centre].sum() / np.sqrt(front.aovs["variance"][centre].sum())
    assert abs(shown) > 10.0
    assert np.all(cut.transmittance == 0.0)


@pytest.mark.parametrize("ground", [False, True], ids=["no_ground", "ground_below"])
def test_camera_under_a_mesh_stays_finite_and_dark(device, ground):
    """The camera 5 m under a 2 km square, looking up at its back in a uniform environment and a high sun: the
    back's own sunlight is 0 (its normal turned down), so without ground every path gives albedo L_env (its bounce
    escapes downwards); with a ground 50 m below, lit only beyond the square's shadow, the image stays finite,
    non-negative and far below the sunlight that would leak through the square."""
    albedo, ground_albedo, elevation = 0.5, 0.5, math.radians(60.0)
    sun = Sun(np.array([math.cos(elevation), math.sin(elevation), 0.0]), np.full(3, 2.0))
    camera = perspective_camera((0.0, -5.0, 0.0), unit((0.1, 1.0, 0.05)))
    scene = Scene(camera=camera, sun=sun, meshes=(square(0.0, 1.0e3, (albedo,) * 3),),
                  ground=Ground(-50.0, np.full(3, ground_albedo)) if ground else None)
    layer = traced(scene, device, 8, spp=16, environment=0.0 if ground else 1.0)
    assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
    if not ground:
        np.testing.assert_allclose(layer.radiance, albedo * 1.0, rtol=1e-6)
        return
    leak = albedo * ground_albedo * 2.0 * math.sin(elevation) / math.pi  # the ground's direct light, reflected
    assert layer.radiance.mean() < 0.05 * leak
