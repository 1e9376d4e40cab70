"""UsdLux DomeLight as the environment, and several DistantLights summed: reading (lat-long orientation, errors),
the path tracer and hybrid in a white furnace, a black dome leaving every pixel as it was, the fast techniques'
ambient light against the thin-medium closed form, and two suns rendering the sum of their images."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from conftest import StageSpec, look_rotation, write_stage

from warpsky.core.errors import SceneError
from warpsky.light.dome import DomeLight, dome_radiance, dome_struct, mean_radiance, upper_hemisphere
from warpsky.model.scene import Dome
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan
from warpsky.usd.stage import StageReader


@wp.kernel
def lookup(light: DomeLight, d: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = dome_radiance(light, d[i])


def write_latlong(path, rgb: np.ndarray):
    """An RGB float EXR of the (H, W, 3) image ``rgb``."""
    import OpenEXR

    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": np.ascontiguousarray(rgb, dtype=np.float32)}).write(str(path))
    return path


def add_dome(stage_path, *, intensity=1.0, color=(1.0, 1.0, 1.0), texture=None, texture_format=None,
             rotate_y=None, orient_to_up=False):
    """Add a /World/Dome DomeLight to the stage at ``stage_path``."""
    from pxr import Gf, Sdf, Usd, UsdLux

    stage = Usd.Stage.Open(str(stage_path))
    dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
    dome.CreateIntensityAttr(intensity)
    dome.CreateColorAttr(Gf.Vec3f(*color))
    if texture is not None:
        dome.CreateTextureFileAttr(Sdf.AssetPath(str(texture)))
    if texture_format is not None:
        dome.CreateTextureFormatAttr(texture_format)
    if orient_to_up:
        dome.OrientToStageUpAxis()
    if rotate_y is not None:
        dome.AddRotateYOp().Set(rotate_y)
    stage.Save()
    return stage_path


def add_distant_light(stage_path, name, direction, intensity):
    """Add a DistantLight ``/World/<name>`` shining from ``direction`` (warpsky Y-up axes, Y-up stage)."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    from evaluation.family_stages import rotation_towards

    stage = Usd.Stage.Open(str(stage_path))
    light = UsdLux.DistantLight.Define(stage, f"/World/{name}")
    light.CreateIntensityAttr(intensity)
    m = np.eye(4)
    m[:3, :3] = rotation_towards(direction)
    UsdGeom.Xformable(light.GetPrim()).AddTransformOp().Set(Gf.Matrix4d(m.T.tolist()))
    stage.Save()
    return stage_path


def render_frame(stage, device, size, technique, **settings):
    """(media layer, Frame) of the stage rendered and composited as ``warpsky render`` does."""
    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique=technique, settings={k: str(v) for k, v in settings.items()},
                     resolution=(size, size), device=device)
    main, layers = render_layers(plan, scene)
    return main, composite(layers, far=scene.camera.far)


@pytest.fixture
def box(tmp_path, homogeneous_npy):
    """A stage maker: the 20 m homogeneous box seen from 42 m, overrides as StageSpec fields."""

    def make(name="box", **overrides):
        spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.05, camera_position=(3.0, 4.0, 42.0),
                         camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3))
        for key, value in overrides.items():
            setattr(spec, key, value)
        return write_stage(tmp_path / f"{name}.usda", spec)

    return make


# ------------------------------------------------------------------------------------------------------- reading
def latlong_direction(row: float, col: float, height: int, width: int) -> np.ndarray:
    """Dome-local unit direction of texel (row, col) in OpenEXR's lat-long convention."""
    lat = (0.5 * (height - 1) - row) * math.pi / (height - 1)
    lon = (0.5 * (width - 1) - col) * 2.0 * math.pi / (width - 1)
    return np.array([math.cos(lat) * math.sin(lon), math.sin(lat), math.cos(lat) * math.cos(lon)])


