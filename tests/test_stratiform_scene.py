"""Stratiform layers through the normal pipeline: USD prims -> Scene.stratiform_layers -> plan (``warpsky info``) -> the
stratiform pass composited with the sky and voxel media -> EXR; advected thickness maps (Neyret 2003)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.cli.main import main
from warpsky.core.errors import SceneError
from warpsky.core.image import ImageLayer
from warpsky.media.stratiform import thickness as stratiform
from warpsky.media.stratiform.thickness import thickness_at_time
from warpsky.output.exr import read_exr
from warpsky.passes.composite import merge_by_depth
from warpsky.usd.stage import StageReader

SIZE = 20000.0  # [m] of the layer and the ground texture
MAP = 32  # texels per side of the test thickness map


def write_layer_stage(path, *, layer_attrs=None, ground=True, volume=None, frames=None, up="Y"):
    """A real stage: camera on the ground looking up at a stratocumulus at 1 km over a two-colour ground, a sun, air.

    ``layer_attrs`` maps attribute name -> (Sdf type name, value) and overrides the defaults; ``volume`` is an
    optional dense ``.npy`` grid placed in a 200 m box in front of the camera; ``frames`` authors a time range.
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdVol

    data = path.parent
    thickness = stratiform.procedural_thickness(MAP, cover=0.7, max_thickness=400.0, seed=5, feature_texels=4.0)
    np.save(data / "thickness.npy", thickness)
    albedo = np.empty((16, 16, 3), np.float32)
    albedo[:8], albedo[8:] = (0.05, 0.08, 0.12), (0.9, 0.9, 0.92)  # water in the west, snow in the east
    np.save(data / "albedo.npy", albedo)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    if frames is not None:
        stage.SetStartTimeCode(frames[0])
        stage.SetEndTimeCode(frames[1])
        stage.SetTimeCodesPerSecond(0.1)  # one frame = 10 s of cloud time
    UsdGeom.Xform.Define(stage, "/World")
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateFocalLengthAttr(18.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 1.0e5))
    m = np.eye(4)
    m[:3, :3] = look_rotation((0.0, 0.6, -1.0))
    m[:3, 3] = (0.0, 2.0, 0.0)
    up_rot = np.eye(4) if up == "Y" else np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1]])
    UsdGeom.Xformable(cam.GetPrim()).AddTransformOp().Set(Gf.Matrix4d((up_rot @ m).T.tolist()))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun_m = np.eye(4)
    sun_m[:3, :3] = look_rotation((-0.3, -0.77, -0.56))  # light travels along the light's -Z: sun 50 deg up
    UsdGeom.Xformable(sun.GetPrim()).AddTransformOp().Set(Gf.Matrix4d((up_rot @ sun_m).T.tolist()))
    atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
    atmosphere.CreateAttribute("warpsky:atmosphere:altitude", Sdf.ValueTypeNames.Float).Set(0.0)
    if ground:
        plane = UsdGeom.Plane.Define(stage, "/World/Ground")
        plane.CreateAxisAttr(UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
        prim = plane.GetPrim()
        prim.CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.3))
        prim.CreateAttribute("warpsky:albedoMap", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("./albedo.npy"))
        prim.CreateAttribute("warpsky:albedoMapSize", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(SIZE, SIZE))
    layer = UsdGeom.Xform.Define(stage, "/World/Stratocumulus")
    offset = (0.0, 1000.0, 0.0) if up == "Y" else (0.0, 0.0, 1000.0)
    layer.AddTranslateOp().Set(Gf.Vec3d(*offset))
    prim = layer.GetPrim()
    prim.CreateAttribute("warpsky:kind", Sdf.ValueTypeNames.Token, custom=False).Set("stratiformLayer")
    attrs = {
        "warpsky:stratiform:thicknessMap": (Sdf.ValueTypeNames.Asset, Sdf.AssetPath("./thickness.npy")),
        "warpsky:stratiform:size": (Sdf.ValueTypeNames.Float2, Gf.Vec2f(SIZE, SIZE)),
    }
    attrs.update(layer_attrs or {})
    for name, (type_name, value) in attrs.items():
        if value is not None:
            prim.CreateAttribute(name, type_name).Set(value)
    if volume is not None:
        vol = UsdVol.Volume.Define(stage, "/World/Cloud")
        vol.CreateExtentAttr([Gf.Vec3f(-100.0, 100.0, -700.0), Gf.Vec3f(100.0, 300.0, -500.0)])
        asset = UsdVol.OpenVDBAsset.Define(stage, "/World/Cloud/density")
        asset.CreateFilePathAttr(Sdf.AssetPath(str(volume)))
        asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(0.05)
        vol.CreateFieldRelationship("density", asset.GetPath())
    stage.GetRootLayer().Save()
    return path


