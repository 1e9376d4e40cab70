"""Terrain meshes through Warp's BVH: ray hits against the analytic height field, Lambertian shading in closed form,
self-shadows where the geometry puts them, voxel-media shadows, extremes, and meshes read from USD."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.core.errors import SceneError
from warpsky.model.scene import Camera, Dome, Ground, Scene, Sun, VoxelMedium
from warpsky.model.stratiform import GroundTexture
from warpsky.model.terrain import TerrainMesh, read_mesh, read_meshes, triangulate
from warpsky.passes.surfaces.surfaces import Surfaces

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import make_terrain  # noqa: E402

DOWN = (0.0, -1.0, 0.0)


def ortho_camera(position, forward, view: float) -> Camera:
    """An orthographic camera showing a ``view`` x ``view`` metre window."""
    return Camera("ortho", np.asarray(position, float), look_rotation(forward), 50.0, view, view, near=0.5,
                  far=1.0e4, projection="orthographic")


def perspective_camera(position, forward, far: float = 1.0e4) -> Camera:
    return Camera("persp", np.asarray(position, float), look_rotation(forward), 30.0, 36.0, 36.0, near=0.5, far=far)


def pixel_points(camera: Camera, size: int) -> np.ndarray:
    """World (x, y, z) of the orthographic window's pixel centres, (size, size, 3)."""
    s = (np.arange(size) + 0.5) / size - 0.5
    sx, sy = s[None, :] * camera.horizontal_aperture, -s[:, None] * camera.vertical_aperture
    return camera.position + sx[..., None] * camera.rotation[:, 0] + sy[..., None] * camera.rotation[:, 1]


def quad(name: str, corners, albedo=(0.3, 0.3, 0.3)) -> TerrainMesh:
    """Two triangles over four corners given counter-clockwise seen from the front."""
    return TerrainMesh(name, np.asarray(corners, float), np.array([[0, 1, 2], [0, 2, 3]]), albedo)


def floor(y: float, half: float, albedo=(0.3, 0.3, 0.3), name="floor") -> TerrainMesh:
    """A horizontal square facing up."""
    return quad(name, [[-half, y, -half], [-half, y, half], [half, y, half], [half, y, -half]], albedo)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


# ------------------------------------------------------------------------------------------ geometry of hits
def test_hits_follow_the_analytic_height_field(device):
    """Straight-down rays hit the mesh at its exact piecewise-linear interpolant (float tolerance) and the analytic
    surface within the interpolation bound M R^2 / 2 (R = spacing / sqrt 2, the triangles' circumradius)."""
    seed, size, n = 3, 2000.0, 257
    field = make_terrain.TerrainField(seed, size)
    points, triangles = make_terrain.terrain_mesh(size, n, seed)
    camera = ortho_camera((0.0, 1000.0, 0.0), DOWN, 1600.0)
    scene = Scene(camera=camera, meshes=(TerrainMesh("terrain", points, triangles),))
    depth = Surfaces(device=device).depth_only(scene, 32, 32)
    where = pixel_points(camera, 32)
    height = camera.position[1] - depth
    # the interpolant: cell (i, j) splits along its (i, j)-(i+1, j+1) diagonal
    spacing = size / (n - 1)
    u, v = (where[..., 0] + size / 2) / spacing, (where[..., 2] + size / 2) / spacing
    i, j = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - i, v - j
    h = points[:, 1].reshape(n, n)
    ha, hb, hc, hd = h[i, j], h[i + 1, j], h[i, j + 1], h[i + 1, j + 1]
    linear = np.where(fu >= fv, ha + fu * (hb - ha) + fv * (hd - hb), ha + fv * (hc - ha) + fu * (hd - hc))
    np.testing.assert_allclose(height, linear, atol=2e-3)
    bound = field.curvature_bound() * (spacing / math.sqrt(2.0)) ** 2 / 2.0
    error = np.abs(height - field.heights(where[..., 0], where[..., 2]))
    assert error.max() <= bound + 2e-3, (error.max(), bound)
    assert error.max() > 1e-3 * bound  # the comparison sees the interpolation, not a coincidence


# ------------------------------------------------------------------------------------------------ shading
SUN = Sun(unit((0.3, 0.8, 0.2)), np.array([1.0, 0.9, 0.8]))
DOME = Dome(np.array([0.1, 0.15, 0.2]))


