"""Half-angle slicing: the optically thin limit, extreme cases, the low-albedo mode and convergence."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, add_field, look_rotation, render_layer, write_stage

from warpsky.render.plan import make_plan
from warpsky.techniques.slicing.slicing import Slicing
from warpsky.usd.stage import StageReader


def pixel_radius(scene, size: int, centre: np.ndarray) -> np.ndarray:
    """Angle [deg] between each pixel's view direction (camera model, pixel centres) and ``centre``."""
    camera = scene.camera.conformed(size, size)
    rows, cols = np.mgrid[0:size, 0:size]
    directions = np.stack([camera.pixel_direction(c + 0.5, r + 0.5, size, size)
                           for r, c in zip(rows.ravel(), cols.ravel(), strict=True)])
    return np.degrees(np.arccos(np.clip(directions @ centre, -1.0, 1.0))).reshape(size, size)


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
    layer = sliced(stage, device, 16, slice_count=512, xi=0)  # xi models thick-cloud back-scatter: none here
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


def smooth_blob(path, size: int = 16):
    """A Gaussian puff on a size^3 grid, zero at the faces (clouds have soft edges; a hard-edged box converges only
    at first order in the slice spacing whatever the light update, because of where planes cut its faces)."""
    x = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    blob = np.exp(-4.0 * (X**2 + Y**2 + Z**2)).astype(np.float32)
    blob[[0, -1]] = 0.0
    blob[:, [0, -1]] = 0.0
    blob[:, :, [0, -1]] = 0.0
    np.save(path, blob)
    return path


@pytest.mark.parametrize("equation", [0, 24])
def test_slice_count_convergence(tmp_path, device, equation):
    """|I_512 - I_256| <= 1/2 |I_256 - I_128|. Measured (12x12, cpu, defaults): equation 0 5.8e-7 then 1.26e-7
    (ratio 0.22: second order); Riley's Eq. 24 9.2e-6 then 4.5e-6 (0.49: first order), so it is held to the
    issue's 1/2 with a 5% margin. `python evaluation/benchmarks/bench_slicing.py --convergence` prints the longer
    sequence."""
    spec = StageSpec(volume_file=smooth_blob(tmp_path / "blob.npy"), extinction_scale=0.3,
                     camera_position=(3.0, 4.0, 42.0), camera_rotation=look_rotation((-0.05, -0.06, -1.0)),
                     sun_direction=(0.4, 0.8, 0.3), phase="hg", g=0.8)
    stage = write_stage(tmp_path / "conv.usda", spec)
    images = {n: sliced(stage, device, 12, slice_count=n, light_equation=equation).radiance for n in (128, 256, 512)}
    coarse = np.abs(images[256] - images[128]).mean()
    fine = np.abs(images[512] - images[256]).mean()
    print(f"equation {equation}: |I256 - I128| = {coarse:.3g}, |I512 - I256| = {fine:.3g}, ratio {fine / coarse:.3f}")
    assert fine <= (0.35 if equation == 0 else 0.525) * coarse, (coarse, fine)


def test_both_light_equations_render_and_differ(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.3, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, 0.8, 0.5), phase="hg", g=0.85)
    stage = write_stage(tmp_path / "eq.usda", spec)
    limit = sliced(stage, device, 8, slice_count=64, light_equation=0)
    eq24 = sliced(stage, device, 8, slice_count=64, light_equation=24)
    eq25 = sliced(stage, device, 8, slice_count=64, light_equation=25)
    for layer in (limit, eq24, eq25):
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
    assert not np.allclose(eq24.radiance, eq25.radiance)
    assert not np.allclose(limit.radiance, eq24.radiance)


def test_sun_below_the_ground_lights_nothing(tmp_path, homogeneous_npy, device):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.1, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, -0.2, 0.5), ground=(-30.0, 0.5))
    layer = sliced(write_stage(tmp_path / "night.usda", spec), device, 8, slice_count=16)
    assert np.all(layer.radiance == 0.0) and np.all(np.isfinite(layer.transmittance))
    assert layer.transmittance.min() < 0.5  # the cloud still hides what lies behind it