def run(args, capsys):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def rgba(path):
    return read_exr(path).rgba()


# ---------------------------------------------------------------------------------------------- scene and plan
def test_reader_fills_scene_layers_and_ground_texture(tmp_path):
    for up in ("Y", "Z"):
        stage = write_layer_stage(tmp_path / f"s{up}.usda", up=up)
        scene = StageReader(stage).scene_at(None)
        (layer,) = scene.stratiform_layers
        assert layer.name == "/World/Stratocumulus" and layer.base_altitude == pytest.approx(1000.0)
        assert layer.origin == pytest.approx((-SIZE / 2, -SIZE / 2)) and layer.size == pytest.approx((SIZE, SIZE))
        np.testing.assert_array_equal(layer.thickness, np.load(tmp_path / "thickness.npy"))
        assert layer.radiosity and layer.advection is None
        texture = scene.ground.albedo_map
        assert texture.albedo.shape == (16, 16, 3) and texture.size == pytest.approx((SIZE, SIZE))


def test_info_prints_the_layer_and_radiosity(tmp_path, capsys, homogeneous_npy):
    stage = write_layer_stage(tmp_path / "s.usda")
    code, out, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0
    assert "layer       /World/Stratocumulus: stratiform (Bouthors 2006), base 1000 m" in out
    assert f"map {MAP}x{MAP}" in out and "static map" in out
    # buffers: 20 km + 2 x 8 h margin at 1 texel per h = 1 km -> 36, rounded up to a multiple of 8
    assert "radiosity   on: ground <-> cloud base, buffers 40x40 texels of 1000 m" in out
    assert "media       none: hybrid does not run" in out
    code, out, _ = run(["info", stage, "--device", "cpu", "--set", "stratiform.radiosity=0"], capsys)
    assert code == 0 and "radiosity   off (stratiform.radiosity=0)" in out
    no_ground = write_layer_stage(tmp_path / "n.usda", ground=False)
    code, out, _ = run(["info", no_ground, "--device", "cpu"], capsys)
    assert code == 0 and "radiosity   off: no ground below the layer" in out
    from conftest import StageSpec, write_stage

    plain = write_stage(tmp_path / "plain.usda", StageSpec(volume_file=homogeneous_npy))
    code, out, _ = run(["info", plain, "--device", "cpu"], capsys)
    assert code == 0 and "layers      no layers" in out and "\n  radiosity" not in out and "\n  layer " not in out


@pytest.mark.parametrize(("name", "type_name", "value", "expect"), [
    ("warpsky:stratiform:size", "Float2", (-1.0, 5.0), "warpsky:stratiform:size must be two positive lengths"),
    ("warpsky:stratiform:size", "Float", 5.0, "warpsky:stratiform:size must be a float2"),
    ("warpsky:stratiform:numberDensity", "Float", 0.0, "warpsky:stratiform:numberDensity must be > 0"),
    ("warpsky:stratiform:thicknessScale", "Float", -2.0, "warpsky:stratiform:thicknessScale must be >= 0"),
    ("warpsky:stratiform:thicknessMap", "Asset", "./missing.npy", "warpsky:stratiform:thicknessMap: file"),
    ("warpsky:stratiform:cover", "Float", 0.5, "warpsky:stratiform:cover applies to procedural maps only"),
    ("warpsky:stratiform:radiosity", "Int", 1, "warpsky:stratiform:radiosity must be a bool"),
    ("warpsky:stratiform:thikness", "Float", 1.0, "unknown attribute(s) warpsky:stratiform:thikness"),
    ("warpsky:advection:period", "Float", -5.0, "warpsky:advection:period must be > 0"),
    ("warpsky:advection:curlSpeed", "Float", -1.0, "warpsky:advection:curlSpeed must be >= 0"),
    ("warpsky:advection:wind", "Float3", (1.0, 2.0, 3.0), "warpsky:advection:wind must be a float2 [m/s]"),
    ("warpsky:advection:seed", "Float", 1.5, "warpsky:advection:seed must be an int"),
])
def test_bad_layer_attributes_name_prim_and_attribute(tmp_path, capsys, name, type_name, value, expect):
    from pxr import Gf, Sdf

    wrap = {"Float2": Gf.Vec2f, "Float3": Gf.Vec3f, "Asset": Sdf.AssetPath}.get(type_name, lambda v: v)
    value = wrap(*value) if isinstance(value, tuple) else wrap(value)
    stage = write_layer_stage(tmp_path / "bad.usda",
                              layer_attrs={name: (getattr(Sdf.ValueTypeNames, type_name), value)})
    with pytest.raises(SceneError, match="/World/Stratocumulus") as info:
        StageReader(stage).scene_at(None)
    assert expect in str(info.value)
    code, _, err = run(["render", stage, tmp_path / "bad.exr", "--res", "8x6", "--device", "cpu"], capsys)
    assert code == 2 and "/World/Stratocumulus" in err and not (tmp_path / "bad.exr").exists()