def test_flat_mesh_renders_as_the_ground_plane(device):
    """A flat mesh at the plane's height with its albedo gives the plane's pixels, which are the closed form
    albedo / pi (E sin e) + albedo L_sky."""
    albedo = np.array([0.2, 0.4, 0.6])
    camera = perspective_camera((3.0, 50.0, -7.0), unit((0.2, -0.5, -1.0)))
    plane = Scene(camera=camera, sun=SUN, dome=DOME, ground=Ground(5.0, albedo))
    mesh = Scene(camera=camera, sun=SUN, dome=DOME, meshes=(floor(5.0, 1.0e5, albedo),))
    surfaces = Surfaces(device=device)
    a, b = surfaces.render(plane, 40, 32), surfaces.render(mesh, 40, 32)
    hit = a.transmittance[..., 0] == 0.0
    assert 0 < hit.sum() < hit.size  # ground and sky both in view
    np.testing.assert_array_equal(a.transmittance, b.transmittance)
    np.testing.assert_allclose(b.radiance, a.radiance, rtol=1e-5, atol=1e-7)
    # the ray-triangle test in float32 errs by a few roundings of the corners' coordinates (1e5 m: 8 mm each)
    np.testing.assert_allclose(b.depth, a.depth, rtol=1e-5, atol=4 * 1.2e-7 * 1.0e5)
    expected = albedo / math.pi * SUN.irradiance * SUN.direction[1] + albedo * DOME.color
    np.testing.assert_allclose(a.radiance[hit], np.broadcast_to(expected, (hit.sum(), 3)), rtol=1e-5)
    assert np.all(a.radiance[~hit] == 0.0) and np.all(a.depth[~hit] == camera.far)


def test_albedo_map_is_read_at_world_x_z_on_meshes_as_on_the_plane(device):
    """A 2 x 2 map over [-40, 40]^2 m: at the texel centres (x, z = +-20 m) and beyond the map (+-60 m, edge texels
    continued) a mesh shows each texel's albedo, and the ground plane with the same map shows the same pixels."""
    texels = np.array([[[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]], [[0.7, 0.8, 0.9], [0.9, 0.1, 0.5]]])
    texture = GroundTexture(texels, (-40.0, -40.0), (80.0, 80.0))
    camera = ortho_camera((0.0, 30.0, 0.0), DOWN, 160.0)
    mesh = dataclasses.replace(floor(0.0, 100.0), albedo_map=texture)
    surfaces = Surfaces(device=device)
    a = surfaces.render(Scene(camera=camera, sun=SUN, dome=DOME, meshes=(mesh,)), 4, 4)
    b = surfaces.render(Scene(camera=camera, sun=SUN, dome=DOME, ground=Ground(0.0, albedo_map=texture)), 4, 4)
    np.testing.assert_allclose(a.radiance, b.radiance, rtol=1e-6)
    light = SUN.irradiance * SUN.direction[1] / math.pi + DOME.color
    where = pixel_points(camera, 4)
    expected = texels[(where[..., 0] > 0).astype(int), (where[..., 2] > 0).astype(int)] * light
    np.testing.assert_allclose(a.radiance, expected, rtol=1e-5)


@pytest.mark.parametrize("sun_direction", [(0.5, 0.7, 0.3), (-0.9, 0.3, 0.1)], ids=["facing", "behind"])
def test_lambert_closed_form_on_a_tilted_plane(device, sun_direction):
    """A plane tilted 30 deg about z: albedo / pi E max(n.l, 0) + albedo L_sky (1 + n_y) / 2."""
    tilt = math.radians(30.0)
    normal = np.array([math.sin(tilt), math.cos(tilt), 0.0])
    along = np.array([math.cos(tilt), -math.sin(tilt), 0.0])  # in the plane, across z
    z = np.array([0.0, 0.0, 1.0])
    corners = [-along * 500 - z * 500, -along * 500 + z * 500, along * 500 + z * 500, along * 500 - z * 500]
    mesh = quad("tilted", corners, (0.5, 0.25, 0.125))
    assert np.allclose(unit(np.cross(corners[1] - corners[0], corners[2] - corners[0])), normal)
    sun = Sun(unit(sun_direction), np.array([2.0, 2.0, 2.0]))
    camera = perspective_camera(normal * 200.0 + (1.0, 2.0, 3.0), -normal)
    layer = Surfaces(device=device).render(Scene(camera=camera, sun=sun, dome=DOME, meshes=(mesh,)), 16, 16)
    cosine = max(float(normal @ sun.direction), 0.0)
    expected = mesh.albedo / math.pi * sun.irradiance * cosine + mesh.albedo * DOME.color * (1 + normal[1]) / 2
    assert np.all(layer.transmittance == 0.0)
    np.testing.assert_allclose(layer.radiance, np.broadcast_to(expected, layer.radiance.shape), rtol=1e-5)


