"""Orthographic cameras (USD reading, parallel view rays in the techniques, slicing's refusal) and the camera
matrices written to EXR headers (worldToCamera, worldToNDC) checked against the kernels' own view rays."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from conftest import StageSpec, look_rotation, path_traced, render_layer, write_stage

from warpsky.core.errors import UsageError
from warpsky.model.camera_rays import PinholeCamera, camera_ray_at, camera_ray_origin, pinhole_camera
from warpsky.model.scene import Camera, Projection, as_imath_rows
from warpsky.usd.stage import StageReader

SIGMA = 0.05  # extinction of the test box [1/m]
HALF = 10.0  # the box spans [-10, 10]^3 m
VIEW = 32.0  # orthographic view width and height [m]
SIZE = 16  # image size: pixel centres 2 m apart at x, y = -15, -13, ..., 15 m
INSIDE = slice(3, 13)  # pixels whose centres lie over the box (|x|, |y| = 9 m at most; the next are 11 m out)


@wp.kernel
def pixel_rays(cam: PinholeCamera, samples: wp.array(dtype=wp.vec4), origins: wp.array(dtype=wp.vec3),
               directions: wp.array(dtype=wp.vec3)):
    """The kernels' view ray through the point (fx, fy) of pixel (row, col), with samples holding (row, col, fx, fy)."""
    i = wp.tid()
    s = samples[i]
    origins[i] = camera_ray_origin(cam, int(s[0]), int(s[1]), s[2], s[3])
    directions[i] = camera_ray_at(cam, int(s[0]), int(s[1]), s[2], s[3])


def kernel_rays(camera: Camera, width: int, height: int, samples: np.ndarray):
    """(origins, directions) of the kernels' rays for ``samples`` rows (row, col, fx, fy), on the CPU."""
    cam = pinhole_camera(camera.conformed(width, height), width, height)
    n = len(samples)
    with wp.ScopedDevice("cpu"):
        origins = wp.zeros(n, dtype=wp.vec3)
        directions = wp.zeros(n, dtype=wp.vec3)
        wp.launch(pixel_rays, dim=n, inputs=[cam, wp.array(samples.astype(np.float32), dtype=wp.vec4), origins,
                                              directions])
        return origins.numpy().astype(np.float64), directions.numpy().astype(np.float64)


SAMPLES = np.array([[0, 0, 0.0, 0.0], [0, 0, 0.5, 0.5], [3, 17, 0.25, 0.75], [15, 19, 1.0, 1.0], [7, 4, 0.9, 0.1],
                    [11, 10, 0.5, 0.5]])