def test_layer_attributes_without_kind_are_an_error(tmp_path):
    from pxr import Usd

    stage_path = write_layer_stage(tmp_path / "kind.usda")
    stage = Usd.Stage.Open(str(stage_path))
    stage.GetPrimAtPath("/World/Stratocumulus").GetAttribute("warpsky:kind").Set("stratiform")
    stage.GetRootLayer().Save()
    with pytest.raises(SceneError, match=r"/World/Stratocumulus: has warpsky:stratiform:\w+ but warpsky:kind"):
        StageReader(stage_path).scene_at(None)


# ---------------------------------------------------------------------------------------------- rendering
def test_cli_renders_the_layer_with_sky_and_radiosity(tmp_path, capsys):
    stage = write_layer_stage(tmp_path / "s.usda")
    on, off = tmp_path / "on.exr", tmp_path / "off.exr"
    assert run(["render", stage, on, "--res", "48x32", "--device", "cpu", "--float"], capsys)[0] == 0
    assert run(["render", stage, off, "--res", "48x32", "--device", "cpu", "--float", "--set",
                "stratiform.radiosity=0"], capsys)[0] == 0
    image = read_exr(on)
    pixels = image.rgba()
    assert np.all(np.isfinite(pixels)) and pixels.min() >= 0.0
    depth = image.channels["depth.Z"]
    cloud = depth < 0.99e5  # the layer's base where it is hit, the clip distance through the gaps
    assert 0.2 < cloud.mean() < 0.95  # cloud and gaps both in view
    assert np.all(pixels[~cloud, 2] > 1.2 * pixels[~cloud, 0])  # blue sky through the gaps (the sky pass ran)
    assert pixels[cloud, :3].mean() > 2 * pixels[~cloud, :3].mean()  # a bright overcast base
    meta = image.metadata
    assert '"radiosity": true' in meta["stratiform"] and '"radiosity_converged": true' in meta["stratiform"]
    assert '"stratiform"' in meta["settings"]
    dark = rgba(off)
    # radiosity adds the ground's light to the cloud base, never removes any
    assert np.all(pixels[cloud, :3] >= dark[cloud, :3] - 1e-6)
    assert pixels[cloud, :3].mean() > 1.02 * dark[cloud, :3].mean()
    # the layer attribute turns it off too, with the same pixels as the setting
    attr = write_layer_stage(tmp_path / "attr.usda",
                             layer_attrs={"warpsky:stratiform:radiosity": (_sdf("Bool"), False)})
    assert run(["render", attr, tmp_path / "attr.exr", "--res", "48x32", "--device", "cpu", "--float"],
               capsys)[0] == 0
    np.testing.assert_array_equal(rgba(tmp_path / "attr.exr"), dark)


def test_layer_composites_with_voxel_media_by_depth(tmp_path, capsys):
    volume = tmp_path / "box.npy"
    np.save(volume, np.ones((4, 4, 4), np.float32))
    stage = write_layer_stage(tmp_path / "v.usda", volume=volume)
    out = tmp_path / "v.exr"
    code, _, err = run(["render", stage, out, "--res", "32x24", "--device", "cpu", "--float", "--technique",
                        "single_scatter"], capsys)
    assert code == 0, err
    both = rgba(out)
    alone = tmp_path / "alone.exr"
    assert run(["render", write_layer_stage(tmp_path / "a.usda"), alone, "--res", "32x24", "--device", "cpu",
                "--float", "--technique", "single_scatter"], capsys)[0] == 0
    layer_only = rgba(alone)
    assert np.all(np.isfinite(both)) and both.min() >= 0.0
    changed = np.abs(both - layer_only).max(axis=-1) > 1e-6
    assert 0 < changed.mean() < 0.5  # the box covers part of the view, in front of the layer
    depth = read_exr(out).channels["depth.Z"]
    assert np.all(depth[changed] < 1000.0)  # the box (~600 m away) is the front-most thing where it shows