def test_wall_shadows_the_floor_where_the_geometry_says(device):
    """A wall 20 m high along x = 0 under a sun at 30 deg from +x: the floor is in shadow for -H / tan e < x < 0."""
    height, elevation = 20.0, math.radians(30.0)
    wall = quad("wall", [[0, 0, -200], [0, 0, 200], [0, height, 200], [0, height, -200]])
    sun = Sun(np.array([math.cos(elevation), math.sin(elevation), 0.0]), np.ones(3))
    camera = ortho_camera((0.0, 100.0, 0.0), DOWN, 128.0)
    scene = Scene(camera=camera, sun=sun, dome=DOME, meshes=(floor(0.0, 200.0), wall))
    layer = Surfaces(device=device).render(scene, 64, 64)
    x = pixel_points(camera, 64)[..., 0]
    shadowed = (x > -height / math.tan(elevation)) & (x < 0.0)
    a = 0.3
    lit = a / math.pi * math.sin(elevation) + a * DOME.color
    np.testing.assert_allclose(layer.radiance[shadowed], np.broadcast_to(a * DOME.color, (shadowed.sum(), 3)),
                               rtol=1e-5)
    np.testing.assert_allclose(layer.radiance[~shadowed], np.broadcast_to(lit, ((~shadowed).sum(), 3)), rtol=1e-5)
    assert shadowed.sum() == 17 * 64  # pixel columns at x = -33 .. -1 m


def test_voxel_slab_shadows_the_terrain(device):
    """A homogeneous slab (sigma = 0.01 /m, 20 m thick) above the floor: the sunlight is exp(-sigma h / sin e), the
    sky light exp(-sigma h)."""
    sigma, thickness, elevation = 0.01, 20.0, math.radians(60.0)
    shape = np.array([4, 2, 4])
    world_from_index = np.diag([250.0, 10.0, 250.0, 1.0])
    world_from_index[:3, 3] = [-500.0 + 125.0, 50.0 + 5.0, -500.0 + 125.0]
    slab = VoxelMedium("slab", np.ones(shape, np.float32), world_from_index, np.full(3, sigma), np.ones(3))
    assert np.allclose(slab.world_corners().min(axis=0), [-500, 50, -500])
    sun = Sun(np.array([math.cos(elevation), math.sin(elevation), 0.0]), np.array([1.0, 2.0, 3.0]))
    camera = ortho_camera((0.0, 30.0, 0.0), DOWN, 100.0)
    mesh = floor(0.0, 300.0, (0.5, 0.5, 0.5))
    layer = Surfaces(device=device).render(
        Scene(camera=camera, sun=sun, dome=DOME, media=(slab,), meshes=(mesh,)), 8, 8)
    direct = 0.5 / math.pi * sun.irradiance * math.sin(elevation) * math.exp(-sigma * thickness / math.sin(elevation))
    expected = direct + 0.5 * DOME.color * math.exp(-sigma * thickness)
    np.testing.assert_allclose(layer.radiance, np.broadcast_to(expected, layer.radiance.shape), rtol=1e-5)