@pytest.mark.slow
def test_rain_sheet_shows_the_primary_bow(tmp_path, homogeneous_npy, species_phase, device):
    """A thin rain sheet lit from behind the camera: the radial profile of rendered radiance (per unit opacity)
    around the antisolar point peaks at the primary bow's radius, measured from pixel positions."""
    species_phase("rain")  # build (or load) the rain tables in the session cache
    sun = np.array([0.0, np.sin(np.radians(10.0)), np.cos(np.radians(10.0))])
    look = -sun
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.0, camera_position=(0.0, 0.0, 0.0),
                     camera_rotation=look_rotation(look), focal_length=12.0, aperture=(36.0, 36.0),
                     volume_extent=((-3000.0, -3000.0, -400.0), (3000.0, 3000.0, -300.0)),
                     sun_direction=tuple(sun), clipping=(0.1, 1e5))
    stage = write_stage(tmp_path / "rain.usda", spec)
    add_field(stage, "rain", homogeneous_npy, scale=2e-4)  # optical depth ~0.02 across the sheet
    scene = StageReader(stage).scene_at(None)
    size = 96
    layer = Slicing(Slicing.Settings(slice_count=64, orders=8, xi=0.0), device=device).render(scene, size, size)
    radius = pixel_radius(scene, size, look)
    opacity = 1.0 - layer.transmittance[..., 1]
    seen = (opacity > 1e-4) & (radius > 30.0) & (radius < 50.0)
    per_opacity = layer.radiance[..., 1][seen] / opacity[seen]
    peak = float(radius[seen][np.argmax(per_opacity)])
    print(f"rendered primary bow radius {peak:.2f} deg")
    assert 41.4 <= peak <= 42.5, peak


@pytest.mark.slow
def test_cirrus_sheet_shows_the_22_degree_halo(tmp_path, homogeneous_npy, species_phase, device):
    """A thin ice-crystal sheet between the camera and the sun: a ring of peak radiance 22 deg around the sun."""
    species_phase("ice")
    sun = np.array([0.0, np.sin(np.radians(30.0)), -np.cos(np.radians(30.0))])
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.0, camera_position=(0.0, 0.0, 0.0),
                     camera_rotation=look_rotation(sun), focal_length=18.0, aperture=(36.0, 36.0),
                     volume_extent=((-20000.0, 7000.0, -20000.0), (20000.0, 7500.0, 20000.0)),
                     sun_direction=tuple(sun), clipping=(0.1, 1e6))
    stage = write_stage(tmp_path / "cirrus.usda", spec)
    add_field(stage, "ice", homogeneous_npy, scale=4e-5)  # optical depth ~0.02 through the layer
    scene = StageReader(stage).scene_at(None)
    size = 96
    layer = Slicing(Slicing.Settings(slice_count=64, orders=8, xi=0.0), device=device).render(scene, size, size)
    radius = pixel_radius(scene, size, sun)
    opacity = 1.0 - layer.transmittance[..., 1]
    seen = (opacity > 1e-4) & (radius > 15.0) & (radius < 30.0)
    per_opacity = layer.radiance[..., 1][seen] / opacity[seen]
    peak = float(radius[seen][np.argmax(per_opacity)])
    print(f"rendered halo radius {peak:.2f} deg")
    assert 21.3 <= peak <= 22.7, peak