def test_uniform_dome_reads_color_intensity_exposure(box):
    from pxr import Usd, UsdLux

    stage = add_dome(box(), intensity=2.0, color=(1.0, 0.5, 0.25))
    usd = Usd.Stage.Open(str(stage))
    UsdLux.DomeLight(usd.GetPrimAtPath("/World/Dome")).CreateExposureAttr(1.0)
    usd.Save()
    dome = StageReader(stage).scene_at(None).dome
    np.testing.assert_allclose(dome.color, [4.0, 2.0, 1.0], rtol=1e-6)
    np.testing.assert_allclose(dome.radiance([[0.0, 1.0, 0.0], [0.6, -0.8, 0.0]]), [[4.0, 2.0, 1.0]] * 2)
    np.testing.assert_allclose(mean_radiance(dome), [4.0, 2.0, 1.0])


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_latlong_texel_maps_to_its_direction(box, tmp_path, up):
    """A texture bright in one texel: the dome's radiance towards that texel's direction (rotated by the prim, on a
    Z-up stage oriented with OrientToStageUpAxis) is the texel's, and a direction far from it is dark."""
    height, width, row, col = 9, 17, 2, 5
    rgb = np.zeros((height, width, 3), np.float32)
    rgb[row, col] = (3.0, 2.0, 1.0)
    texture = write_latlong(tmp_path / "env.exr", rgb)
    stage = write_stage(tmp_path / f"dome{up}.usda", StageSpec(sun_direction=None), up=up)
    add_dome(stage, texture=texture, texture_format="latlong", orient_to_up=up == "Z", rotate_y=90.0)
    dome = StageReader(stage).scene_at(None).dome
    local = latlong_direction(row, col, height, width)
    turn = math.radians(90.0)  # rotateY 90: dome-local +Z goes to world +X
    rotation = np.array([[math.cos(turn), 0, math.sin(turn)], [0, 1, 0], [-math.sin(turn), 0, math.cos(turn)]])
    world = rotation @ local
    np.testing.assert_allclose(dome.radiance(world), [3.0, 2.0, 1.0], rtol=1e-5)
    assert np.all(dome.radiance(-world) == 0.0)
    assert np.all(dome.radiance(local) < 1e-6)  # unrotated: another texel
    # The image centre (latitude 0, longitude 0) is the dome's +Z.
    np.testing.assert_allclose(latlong_direction((height - 1) // 2, (width - 1) // 2, height, width), [0, 0, 1],
                               atol=1e-12)


def test_textured_means_weigh_texels_by_solid_angle():
    """A texture bright only in its top row (the pole): its bilinear radiance falls linearly to 0 over the first
    row spacing a = pi/8, so the mean over the sphere is (1 - sin(a)/a) / 2 = 0.0127, not the texel mean 1/9; a
    texture bright above the equator and dark below (0.5 on it) has mean 1/2."""
    pole = np.zeros((9, 16, 3), np.float32)
    pole[0] = 1.0
    a = math.pi / 8.0
    exact = 0.5 * (1.0 - math.sin(a) / a)
    np.testing.assert_allclose(mean_radiance(Dome(1.0, pole)), exact, rtol=5e-3)  # the 256 x 512 grid: 0.24 %
    np.testing.assert_allclose(mean_radiance(Dome(1.0, pole), 1024), exact, rtol=4e-4)  # converging: 0.025 %
    halves = np.zeros((9, 16, 3), np.float32)
    halves[:4], halves[4] = 1.0, 0.5
    np.testing.assert_allclose(mean_radiance(Dome(2.0, halves)), 1.0, rtol=1e-6)
    upper, cosine_weighted = upper_hemisphere(Dome(2.0, halves))
    assert 1.8 < upper[0] < 2.0 and 1.9 < cosine_weighted[0] < 2.0  # the dim band lies near the horizon


def test_kernel_lookup_matches_the_host_lookup(tmp_path):
    """The kernels' bilinear lat-long lookup equals :meth:`Dome.radiance` in random directions."""
    rng = np.random.default_rng(1)
    angle = 0.7
    rotation = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    dome = Dome((1.0, 2.0, 0.5), rng.random((6, 12, 3)).astype(np.float32), rotation)
    directions = rng.normal(size=(256, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)

    out = wp.zeros(len(directions), dtype=wp.vec3, device="cpu")
    wp.launch(lookup, dim=len(directions), inputs=[dome_struct(dome, "cpu"),
                                                   wp.array(directions.astype(np.float32), dtype=wp.vec3)],
              outputs=[out], device="cpu")
    np.testing.assert_allclose(out.numpy(), dome.radiance(directions), rtol=1e-4, atol=1e-4)


def test_missing_texture_names_prim_attribute_and_file(box, tmp_path):
    stage = add_dome(box(), texture=tmp_path / "nowhere.exr")
    with pytest.raises(SceneError, match=r"/World/Dome\.inputs:texture:file.*nowhere\.exr"):
        StageReader(stage).scene_at(None)


def test_unsupported_texture_format_is_an_error(box, tmp_path):
    texture = write_latlong(tmp_path / "env.exr", np.ones((4, 8, 3), np.float32))
    stage = add_dome(box(), texture=texture, texture_format="mirroredBall")
    with pytest.raises(SceneError, match=r"/World/Dome: inputs:texture:format 'mirroredBall' is not supported"):
        StageReader(stage).scene_at(None)


def test_radiance_hdr_reads_and_other_formats_are_named(box, tmp_path, capsys):
    """A Radiance .hdr dome (written by OpenImageIO) reads as the same lat-long map as the EXR; negative texels
    (filter ringing) are clamped to 0 with one warning naming the prim; a file in a format nothing here reads
    (RenderMan .tex is not an image OpenImageIO knows) is refused as such, not as a missing file."""
    oiio = pytest.importorskip("OpenImageIO")
    rng = np.random.default_rng(2)
    rgb = rng.random((8, 16, 3)).astype(np.float32) * 4.0
    hdr = tmp_path / "env.hdr"
    out = oiio.ImageOutput.create(str(hdr))
    out.open(str(hdr), oiio.ImageSpec(16, 8, 3, "float"))
    out.write_image(rgb)
    out.close()
    dome = StageReader(add_dome(box(), texture=hdr)).scene_at(None).dome
    # RGBE: 8-bit mantissas under the pixel's shared exponent
    assert np.all(np.abs(dome.texture - rgb) <= rgb.max(axis=-1, keepdims=True) / 64.0)
    ringing = rgb.copy()
    ringing[0, :3] = -0.2
    exr = write_latlong(tmp_path / "ringing.exr", ringing)
    capsys.readouterr()
    dome = StageReader(add_dome(box(), texture=exr)).scene_at(None).dome
    assert dome.texture.min() == 0.0 and dome.texture[0, :3].max() == 0.0
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "/World/Dome" in err and "9 negative" in err
    tex = tmp_path / "env.tex"
    tex.write_bytes(b"\x00\x01RenderMan texture, not an image format OpenImageIO reads" * 4)
    with pytest.raises(SceneError, match=r"/World/Dome\.inputs:texture:file: texture file .*env\.tex is in a "
                                         r"format warpsky cannot read"):
        StageReader(add_dome(box(), texture=tex)).scene_at(None)


def test_several_distant_lights_are_the_sun_and_extra_suns(box):
    stage = add_distant_light(box(), "Moon", (-0.5, 0.4, 0.2), 0.1)
    scene = StageReader(stage).scene_at(None)
    assert scene.sun.name == "/World/Sun"
    assert [s.name for s in scene.extra_suns] == ["/World/Moon"]
    np.testing.assert_allclose(scene.extra_suns[0].irradiance, 0.1)


# ------------------------------------------------------------------------------------------------------ rendering
@pytest.mark.parametrize("technique", ["single_scatter", "path_tracer"])
def test_black_dome_renders_exactly_as_no_dome(box, device, technique):
    plain = box("plain")
    black = add_dome(box("black"), intensity=0.0)
    assert StageReader(black).scene_at(None).dome is None
    settings = {"spp": 4} if technique == "path_tracer" else {}
    _, a = render_frame(plain, device, 8, technique, **settings)
    _, b = render_frame(black, device, 8, technique, **settings)
    assert np.array_equal(a.rgba, b.rgba)
    assert np.array_equal(a.transmittance, b.transmittance)


@pytest.mark.parametrize("technique,settings", [
    ("path_tracer", {"spp": 256}),
    ("hybrid", {"spp": 256, "denoise": 0, "target_error": 0}),
])


def test_white_furnace_under_a_uniform_dome(box, device, technique, settings):
    """Albedo 1, no sun, no ground or air, a uniform dome of radiance 1.5: every pixel sees exactly the dome."""
    stage = add_dome(box(sun_direction=None, extinction_scale=0.2, phase="hg", g=0.6), intensity=1.5)
    _, frame = render_frame(stage, device, 8, technique, **settings)
    seen = frame.rgba[..., :3]
    assert seen.mean() == pytest.approx(1.5, abs=0.015)  # 64 pixels x 3 of 256 paths each
    np.testing.assert_allclose(seen, 1.5, atol=0.25)


def test_path_traced_background_shows_the_texture_where_the_camera_looks(tmp_path, device):
    """A camera looking at the bright half of a dome (longitudes 0..pi: the dome's +X side) sees it; one looking
    the other way sees the dark half."""
    rgb = np.zeros((8, 16, 3), np.float32)
    rgb[:, :8] = (2.0, 1.0, 0.5)  # left half: longitude +pi .. 0
    texture = write_latlong(tmp_path / "half.exr", rgb)
    for name, forward, expected in (("east", (1.0, 0.1, 0.3), (2.0, 1.0, 0.5)), ("west", (-1.0, 0.1, 0.3), 0.0)):
        stage = write_stage(tmp_path / f"{name}.usda", StageSpec(sun_direction=None, focal_length=200.0,
                                                                 camera_rotation=look_rotation(forward)))
        add_dome(stage, texture=texture)
        _, frame = render_frame(stage, device, 4, "path_tracer", spp=1)
        np.testing.assert_allclose(frame.rgba[..., :3], np.broadcast_to(expected, (4, 4, 3)), atol=1e-5)


@pytest.mark.parametrize("technique", ["single_scatter", "slicing"])
def test_thin_cloud_ambient_matches_the_closed_form(tmp_path, device, technique):
    """A thin box (optical depth 0.02 across) under a uniform dome, no sun: the centre pixels see sigma_s L times
    the length through the box, to 3% (the zenith occlusion and the eye's own attenuation take about 2%)."""
    npy = tmp_path / "box.npy"
    np.save(npy, np.ones((8, 8, 8), np.float32))
    stage = write_stage(tmp_path / "thin.usda", StageSpec(volume_file=npy, extinction_scale=0.001,
                                                          sun_direction=None, focal_length=500.0))
    add_dome(stage, intensity=2.0)
    layer, _ = render_frame(stage, device, 8, technique)
    centre = layer.radiance[3:5, 3:5]  # the media's light, without the dome behind them
    expected = 0.001 * 2.0 * 20.0  # sigma_s L length; the rays are within 0.5 deg of the axis
    np.testing.assert_allclose(centre, expected, rtol=0.03)


@pytest.mark.parametrize("technique", ["single_scatter", "slicing"])
def test_two_distant_lights_render_the_sum_of_their_images(box, device, technique):
    sun, moon = (0.4, 0.8, 0.3), (-0.5, 0.4, 0.2)
    both = add_distant_light(box("both", sun_direction=sun), "Moon", moon, 0.3)
    only_sun = box("sun", sun_direction=sun)
    only_moon = box("moon", sun_direction=moon, sun_intensity=0.3)
    frames = [render_frame(stage, device, 8, technique)[1] for stage in (both, only_sun, only_moon)]
    np.testing.assert_allclose(frames[0].rgba[..., :3], frames[1].rgba[..., :3] + frames[2].rgba[..., :3],
                               rtol=1e-6, atol=1e-9)
    assert np.array_equal(frames[0].transmittance, frames[1].transmittance)


def test_stratiform_stage_with_air_sums_its_lights_and_takes_the_dome(tmp_path, device):
    """The stratocumulus stage (sky pass, stratiform layer over a textured ground, a voxel cloud): a second
    DistantLight adds its own image, and a dome brightens the layer and shows through the air above the horizon."""
    from pxr import Usd
    from test_stratiform_scene import write_layer_stage

    npy = tmp_path / "cloud.npy"
    np.save(npy, np.ones((6, 6, 6), np.float32))
    stages = {}
    for name in ("both", "sun", "moon", "dome"):
        folder = tmp_path / name
        folder.mkdir()
        stages[name] = write_layer_stage(folder / "layer.usda", volume=npy)
    moon = (-0.2, 0.5, 0.6)
    add_distant_light(stages["both"], "Moon", moon, 0.2)
    add_distant_light(stages["moon"], "Moon", moon, 0.2)
    usd = Usd.Stage.Open(str(stages["moon"]))
    usd.GetPrimAtPath("/World/Sun").SetActive(False)
    usd.Save()
    add_dome(stages["dome"], intensity=0.05)
    (both_layer, both), (sun_layer, sun), (_, moon_frame), (dome_layer, dome) = (
        render_frame(stages[name], device, 12, "single_scatter") for name in ("both", "sun", "moon", "dome"))
    np.testing.assert_allclose(both.rgba[..., :3], sun.rgba[..., :3] + moon_frame.rgba[..., :3], rtol=1e-5,
                               atol=1e-7)
    covered = (sun_layer.transmittance < 0.9).all(axis=-1)
    assert covered.any()
    assert np.all((dome_layer.radiance - sun_layer.radiance)[covered] > 0.0)
    assert np.all(dome.rgba[..., :3] >= sun.rgba[..., :3] - 1e-6)


def test_dome_lies_beyond_the_air(tmp_path, device):
    """With an atmosphere (sky pass), the dome replaces black space: seen through the air's transmittance above the
    horizon, hidden below it (sea level)."""
    from conftest import add_atmosphere

    from warpsky.light.background import pixel_directions

    spec = StageSpec(sun_direction=(0.3, 0.5, 0.2), camera_rotation=look_rotation((0.0, 0.05, -1.0)),
                     camera_position=(0.0, 10.0, 0.0))
    plain = add_atmosphere(write_stage(tmp_path / "air.usda", spec))
    domed = add_dome(add_atmosphere(write_stage(tmp_path / "air_dome.usda", spec)), intensity=3.0)
    _, without = render_frame(plain, device, 8, "single_scatter")
    _, with_dome = render_frame(domed, device, 8, "single_scatter")
    scene = StageReader(domed).scene_at(None)
    directions = pixel_directions(scene.camera, 8, 8)
    atmosphere = scene.atmosphere
    column = atmosphere.beta_sea_level * np.exp(-atmosphere.gamma * 10.0) / atmosphere.gamma
    up = directions[..., 1] > 0.1
    assert up.any() and (~up).any()
    expected = 3.0 * np.exp(-column / directions[..., 1:2])
    added = with_dome.rgba[..., :3] - without.rgba[..., :3]
    np.testing.assert_allclose(added[up], np.broadcast_to(expected, added.shape)[up], rtol=1e-4)
    assert np.all(added[directions[..., 1] < 0.0] == 0.0)