def test_host_sun_transmittance_multiplies_the_sunlight_at_world_points(device):
    """The callback sees world points (100 km out) on the surface and scales only the sunlight."""
    offset = np.array([1.0e5, 0.0, -1.0e5])
    camera = ortho_camera(offset + (0.0, 40.0, 0.0), DOWN, 64.0)
    scene = Scene(camera=camera, sun=SUN, dome=DOME, meshes=(floor(2.0, 100.0),))
    scene = Scene(camera=camera, sun=SUN, dome=DOME,
                  meshes=(TerrainMesh("far", scene.meshes[0].points + offset, scene.meshes[0].triangles),))
    seen = []

    def half_east(points):
        seen.append(points)
        return np.where(points[:, :1] > offset[0], 0.5, 1.0) * np.ones((1, 3))

    layer = Surfaces(device=device).render(scene, 16, 16, sun_transmittance=half_east)
    assert len(seen) == 1 and seen[0].shape == (256, 3)
    np.testing.assert_allclose(seen[0][:, 1], 2.0, atol=1e-3)
    np.testing.assert_allclose(seen[0][:, [0, 2]], pixel_points(camera, 16).reshape(-1, 3)[:, [0, 2]], atol=1e-3)
    sky = 0.3 * DOME.color
    sun = 0.3 / math.pi * SUN.irradiance * SUN.direction[1]
    east = pixel_points(camera, 16)[..., 0] > offset[0]
    np.testing.assert_allclose(layer.radiance[east], np.broadcast_to(sky + 0.5 * sun, (east.sum(), 3)), rtol=1e-5)
    np.testing.assert_allclose(layer.radiance[~east], np.broadcast_to(sky + sun, ((~east).sum(), 3)), rtol=1e-5)


# ------------------------------------------------------------------------------------------------ extremes
@pytest.mark.parametrize("what", ["mesh", "plane"])
def test_camera_under_the_terrain_draws_black_with_one_warning(device, what):
    camera = perspective_camera((0.0, -10.0, 0.0), (0.0, 0.2, -1.0))
    scene = (Scene(camera=camera, sun=SUN, dome=DOME, meshes=(floor(0.0, 1000.0),)) if what == "mesh" else
             Scene(camera=camera, sun=SUN, dome=DOME, ground=Ground(0.0)))
    surfaces = Surfaces(device=device)
    layer = surfaces.render(scene, 16, 16)
    assert len(layer.warnings) == 1 and "under the surface" in layer.warnings[0]
    assert np.all(layer.radiance == 0.0) and np.all(layer.transmittance == 0.0)
    assert np.all(layer.depth == camera.near)
    assert np.all(surfaces.depth_only(scene, 16, 16) == camera.near)
    # one metre higher the same scene renders normally, without a warning
    above = Scene(camera=perspective_camera((0.0, 1.0, 0.0), (0.0, -0.2, -1.0)), sun=SUN, dome=DOME,
                  meshes=scene.meshes, ground=scene.ground)
    layer = surfaces.render(above, 16, 16)
    assert layer.radiance.max() > 0.0 and not layer.warnings


def test_terrain_far_from_the_origin_renders_as_at_the_origin(device):
    points, triangles = make_terrain.terrain_mesh(2000.0, 65, 5)
    shift = np.array([1.0e5, 2.0e4, -1.0e5])
    forward = unit((0.1, -0.35, -1.0))
    images = []
    for offset in (np.zeros(3), shift):
        camera = perspective_camera(offset + (0.0, 600.0, 900.0), forward)
        mesh = TerrainMesh("terrain", points + offset, triangles)
        images.append(Surfaces(device=device).render(Scene(camera=camera, sun=SUN, dome=DOME, meshes=(mesh,)),
                                                         32, 32))
    assert (images[0].transmittance == 0.0).mean() > 0.5
    np.testing.assert_array_equal(images[0].transmittance, images[1].transmittance)
    np.testing.assert_allclose(images[1].depth, images[0].depth, rtol=2e-5)
    np.testing.assert_allclose(images[1].radiance, images[0].radiance, rtol=1e-4, atol=1e-6)


def test_a_million_triangles_build_and_render(device):
    points, triangles = make_terrain.terrain_mesh(4000.0, 709, 2)
    mesh = TerrainMesh("big", points, triangles)
    assert mesh.triangle_count > 1_000_000
    camera = perspective_camera((0.0, 900.0, 2500.0), unit((0.0, -0.4, -1.0)))
    started = time.perf_counter()
    layer = Surfaces(device=device).render(Scene(camera=camera, sun=SUN, dome=DOME, meshes=(mesh,)), 32, 32)
    seconds = time.perf_counter() - started
    print(f"\n1e6-triangle BVH build {layer.stats['bvh_seconds']:.3f} s, 32x32 render {seconds:.3f} s on {device}")
    assert layer.stats["triangles"] == mesh.triangle_count
    assert layer.stats["hits"] > 0.5 * 32 * 32
    hit = layer.transmittance[..., 0] == 0.0
    assert np.all(np.isfinite(layer.radiance)) and np.all(layer.radiance[hit].sum(axis=-1) > 0.0)