def test_merge_by_depth_orders_each_pixel():
    far = 1.0e6
    shape = (1, 2)
    near_first = np.array([[10.0, 50.0]], np.float32)
    a = ImageLayer(np.full((*shape, 3), 1.0, np.float32), np.full((*shape, 3), 0.5, np.float32), near_first)
    b = ImageLayer(np.full((*shape, 3), 2.0, np.float32), np.full((*shape, 3), 0.25, np.float32),
                   np.array([[20.0, 30.0]], np.float32))
    merged = merge_by_depth([a, b], far)
    # pixel 0: a in front (1 + 0.5 * 2 = 2); pixel 1: b in front (2 + 0.25 * 1 = 2.25)
    np.testing.assert_allclose(merged.radiance[0, :, 0], [2.0, 2.25])
    np.testing.assert_allclose(merged.transmittance, 0.125)
    np.testing.assert_allclose(merged.depth, [[10.0, 30.0]])


# ---------------------------------------------------------------------------------------------- advection
def _advected_attrs(wind=(14.0, 5.0), curl=2.0):
    from pxr import Gf

    return {"warpsky:advection:wind": (_sdf("Float2"), Gf.Vec2f(*wind)),
            "warpsky:advection:curlSpeed": (_sdf("Float"), curl),
            "warpsky:advection:curlScale": (_sdf("Float"), 8000.0),
            "warpsky:advection:period": (_sdf("Float"), 400.0),
            "warpsky:advection:seed": (_sdf("Int"), 3)}


def _sdf(name):
    from pxr import Sdf

    return getattr(Sdf.ValueTypeNames, name)


def test_advected_frame_cold_equals_frame_after_its_predecessor(tmp_path, capsys):
    stage = write_layer_stage(tmp_path / "anim.usda", layer_attrs=_advected_attrs(), frames=(1, 6))
    code, out, _ = run(["info", stage, "--device", "cpu", "--time", "5"], capsys)
    assert code == 0 and "advected at t = 50 s: wind [14.0, 5.0] m/s, curl 2 m/s at 8000 m" in out
    args = ["--res", "32x24", "--device", "cpu", "--float"]
    stratiform._ADVECTED.clear()
    assert run(["render", stage, tmp_path / "cold" / "f.####.exr", "--frames", "5", *args], capsys)[0] == 0
    stratiform._ADVECTED.clear()
    assert run(["render", stage, tmp_path / "seq" / "f.####.exr", "--frames", "4:5", *args], capsys)[0] == 0
    cold, seq4, seq5 = (rgba(tmp_path / d / f"f.{n:04d}.exr") for d, n in (("cold", 5), ("seq", 4), ("seq", 5)))
    np.testing.assert_array_equal(cold, seq5)  # random access: bit-identical on one device
    assert np.abs(seq5 - seq4).max() > 1e-3  # and the layer does move between frames


def test_still_advection_shows_the_static_map_and_wind_translates_it(tmp_path):
    still = write_layer_stage(tmp_path / "still.usda", layer_attrs=_advected_attrs(wind=(0.0, 0.0), curl=0.0),
                              frames=(1, 100))
    reader = StageReader(still)
    static = np.load(tmp_path / "thickness.npy")
    for time in (1.0, 37.0, 100.0):
        (layer,) = reader.scene_at(time).stratiform_layers
        assert layer.advection is not None and layer.advection.still
        np.testing.assert_array_equal(thickness_at_time(layer), static)
    # wind along +x carrying the map 3 texels per frame (10 s): the map at frame 2 is the static map shifted by 6
    # texels along axis 0 (world x), and along axis 1 for wind along z
    speed = 3 * SIZE / MAP / 10.0
    for wind, axis in (((speed, 0.0), 0), ((0.0, speed), 1)):
        windy = write_layer_stage(tmp_path / f"wind{axis}.usda", layer_attrs=_advected_attrs(wind=wind, curl=0.0),
                                  frames=(1, 100))
        (layer,) = StageReader(windy).scene_at(2.0).stratiform_layers
        np.testing.assert_allclose(thickness_at_time(layer), np.roll(static, 6, axis=axis), atol=1e-3)