def test_world_to_camera_of_a_rotated_translated_camera():
    # turned 90 degrees about +Y: right is world -Z, up +Y, and the view (-back) world -X
    rotation = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    camera = Camera("c", (10.0, 2.0, -5.0), rotation, 0.05, 0.036, 0.024)
    point = np.array([10.0 - 3.0, 2.0 + 2.0, -5.0 - 1.0, 1.0])  # 3 m ahead, 2 m up, 1 m right
    np.testing.assert_allclose(camera.world_to_camera() @ point, [1.0, 2.0, -3.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(camera.world_to_camera(left_handed=True) @ point, [1.0, 2.0, 3.0, 1.0], atol=1e-12)
    np.testing.assert_array_equal(as_imath_rows(camera.world_to_camera()), camera.world_to_camera().T)


@pytest.mark.parametrize("projection", list(Projection))
def test_world_to_ndc_puts_the_kernels_rays_on_their_pixels(projection):
    """A point along the kernels' ray through (col + fx, row + fy) lands at NDC ((col + fx) / W, (row + fy) / H),
    y down, whatever the camera's offsets, rotation, position far from the origin and conforming."""
    width, height = 20, 16
    if projection is Projection.PERSPECTIVE:
        apertures = (0.030, 0.036, 0.036, 0.003, -0.002)  # focal, width, height, offsets [m]: conforming widens it
    else:
        apertures = (0.050, 40.0, 30.0, 5.0, -3.0)  # view 40 x 30 m shifted 5 m right and 3 m down
    camera = Camera("c", (1.0e5, 50.0, -2.0e4), look_rotation((0.3, -0.2, -1.0)), *apertures, near=0.5, far=1.0e4,
                    projection=projection)
    origins, directions = kernel_rays(camera, width, height, SAMPLES)
    forward = camera.forward
    for t in (3.0, 250.0):
        points = camera.position + origins + t * directions
        ndc = np.c_[points, np.ones(len(points))] @ camera.world_to_ndc(width, height).T
        ndc = ndc[:, :3] / ndc[:, 3:]
        np.testing.assert_allclose(ndc[:, 0] * width, SAMPLES[:, 1] + SAMPLES[:, 2], atol=2e-4)
        np.testing.assert_allclose(ndc[:, 1] * height, SAMPLES[:, 0] + SAMPLES[:, 3], atol=2e-4)
        depth = (points - camera.position) @ forward
        if projection is Projection.PERSPECTIVE:
            expected_z = camera.far * (depth - camera.near) / ((camera.far - camera.near) * depth)
        else:
            expected_z = (depth - camera.near) / (camera.far - camera.near)
        np.testing.assert_allclose(ndc[:, 2], expected_z, atol=1e-6)
    if projection is Projection.ORTHOGRAPHIC:
        np.testing.assert_allclose(directions, np.broadcast_to(forward, directions.shape), atol=1e-6)
        np.testing.assert_allclose(origins @ forward, 0.0, atol=1e-3)  # in the plane through the eye
    else:
        assert np.all(origins == 0.0)


def orthographic_stage(path, npy, *, up="Y", mpu=1.0, projection="orthographic"):
    """The 20 m box of extinction SIGMA seen from 100 m along -Z by a VIEW x VIEW m orthographic camera."""
    from pxr import Usd, UsdGeom

    spec = StageSpec(volume_file=npy, extinction_scale=SIGMA, camera_position=(0.0, 0.0, 100.0),
                     aperture=(10.0 * VIEW, 10.0 * VIEW), focal_length=400.0, sun_direction=(0.4, 0.8, 0.3))
    write_stage(path, spec, up=up, mpu=mpu)
    stage = Usd.Stage.Open(str(path))
    UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).CreateProjectionAttr(projection)
    stage.Save()
    return path


@pytest.mark.parametrize("up,mpu", [("Y", 1.0), ("Z", 0.01)])
def test_orthographic_camera_reads_its_view_size_in_metres(tmp_path, homogeneous_npy, up, mpu):
    from pxr import Usd, UsdGeom

    path = orthographic_stage(tmp_path / "ortho.usda", homogeneous_npy, up=up, mpu=mpu)
    camera = StageReader(path).scene_at(None).camera
    assert camera.projection is Projection.ORTHOGRAPHIC
    assert camera.horizontal_aperture == pytest.approx(VIEW)
    assert camera.vertical_aperture == pytest.approx(VIEW)
    np.testing.assert_allclose(camera.position, [0.0, 0.0, 100.0], atol=1e-9)
    # USD's own frustum: the window of an orthographic camera is the view's extent in scene units
    stage = Usd.Stage.Open(str(path))
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera")).GetCamera(Usd.TimeCode.Default())
    window = gf.frustum.window
    assert (window.GetMax()[0] - window.GetMin()[0]) * mpu == pytest.approx(VIEW)
    assert camera.conformed(24, 12).projection is Projection.ORTHOGRAPHIC


def test_orthographic_box_has_one_transmittance_single_scatter(tmp_path, homogeneous_npy, device):
    """Parallel rays all cross the 20 m box: exp(-SIGMA 20) over the pixels above it, 1 beside it; the same box
    seen in perspective from the same place (a 4 x 4 pixel patch, film slopes 0.025 and 0.075) is crossed at
    slants that lengthen the path by 0.06% to 0.56%."""
    path = orthographic_stage(tmp_path / "ortho.usda", homogeneous_npy)
    _, layer = render_layer(path, device, SIZE, SIZE, min_transmittance=0.0)
    inside = np.zeros((SIZE, SIZE), dtype=bool)
    inside[INSIDE, INSIDE] = True
    expected = math.exp(-SIGMA * 2.0 * HALF)
    np.testing.assert_allclose(layer.transmittance[inside], expected, rtol=1e-4)
    assert np.all(layer.transmittance[~inside] == 1.0)
    # depth along the axis: 90 m to the box plus the opacity-weighted mean depth inside it
    mean_inside = (1.0 - math.exp(-1.0) * 2.0) / SIGMA / (1.0 - math.exp(-1.0))
    np.testing.assert_allclose(layer.depth[inside], 90.0 + mean_inside, rtol=2e-3)
    assert np.ptp(layer.depth[inside]) < 1e-3
    radiance = layer.radiance[inside]
    assert np.all(np.isfinite(radiance)) and radiance.min() > 0.0

    perspective = orthographic_stage(tmp_path / "persp.usda", homogeneous_npy, projection="perspective")
    _, seen = render_layer(perspective, device, SIZE, SIZE, min_transmittance=0.0)
    crossed = seen.transmittance[..., 1][seen.transmittance[..., 1] < 1.0]
    assert crossed.size == 16
    assert np.ptp(crossed) > 1e-3


def test_orthographic_box_has_one_transmittance_path_tracer(tmp_path, homogeneous_npy, device):
    path = orthographic_stage(tmp_path / "ortho.usda", homogeneous_npy)
    layer = path_traced(path, device, SIZE, spp=64, max_bounces=2, seed=3)
    expected = math.exp(-SIGMA * 2.0 * HALF)
    inside = layer.transmittance[INSIDE, INSIDE]
    # 100 pixels x 64 binary-ish estimates of exp(-1): the mean's standard error is below 0.006
    assert inside.mean() == pytest.approx(expected, abs=0.03)
    assert np.abs(inside - expected).max() < 0.35
    outside = np.ones((SIZE, SIZE), dtype=bool)
    outside[INSIDE, INSIDE] = False
    assert np.all(layer.transmittance[outside] == 1.0)
    assert np.all(np.isfinite(layer.radiance)) and layer.radiance[INSIDE, INSIDE].mean() > 0.0


def test_orthographic_box_has_one_transmittance_hybrid(tmp_path, homogeneous_npy, device):
    from warpsky.render.plan import make_plan
    from warpsky.techniques.hybrid.hybrid import Hybrid

    scene = StageReader(orthographic_stage(tmp_path / "ortho.usda", homogeneous_npy)).scene_at(None)
    settings = {"spp": "4", "seed": "3", "target_error": "0", "denoise": "0"}
    plan = make_plan(scene, technique="hybrid", settings=settings, resolution=(SIZE, SIZE), device=device)
    layer = Hybrid(plan.settings, device=device).render(scene, SIZE, SIZE)
    np.testing.assert_allclose(layer.transmittance[INSIDE, INSIDE], math.exp(-SIGMA * 2.0 * HALF), rtol=1e-4)
    assert np.all(np.isfinite(layer.radiance)) and layer.radiance[INSIDE, INSIDE].min() > 0.0


def test_slicing_refuses_an_orthographic_camera(tmp_path, homogeneous_npy):
    from warpsky.render.plan import make_plan

    scene = StageReader(orthographic_stage(tmp_path / "ortho.usda", homogeneous_npy)).scene_at(None)
    with pytest.raises(UsageError, match=r"camera /World/Camera is orthographic.*single_scatter"):
        make_plan(scene, technique="slicing", resolution=(SIZE, SIZE))


def test_orthographic_sky_transmittance_follows_each_rows_altitude(device):
    """Parallel rays climbing at 30 degrees from a view window 4 km wide and 8 km tall: each row's air to space is
    the column above its own start, beta H exp(-h / H) / sin(30 deg), with h the row's altitude."""
    from warpsky.model.scene import Atmosphere, Scene
    from warpsky.passes.sky.sky import Sky

    elevation = math.radians(30.0)
    forward = (0.0, math.sin(elevation), -math.cos(elevation))
    camera = Camera("ortho", (0.0, 5000.0, 0.0), look_rotation(forward), 0.05, 4000.0, 8000.0,
                    projection=Projection.ORTHOGRAPHIC)
    atmosphere = Atmosphere()
    front, _ = Sky(device=device).render(Scene(camera, None, atmosphere=atmosphere), 4, 8)
    window_y = (0.5 - (np.arange(8) + 0.5) / 8) * 8000.0  # each row's centre up the view window
    altitude = 5000.0 + window_y * math.cos(elevation)  # the window's up axis climbs at cos(30 deg)
    depth = np.outer(np.exp(-altitude / atmosphere.scale_height), atmosphere.beta_sea_level)
    expected = np.exp(-depth * atmosphere.scale_height / math.sin(elevation))
    np.testing.assert_allclose(front.transmittance, np.broadcast_to(expected[:, None, :], (8, 4, 3)), rtol=1e-4)


def test_orthographic_stratiform_layer_maps_texels_to_pixels_at_any_distance(device):
    """Looking straight up through a 2.4 km window at 24 px, each pixel's vertical ray meets the centre of one
    100 m texel of an overcast at 1.5 km: a clear 3 x 2 texel block opens exactly 6 pixels, and the image is the
    same from the ground and from 1 km up (in perspective it would shrink with the distance)."""
    from warpsky.model.scene import Atmosphere, Scene, Sun
    from warpsky.model.stratiform import StratiformLayer
    from warpsky.passes.stratiform.stratiform import Stratiform

    thickness = np.full((24, 24), 300.0, np.float32)
    thickness[12:15, 4:6] = 0.0
    layer = StratiformLayer(thickness, 1500.0, (-1200.0, -1200.0), (2400.0, 2400.0))
    images = []
    for height in (0.0, 1000.0):
        camera = Camera("ortho", (0.0, height, 0.0), look_rotation((0.0, 1.0, 0.0)), 0.05, 2400.0, 2400.0, far=1e5,
                        projection=Projection.ORTHOGRAPHIC)
        scene = Scene(camera, Sun((0.3, 0.8, 0.2), (1.0, 1.0, 1.0)), atmosphere=Atmosphere())
        images.append(Stratiform(device=device).render(scene, 24, 24, layer=layer))
    low, high = images
    assert np.count_nonzero(low.transmittance[..., 1] > 0.5) == 6
    np.testing.assert_allclose(high.transmittance, low.transmittance, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(high.radiance, low.radiance, rtol=1e-4, atol=1e-7)
    hit = low.depth < 1e5  # the cloud base, 1500 m and then 500 m along the axis; the far plane elsewhere
    np.testing.assert_allclose(low.depth[hit], 1500.0, rtol=1e-5)
    np.testing.assert_allclose(high.depth[hit], 500.0, rtol=1e-5)
    np.testing.assert_array_equal(high.depth[~hit], low.depth[~hit])