def test_cloud_sheet_shows_the_glory(tmp_path, homogeneous_npy, species_phase, device):
    """A thin sheet of 10 um droplets lit from behind the camera: brightest (per unit opacity) at the antisolar
    point, darker a few degrees out (the glory's first dark ring)."""
    species_phase("cloud")
    sun = np.array([0.0, np.sin(np.radians(20.0)), np.cos(np.radians(20.0))])
    look = -sun
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.0, camera_position=(0.0, 0.0, 0.0),
                     camera_rotation=look_rotation(look), focal_length=120.0, aperture=(36.0, 36.0),
                     volume_extent=((-3000.0, -3000.0, -400.0), (3000.0, 3000.0, -300.0)),
                     sun_direction=tuple(sun), clipping=(0.1, 1e5))
    stage = write_stage(tmp_path / "glory.usda", spec)
    add_field(stage, "cloud", homogeneous_npy, scale=2e-4)
    scene = StageReader(stage).scene_at(None)
    size = 64
    layer = Slicing(Slicing.Settings(slice_count=32, orders=8, xi=0.0), device=device).render(scene, size, size)
    radius = pixel_radius(scene, size, look)
    per_opacity = layer.radiance[..., 1] / np.maximum(1.0 - layer.transmittance[..., 1], 1e-12)
    centre = per_opacity[radius < 0.5].mean()
    ring = per_opacity[(radius > 3.0) & (radius < 6.0)].mean()
    print(f"rendered glory: centre / 3-6 deg ring = {centre / ring:.2f}")
    assert centre > 2.0 * ring, (centre, ring)


def test_rotating_scene_camera_and_sun_together_leaves_the_image_unchanged(tmp_path, device):
    import dataclasses

    rng = np.random.default_rng(2)
    grid = tmp_path / "blob.npy"
    np.save(grid, (rng.random((6, 6, 6)) ** 2).astype(np.float32))
    spec = StageSpec(volume_file=grid, extinction_scale=0.2, camera_position=(5.0, 6.0, 40.0),
                     camera_rotation=look_rotation((-0.1, -0.15, -1.0)), sun_direction=(0.5, 0.7, 0.2),
                     phase="hg", g=0.8)
    scene = StageReader(write_stage(tmp_path / "blob.usda", spec)).scene_at(None)
    angle = np.radians(37.0)
    rot = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
    shift = np.array([1.0e5, 0.0, -3.0e4])  # and far from the origin
    m4 = np.eye(4)
    m4[:3, :3] = rot
    m4[:3, 3] = shift
    medium = dataclasses.replace(scene.media[0], world_from_index=m4 @ scene.media[0].world_from_index)
    camera = dataclasses.replace(scene.camera, position=rot @ scene.camera.position + shift,
                                 rotation=rot @ scene.camera.rotation)
    sun = dataclasses.replace(scene.sun, direction=rot @ scene.sun.direction)
    turned = dataclasses.replace(scene, media=(medium,), camera=camera, sun=sun)
    settings = Slicing.Settings(slice_count=64)
    a = Slicing(settings, device=device).render(scene, 16, 16)
    b = Slicing(settings, device=device).render(turned, 16, 16)
    assert a.radiance.max() > 0.0
    np.testing.assert_allclose(b.radiance, a.radiance, rtol=2e-3, atol=1e-4 * a.radiance.max())
    np.testing.assert_allclose(b.transmittance, a.transmittance, atol=1e-4)


def test_xi_per_volume_from_usd(tmp_path, homogeneous_npy, device):
    """``warpsky:slicing:xi`` on a Volume overrides the technique's ``xi`` for that medium only."""
    from pxr import Sdf, Usd

    from warpsky.core.errors import SceneError

    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.2, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.3, 0.8, 0.5), phase="hg", g=0.85)
    stage_path = write_stage(tmp_path / "xi.usda", spec)
    no_xi = sliced(stage_path, device, 8, slice_count=32, xi=0)
    with_xi = sliced(stage_path, device, 8, slice_count=32, xi=0.2)
    assert with_xi.radiance.sum() > 1.05 * no_xi.radiance.sum()
    stage = Usd.Stage.Open(str(stage_path))
    attr = stage.GetPrimAtPath("/World/Cloud").CreateAttribute("warpsky:slicing:xi", Sdf.ValueTypeNames.Float)
    attr.Set(0.0)
    stage.Save()
    authored = sliced(stage_path, device, 8, slice_count=32, xi=0.2)
    np.testing.assert_array_equal(authored.radiance, no_xi.radiance)
    attr.Set(-1.0)
    stage.Save()
    with pytest.raises(SceneError, match=r"/World/Cloud.*warpsky:slicing:xi"):
        StageReader(stage_path).scene_at(None)