# ---------------------------------------------------------------------------------------------------- USD
def _stage(tmp_path, *, up="Y", mpu=1.0):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "mesh.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def _reader(stage):
    from warpsky.usd.stage import StageReader

    stage.GetRootLayer().Save()
    return StageReader(stage.GetRootLayer().realPath)


def test_usd_mesh_round_trips_through_read_mesh(tmp_path):
    """Z-up, centimetres, a translate: points in Y-up metres; a quad fans into 2 triangles and a triangle stays;
    per-vertex displayColor is averaged; leftHanded winding is reversed; an invisible mesh is skipped."""
    from pxr import Gf, UsdGeom, Vt

    stage = _stage(tmp_path, up="Z", mpu=0.01)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Terrain")
    local = np.array([[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0], [200, 0, 50]], np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(local))
    mesh.CreateFaceVertexCountsAttr([4, 3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 1, 4, 2])
    mesh.CreateDisplayColorAttr([(0.1, 0.2, 0.3), (0.3, 0.4, 0.5), (0.2, 0.3, 0.4), (0.2, 0.3, 0.4),
                                 (0.2, 0.3, 0.4)])
    UsdGeom.Primvar(mesh.GetDisplayColorAttr()).SetInterpolation(UsdGeom.Tokens.vertex)
    mesh.AddTranslateOp().Set(Gf.Vec3d(1000.0, 2000.0, 300.0))
    hidden = UsdGeom.Mesh.Define(stage, "/World/Hidden")
    hidden.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    hidden.CreateFaceVertexCountsAttr([3])
    hidden.CreateFaceVertexIndicesAttr([0, 1, 2])
    hidden.CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    reader = _reader(stage)
    meshes = read_meshes(reader)
    assert [m.name for m in meshes] == ["/World/Terrain"]
    got = meshes[0]
    stage_points = local.astype(np.float64) + (1000.0, 2000.0, 300.0)
    expected = 0.01 * np.stack([stage_points[:, 0], stage_points[:, 2], -stage_points[:, 1]], axis=-1)
    np.testing.assert_allclose(got.points, expected, atol=1e-9)
    np.testing.assert_array_equal(got.triangles, [[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    np.testing.assert_allclose(got.albedo, [0.2, 0.3, 0.4], atol=1e-6)
    normal = np.cross(got.points[1] - got.points[0], got.points[2] - got.points[0])
    assert normal[1] > 0  # counter-clockwise about the stage's +Z = world +Y
    mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    mesh.GetPrim().CreateAttribute("warpsky:albedo", __import__("pxr").Sdf.ValueTypeNames.Color3f).Set(
        Gf.Vec3f(0.5, 0.6, 0.7))
    again = read_mesh(_reader(stage), stage.GetPrimAtPath("/World/Terrain"), None)
    np.testing.assert_array_equal(again.triangles, [[2, 1, 0], [3, 2, 0], [2, 4, 1]])
    np.testing.assert_allclose(again.albedo, [0.5, 0.6, 0.7], atol=1e-6)


def test_face_of_two_vertices_is_refused_naming_prim_and_attribute(tmp_path):
    from pxr import UsdGeom

    stage = _stage(tmp_path)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Bad")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([3, 2])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 0, 1])
    with pytest.raises(SceneError, match=r"/World/Bad\.faceVertexCounts.*face 1 has 2"):
        read_meshes(_reader(stage))
    with pytest.raises(SceneError, match=r"faceVertexIndices"):
        triangulate([3, 3], [0, 1, 2, 0, 1], 3, "/World/Short")
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    mesh.CreateHoleIndicesAttr([0])
    with pytest.raises(SceneError, match=r"/World/Bad\.holeIndices"):
        read_meshes(_reader(stage))


def test_time_sampled_points_move_the_hit_and_refit_the_bvh(tmp_path, device):
    """Points sampled at t = 1 (y = 0) and t = 2 (y = 10): the hit depth follows, and the second frame refits."""
    from pxr import UsdGeom, Vt

    stage = _stage(tmp_path)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Ground")
    base = np.array([[-50, 0, -50], [-50, 0, 50], [50, 0, 50], [50, 0, -50]], np.float32)
    for time_code, y in ((1.0, 0.0), (2.0, 10.0)):
        mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(base + np.float32([0, y, 0])), time_code)
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    reader = _reader(stage)
    camera = ortho_camera((0.0, 100.0, 0.0), DOWN, 50.0)
    surfaces = Surfaces(device=device)
    depths, refitted = [], []
    for time_code in (1.0, 1.5, 2.0):
        scene = Scene(camera=camera, sun=SUN, meshes=read_meshes(reader, time_code))
        layer = surfaces.render(scene, 8, 8)
        depths.append(float(layer.depth.mean()))
        refitted.append(layer.stats["bvh_refitted"])
    np.testing.assert_allclose(depths, [100.0, 95.0, 90.0], rtol=1e-6)
    assert refitted == [False, True, True]


# ------------------------------------------------------------------------------------------ shading normals
def test_vertex_normals_shade_a_flat_quad_as_a_tilted_plane(device):
    """A horizontal quad whose vertex normals all lean 30 deg about z shades as the 30-deg plane of the Lambert
    test (its shading normal), while the rays hit the flat triangles (depth of the flat quad)."""
    tilt = math.radians(30.0)
    normal = np.array([math.sin(tilt), math.cos(tilt), 0.0])
    flat = floor(0.0, 500.0, (0.5, 0.25, 0.125))
    mesh = dataclasses.replace(flat, normals=np.tile(normal, (4, 1)))
    sun = Sun(unit((0.5, 0.7, 0.3)), np.array([2.0, 2.0, 2.0]))
    camera = ortho_camera((3.0, 100.0, -7.0), DOWN, 200.0)
    layer = Surfaces(device=device).render(Scene(camera=camera, sun=sun, dome=DOME, meshes=(mesh,)), 8, 8)
    expected = mesh.albedo / math.pi * sun.irradiance * float(normal @ sun.direction) \
        + mesh.albedo * DOME.color * (1 + normal[1]) / 2
    np.testing.assert_allclose(layer.radiance, np.broadcast_to(expected, layer.radiance.shape), rtol=1e-5)
    np.testing.assert_allclose(layer.depth, 100.0, rtol=1e-6)


def test_vertex_normals_interpolate_across_a_triangle(device):
    """Normals (0, 1, 0) at one edge of a floor and leaning 60 deg at the other: under an overhead sun, the
    radiance follows cos of the normalised barycentric blend, which is not linear in x."""
    lean = np.array([math.sin(math.radians(60.0)), math.cos(math.radians(60.0)), 0.0])
    flat = floor(0.0, 100.0, (1.0, 1.0, 1.0))  # corners (-x,-z), (-x,+z), (+x,+z), (+x,-z)
    normals = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], lean, lean])
    mesh = dataclasses.replace(flat, normals=normals)
    sun = Sun(np.array([0.0, 1.0, 0.0]), np.array([math.pi, math.pi, math.pi]))
    camera = ortho_camera((0.0, 50.0, 0.0), DOWN, 200.0)
    layer = Surfaces(device=device).render(Scene(camera=camera, sun=sun, meshes=(mesh,)), 16, 16)
    x = pixel_points(camera, 16)[..., 0]
    f = (x + 100.0) / 200.0
    blend = (1 - f)[..., None] * np.array([0.0, 1.0, 0.0]) + f[..., None] * lean
    expected = blend[..., 1] / np.linalg.norm(blend, axis=-1)
    np.testing.assert_allclose(layer.radiance[..., 0], expected, rtol=1e-4)


def test_usd_vertex_normals_are_read_through_the_inverse_transpose(tmp_path):
    """``normals`` with vertex interpolation under a non-uniform scale come back as the inverse transpose maps
    them (unit length); faceVarying normals are ignored; a count that does not match the points is refused."""
    from pxr import Gf, UsdGeom

    stage = _stage(tmp_path)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Lean")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 0, 1)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 2, 1])
    mesh.CreateNormalsAttr([(1, 1, 0)] * 3)
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.AddScaleOp().Set(Gf.Vec3f(2.0, 1.0, 1.0))
    got = read_mesh(_reader(stage), mesh.GetPrim(), None)
    np.testing.assert_allclose(got.normals, np.tile(unit((0.5, 1.0, 0.0)), (3, 1)), atol=1e-6)
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)
    assert read_mesh(_reader(stage), mesh.GetPrim(), None).normals is None
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateNormalsAttr([(0, 1, 0)] * 2)
    with pytest.raises(SceneError, match=r"/World/Lean\.normals: vertex normals need one per point \(3\), got 2"):
        read_mesh(_reader(stage), mesh.GetPrim(), None)