def test_single_voxel_and_orders_beyond_the_table(tmp_path, device):
    """A volume of one voxel, and a thick cloud whose expected scattering count runs far past the last tabulated
    order (orders=2, optical depth ~400): finite, non-negative, transmittance in [0, 1]."""
    one = tmp_path / "one.npy"
    np.save(one, np.ones((1, 1, 1), dtype=np.float32))
    spec = StageSpec(volume_file=one, extinction_scale=20.0, camera_position=(0.0, 0.0, 40.0),
                     sun_direction=(0.2, 0.9, 0.3), phase="hg", g=0.85)
    for orders in (60, 2):
        layer = sliced(write_stage(tmp_path / f"one{orders}.usda", spec), device, 12, orders=orders)
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
        assert layer.transmittance.min() >= 0.0 and layer.transmittance.max() <= 1.0
        assert layer.transmittance.min() < 1e-6 and layer.radiance.max() > 0.0  # the voxel is there, opaque, lit


def stripe_residual(layer, bright_rows: int = 8) -> float:
    """Row-to-row striping of a smooth sheet: the rms residual of its row profile (central third of the columns)
    about a quartic fit, relative to its mean, over the covered rows above the bright rows next to the sun."""
    width = layer.radiance.shape[1]
    middle = slice(width // 3, 2 * width // 3)
    covered = np.flatnonzero((1.0 - layer.transmittance[:, middle, 1] > 0.05).all(axis=1))[:-bright_rows]
    profile = layer.radiance[covered, middle].mean(axis=(1, 2))
    x = np.arange(profile.size)
    residual = profile - np.polyval(np.polyfit(x, profile, 4), x)
    return float(np.sqrt(np.mean(residual**2)) / profile.mean())


@pytest.mark.parametrize("padding", [0, 1])  # hard box faces; faces ramped over a voxel, as in real data
def test_uniform_sheet_seen_from_below_has_no_row_stripes(tmp_path, device, padding):
    """A flat, uniform 1 km sheet of 250 m voxels at 8 km, seen from below looking 28 deg up into a sun 10 deg
    high: the anvil's geometry, where one eye sample per slice (about a voxel apart) let the sheet's faces fall
    between samples differently from one image row to the next. The rows' residual about a smooth fit was 4.5%
    (hard faces) and 1.1% (ramped faces) then; sampling the eye ray a half voxel apart inside each slice's slab,
    clipped to the box, gives 0.2% and 0.1%."""
    grid = np.zeros((64, 4 + 2 * padding, 64), dtype=np.float32)
    grid[:, padding:padding + 4, :] = 1.0
    np.save(tmp_path / "sheet.npy", grid)
    up, sun = np.radians(28.0), np.radians(10.0)
    top = 8000.0 + 250.0 * grid.shape[1]
    spec = StageSpec(volume_file=tmp_path / "sheet.npy", extinction_scale=6e-4, camera_position=(0.0, 0.0, 0.0),
                     camera_rotation=look_rotation((np.cos(up), np.sin(up), 0.0)), focal_length=12.0,
                     aperture=(36.0, 24.0), volume_extent=((0.0, 8000.0, -8000.0), (16000.0, top, 8000.0)),
                     sun_direction=(np.cos(sun), np.sin(sun), 0.0), phase="hg", g=0.8, clipping=(1.0, 1e6))
    scene = StageReader(write_stage(tmp_path / "sheet.usda", spec)).scene_at(None)
    layer = Slicing(Slicing.Settings(), device=device).render(scene, 96, 64)
    residual = stripe_residual(layer)
    print(f"row residual {residual:.5f}")
    assert residual < 0.004, residual
