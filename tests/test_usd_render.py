"""UsdRender settings, products and vars; colour spaces and camera matrices in the header; the Python API.

Real stages written with pxr, real EXRs read back through the OpenEXR bindings.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, write_stage
from conftest import run_cli as run

import warpsky
from warpsky.output.exr import read_exr

#: lin_rec709 -> ACEScg (Bradford D65 -> ACES white), as published with the ACES CG configs.
REC709_TO_ACESCG = np.array([[0.61309732, 0.33952285, 0.04737928],
                             [0.07019422, 0.91635557, 0.01345020],
                             [0.02061560, 0.10956983, 0.86981457]])
FAST = ["--device", "cpu", "--technique", "single_scatter", "--set", "step_length=1"]


@pytest.fixture
def stage(tmp_path, homogeneous_npy):
    return write_stage(tmp_path / "shot.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))


def add_render(stage_path, products, *, settings_attrs=None, second_camera=True):
    """Add /Render/Settings with ``products``: {name: (productName, camera or None, resolution or None,
    [(var name, sourceName, dataType, sourceType)], extra attrs)}."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdRender

    usd = Usd.Stage.Open(str(stage_path))
    if second_camera:
        cam = UsdGeom.Camera.Define(usd, "/World/Side")
        cam.CreateFocalLengthAttr(50.0)
        cam.CreateHorizontalApertureAttr(36.0)
        cam.CreateVerticalApertureAttr(36.0)
        m = np.eye(4)
        m[:3, :3] = look_rotation((-1.0, 0.0, 0.0))
        m[:3, 3] = (40.0, 0.0, 0.0)
        UsdGeom.Xformable(cam.GetPrim()).AddTransformOp().Set(Gf.Matrix4d(m.T.tolist()))
    settings = UsdRender.Settings.Define(usd, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(12, 8))
    settings.CreateCameraRel().SetTargets(["/World/Camera"])
    for name, value in (settings_attrs or {}).items():
        getattr(settings, f"Create{name[0].upper()}{name[1:]}Attr")(value)
    targets = []
    for name, (product_name, camera, resolution, variables, extra) in products.items():
        product = UsdRender.Product.Define(usd, f"/Render/{name}")
        if product_name is not None:
            product.CreateProductNameAttr(product_name)
        if camera is not None:
            product.CreateCameraRel().SetTargets([camera])
        if resolution is not None:
            product.CreateResolutionAttr(Gf.Vec2i(*resolution))
        for attr, value in (extra or {}).items():
            getattr(product, f"Create{attr[0].upper()}{attr[1:]}Attr")(value)
        var_paths = []
        for var_name, source, data_type, source_type in variables:
            var = UsdRender.Var.Define(usd, f"/Render/{name}/{var_name}")
            var.CreateSourceNameAttr(source)
            var.CreateDataTypeAttr(data_type)
            var.CreateSourceTypeAttr(source_type)
            var_paths.append(var.GetPath())
        product.CreateOrderedVarsRel().SetTargets(var_paths)
        targets.append(product.GetPath())
    settings.CreateProductsRel().SetTargets(targets)
    usd.GetRootLayer().Save()
    del Sdf
    return stage_path


def test_two_products_write_their_sequences_with_their_vars(tmp_path, stage, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    add_render(stage, {
        "Beauty": ("out/beauty.$F4.exr", None, None,
                   [("color", "color", "color4f", "raw"), ("depth", "depth", "float", "raw")], None),
        "Side": ("out/side.####.exr", "/World/Side", (8, 6),
                 [("beauty", "Ci", "color3h", "raw"), ("tau", "transmittance", "color3f", "raw")], None),
    })
    code, stdout, err = run(["render", stage, "--frames", "1:2", *FAST], capsys)
    assert code == 0, err
    for frame in (1, 2):
        beauty = read_exr(tmp_path / f"out/beauty.{frame:04d}.exr")
        assert set(beauty.channels) == {"R", "G", "B", "A", "depth.Z"}
        assert (beauty.width, beauty.height) == (12, 8)
        assert beauty.metadata["camera"] == "/World/Camera"
        assert beauty.metadata["orderedChannels"] == "R,G,B,A,depth.Z"
        side = read_exr(tmp_path / f"out/side.{frame:04d}.exr")
        assert set(side.channels) == {"R", "G", "B", "tau.R", "tau.G", "tau.B"}
        assert side.channels["R"].dtype == np.float16 and side.channels["tau.R"].dtype == np.float32
        assert (side.width, side.height) == (8, 6) and side.metadata["camera"] == "/World/Side"
    assert (tmp_path / "out/beauty.log.json").is_file() and (tmp_path / "out/side.log.json").is_file()


def test_one_product_selected_and_out_overrides_its_name(tmp_path, stage, capsys):
    add_render(stage, {
        "A": ("a.####.exr", None, None, [("color", "color", "color4f", "raw")], None),
        "B": ("b.####.exr", None, None, [("color", "color", "color4f", "raw")], None),
    })
    out = tmp_path / "picked.exr"
    code, _, err = run(["render", stage, out, "--product", "/Render/B", *FAST], capsys)
    assert code == 0, err
    assert read_exr(out).channels.keys() == {"R", "G", "B", "A"}
    code, _, err = run(["render", stage, out, *FAST], capsys)
    assert code == 2 and "2 products" in err and "--product" in err


def test_data_window_and_pixel_aspect(tmp_path, stage, capsys):
    add_render(stage, {"P": (str(tmp_path / "w.exr"), None, (16, 8), [("color", "color", "color4f", "raw")],
                             {"dataWindowNDC": (0.25, 0.5, 0.75, 1.0), "pixelAspectRatio": 2.0})})
    code, _, err = run(["render", stage, *FAST], capsys)
    assert code == 0, err
    image = read_exr(tmp_path / "w.exr")
    lo, hi = image.header["dataWindow"]
    assert lo.tolist() == [4, 0] and hi.tolist() == [11, 3]  # the top half, middle half of the columns
    assert image.header["displayWindow"][1].tolist() == [15, 7] and image.header["pixelAspectRatio"] == 2.0
    api = warpsky.render_stage(stage, product="/Render/P", device="cpu", technique="single_scatter",
                               settings={"step_length": 1})
    assert np.array_equal(api.channels["R"], image.channels["R"])
    assert api.frame.rgba.shape == (8, 16, 4)
    # a data window the caller gives wins over the product's and the settings'
    whole = warpsky.render_stage(stage, product="/Render/P", device="cpu", technique="single_scatter",
                                 settings={"step_length": 1}, data_window=(0.0, 0.0, 1.0, 1.0))
    assert whole.window is None and whole.channels["R"].shape == (8, 16)


def test_colorspace_acescg_is_rec709_times_the_standard_matrix(tmp_path, stage, capsys):
    rec, aces = tmp_path / "rec.exr", tmp_path / "aces.exr"
    assert run(["render", stage, rec, "--res", "12x8", "--float", *FAST], capsys)[0] == 0
    assert run(["render", stage, aces, "--res", "12x8", "--float", "--colorspace", "ACEScg", *FAST], capsys)[0] == 0
    a, b = read_exr(rec), read_exr(aces)
    rgb_a = np.stack([a.channels[c] for c in "RGB"], axis=-1)
    rgb_b = np.stack([b.channels[c] for c in "RGB"], axis=-1)
    assert rgb_a.max() > 0.0
    np.testing.assert_allclose(rgb_b, rgb_a @ REC709_TO_ACESCG.T, rtol=1e-5, atol=1e-7)
    np.testing.assert_array_equal(a.channels["A"], b.channels["A"])
    np.testing.assert_array_equal(a.channels["transmittance.R"], b.channels["transmittance.R"])
    assert np.allclose(a.header["chromaticities"], (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290))
    assert np.allclose(b.header["chromaticities"], (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767))
    assert a.header["whiteLuminance"] == 1.0 and b.metadata["colorspace"] == "ACEScg"


def test_camera_matrices_in_the_header(tmp_path, stage, capsys):
    out = tmp_path / "m.exr"
    assert run(["render", stage, out, "--res", "12x8", *FAST], capsys)[0] == 0
    header = read_exr(out).header
    world_to_camera = np.asarray(header["worldToCamera"], dtype=np.float64).T  # Imath rows -> column vectors
    world_to_ndc = np.asarray(header["worldToNDC"], dtype=np.float64).T
    point = np.array([3.0, -2.0, 0.0, 1.0])  # the camera sits at (0, 0, 40) looking down -Z
    np.testing.assert_allclose(world_to_camera @ point, [3.0, -2.0, 40.0, 1.0], atol=1e-4)  # z > 0 in front
    ndc = world_to_ndc @ point
    # The same point through the camera model: film x = f X / depth over the film (36 x 36 at focal length 50,
    # conformed to 12x8 by growing the film to 54 x 36), NDC (0, 0) at the top left.
    col = (50.0 * 3.0 / 40.0 / 54.0 + 0.5) * 12
    row = (0.5 - 50.0 * -2.0 / 40.0 / 36.0) * 8
    np.testing.assert_allclose((ndc[0] / ndc[3] * 12, ndc[1] / ndc[3] * 8), (col, row), atol=1e-4)


def test_api_returns_the_pixels_the_cli_writes(tmp_path, stage, capsys):
    out = tmp_path / "cli.exr"
    assert run(["render", stage, out, "--res", "12x8", "--float", *FAST], capsys)[0] == 0
    written = read_exr(out)
    image = warpsky.render_stage(stage, resolution=(12, 8), device="cpu", technique="single_scatter",
                                 settings={"step_length": 1}, half=False)
    for name in ("R", "G", "B", "A", "depth.Z", "transmittance.G"):
        np.testing.assert_array_equal(image.channels[name], written.channels[name])
    np.testing.assert_array_equal(image.frame.rgba[..., 0], written.channels["R"])
    path = warpsky.render_to_exr(stage, tmp_path / "api.exr", resolution=(12, 8), device="cpu",
                                 technique="single_scatter", settings={"step_length": 1}, half=False)
    np.testing.assert_array_equal(read_exr(path).channels["R"], written.channels["R"])


def test_info_lists_settings_products_and_vars(stage, capsys):
    add_render(stage, {"Beauty": ("b.$F4.exr", None, None, [("color", "color", "color4h", "raw"),
                                                            ("z", "depth", "float", "raw")], None)})
    code, stdout, err = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0, err
    for text in ("render      /Render/Settings", "product     /Render/Beauty -> b.####.exr",
                 "/Render/Beauty/color: color -> R, G, B, A (half)", "/Render/Beauty/z: depth -> Z (float)"):
        assert text in stdout


@pytest.mark.parametrize("case, expected", [
    ("settings_not_settings", "--settings /World/Camera: prim is a Camera, not a RenderSettings"),
    ("no_name", "/Render/P.productName is not authored"),
    ("unknown_source", "RenderVar /Render/P/v.sourceName 'normals' is not a warpsky output; known: color"),
    ("bad_type", "RenderVar /Render/P/v.dataType 'float' does not fit source transmittance"),
    ("technique_aov", "RenderVar /Render/P/v: source single_scatter is written by technique hybrid, not "
                      "single_scatter"),
    ("not_exr", "/Render/P.productName 'x.png' must end in .exr"),
    ("dome_texture_missing", "/World/Dome.inputs:texture:file"),
])
def test_bad_render_prims_exit_2_and_write_nothing(tmp_path, stage, capsys, monkeypatch, case, expected):
    monkeypatch.chdir(tmp_path)
    var = {"unknown_source": ("v", "normals", "color3f", "raw"), "bad_type": ("v", "transmittance", "float", "raw"),
           "technique_aov": ("v", "single_scatter", "color3f", "raw")}.get(case, ("v", "color", "color4f", "raw"))
    name = {"no_name": None, "not_exr": "x.png"}.get(case, "out/p.exr")
    add_render(stage, {"P": (name, None, None, [var], None)})
    if case == "dome_texture_missing":
        from pxr import Sdf, Usd, UsdLux

        usd = Usd.Stage.Open(str(stage))
        UsdLux.DomeLight.Define(usd, "/World/Dome").CreateTextureFileAttr(Sdf.AssetPath("sky/nowhere.exr"))
        usd.GetRootLayer().Save()
        expected += ": texture file "  # and then the file
    args = ["render", stage, *FAST] + (["--settings", "/World/Camera"] if case == "settings_not_settings" else [])
    code, _, err = run(args, capsys)
    assert code == 2
    assert expected in err and len(err.strip().splitlines()) == 1, err
    assert case != "dome_texture_missing" or "nowhere.exr" in err
    assert not (tmp_path / "out").exists()


def _composed_stage(tmp_path, homogeneous_npy):
    """A stage whose cloud sits in a payload, a proxy-purpose second cloud and a variant set choosing the cloud's
    extinction; the camera looks at both."""
    from pxr import Sdf, Usd, UsdGeom, UsdVol

    payload = write_stage(tmp_path / "cloud.usda", StageSpec(volume_file=homogeneous_npy, sun_direction=None))
    path = write_stage(tmp_path / "shot.usda", StageSpec(camera_position=(0, 0, 60)))
    stage = Usd.Stage.Open(str(path))
    holder = stage.DefinePrim("/World/Payloaded")  # typeless: the payload makes it a Volume
    holder.GetPayloads().AddPayload(str(payload), "/World/Cloud")
    proxy = UsdVol.Volume.Define(stage, "/World/Proxy")
    proxy.CreateExtentAttr([(-3, -3, -3), (3, 3, 3)])
    UsdGeom.Imageable(proxy.GetPrim()).CreatePurposeAttr("proxy")
    asset = UsdVol.OpenVDBAsset.Define(stage, "/World/Proxy/density")
    asset.CreateFilePathAttr(Sdf.AssetPath(str(homogeneous_npy)))
    proxy.CreateFieldRelationship("density", asset.GetPath())
    variants = holder.GetVariantSets().AddVariantSet("weather")
    for name, scale in (("fair", 0.01), ("storm", 0.2)):
        variants.AddVariant(name)
        variants.SetVariantSelection(name)
        with variants.GetVariantEditContext():
            holder.CreateAttribute("warpsky:unused", Sdf.ValueTypeNames.Float)
            over = stage.OverridePrim("/World/Payloaded/density")
            over.CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(scale)
    variants.SetVariantSelection("fair")
    stage.GetRootLayer().Save()
    return path


def test_composition_flags_reach_the_render(tmp_path, homogeneous_npy, capsys):
    stage = _composed_stage(tmp_path, homogeneous_npy)
    alpha = {}
    for name, flags in (("loaded", []), ("unloaded", ["--load", "none"]), ("storm", ["--variant", "weather=storm"]),
                        ("proxy", ["--purpose", "proxy", "--load", "none"])):
        out = tmp_path / f"{name}.exr"
        code, _, err = run(["render", stage, out, "--res", "8", *FAST, *flags], capsys)
        assert code == 0, err
        alpha[name] = read_exr(out).channels["A"].astype(np.float64).mean()
    assert alpha["unloaded"] == 0.0  # the payload is the only rendered cloud; the proxy is skipped
    assert 0.0 < alpha["loaded"] < alpha["storm"]  # the variant raises the extinction
    assert alpha["proxy"] > 0.0  # the proxy cloud alone
    code, stdout, _ = run(["info", stage, "--device", "cpu", "--load", "none", "--variant", "weather=storm"],
                          capsys)
    assert code == 0 and "composition payloads: 1 not loaded (--load none)" in stdout
    assert "weather=storm (session layer)" in stdout
    code, _, err = run(["render", stage, tmp_path / "x.exr", *FAST, "--variant", "weather=hail"], capsys)
    assert code == 2 and "hail" in err and "storm" in err and not (tmp_path / "x.exr").exists()


def test_settings_choose_purposes_and_colour_space(tmp_path, homogeneous_npy, capsys):
    from pxr import Usd, UsdRender

    stage = _composed_stage(tmp_path, homogeneous_npy)
    usd = Usd.Stage.Open(str(stage))
    settings = UsdRender.Settings.Define(usd, "/Render/Settings")
    settings.CreateIncludedPurposesAttr(["default", "render", "proxy"])
    settings.CreateMaterialBindingPurposesAttr(["full"])
    settings.GetPrim().GetAttribute("renderingColorSpace").Set("lin_ap1_scene")
    usd.GetRootLayer().Save()
    out = tmp_path / "p.exr"
    code, _, err = run(["render", stage, out, "--res", "8", "--load", "none", *FAST], capsys)
    assert code == 0, err
    assert "materialBindingPurposes ['full'] ignored" in err
    image = read_exr(out)
    assert image.channels["A"].astype(np.float64).mean() > 0.0 and image.metadata["colorspace"] == "ACEScg"
    code, _, err = run(["render", stage, out, "--res", "8", "--load", "none", "--colorspace", "lin_rec709",
                        "--purpose", "render", "--overwrite", *FAST], capsys)
    image = read_exr(out)
    assert code == 0 and image.metadata["colorspace"] == "lin_rec709"
    assert image.channels["A"].astype(np.float64).max() == 0.0  # --purpose wins over includedPurposes


def test_products_sharing_a_camera_come_from_one_render(tmp_path, stage, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    add_render(stage, {
        "Beauty": ("beauty.exr", None, None, [("color", "color", "color4f", "raw")], None),
        "Aovs": ("aovs.exr", None, None, [("single", "single_scatter", "color3f", "raw"),
                                          ("multiple", "multiple_scatter", "color3f", "raw")], None),
    })
    code, stdout, err = run(["render", stage, "--device", "cpu", "--spp", "4", "--set", "denoise=0",
                             "--time-budget", "30"], capsys)
    assert code == 0, err
    beauty, aovs = read_exr(tmp_path / "beauty.exr"), read_exr(tmp_path / "aovs.exr")
    assert "aovs.exr" in stdout and not (tmp_path / "aovs.log.json").exists()  # one render, one log
    rgb = np.stack([beauty.channels[c] for c in "RGB"], axis=-1)
    parts = sum(np.stack([aovs.channels[f"{name}.{c}"] for c in "RGB"], axis=-1) for name in ("single", "multiple"))
    np.testing.assert_allclose(rgb, parts, rtol=1e-5, atol=1e-6)  # no sky: the beauty is exactly the two parts
    code, stdout, err = run(["render", stage, "--device", "cpu", "--spp", "4", "--set", "denoise=0",
                             "--time-budget", "30"], capsys)
    assert code == 0 and "up to date, skipped" in stdout


def test_info_lists_every_light_with_its_irradiance(stage, capsys):
    from pxr import Gf, Usd, UsdGeom, UsdLux

    usd = Usd.Stage.Open(str(stage))
    moon = UsdLux.DistantLight.Define(usd, "/World/Moon")
    moon.CreateIntensityAttr(0.25)
    UsdGeom.Xformable(moon.GetPrim()).AddRotateXOp().Set(-60.0)  # local +Z tilted up: 60 deg elevation
    dome = UsdLux.DomeLight.Define(usd, "/World/Dome")
    dome.CreateIntensityAttr(0.5)
    dome.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    usd.GetRootLayer().Save()
    code, stdout, err = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0, err
    assert "light       /World/Sun: distant" in stdout
    assert "light       /World/Moon: distant, elevation 60.00 deg, irradiance 0.25 at normal incidence" in stdout
    assert "0.216506 on a horizontal surface" in stdout  # 0.25 sin 60 deg
    assert "light       /World/Dome: dome, uniform, mean radiance 0.5, 1.5708 on a horizontal surface" in stdout


def test_time_sampled_product_name_as_solaris_writes_it(tmp_path, stage, capsys, monkeypatch):
    """Houdini Solaris writes productName as one literal file name per time sample: those samples are one
    frame pattern; samples that follow none are refused by name."""
    from pxr import Usd

    monkeypatch.chdir(tmp_path)
    add_render(stage, {"Beauty": (None, None, None, [("color", "color", "color4f", "raw")], None)})
    usd = Usd.Stage.Open(str(stage))
    attr = usd.GetPrimAtPath("/Render/Beauty").GetAttribute("productName")
    for frame in (1, 2, 3):
        attr.Set(f"render/shot_v002.{frame:04d}.exr", float(frame))
    usd.GetRootLayer().Save()
    code, _, err = run(["render", stage, "--frames", "1:2", *FAST], capsys)
    assert code == 0, err
    assert (tmp_path / "render/shot_v002.0001.exr").is_file() and (tmp_path / "render/shot_v002.0002.exr").is_file()
    attr.Set("render/other.0002.exr", 2.0)
    usd.GetRootLayer().Save()
    code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 2 and "/Render/Beauty.productName" in err and "frame pattern" in err
    assert len(err.strip().splitlines()) == 1


def test_overscan_and_tiles_that_share_an_edge(tmp_path, stage, capsys):
    """dataWindowNDC outside the unit square renders overscan (a negative data window, as husk writes it) whose
    image pixels are the plain render's; two tiles split at a pixel centre share no column and miss none."""
    from conftest import add_atmosphere

    add_atmosphere(stage)
    add_render(stage, {
        "Plain": (str(tmp_path / "plain.exr"), None, (64, 16), [("color", "color", "color4f", "raw")], None),
        "Over": (str(tmp_path / "over.exr"), None, (64, 16), [("color", "color", "color4f", "raw")],
                 {"dataWindowNDC": (-0.1, -0.1, 1.1, 1.1)}),
        "Left": (str(tmp_path / "left.exr"), None, (64, 16), [("color", "color", "color4f", "raw")],
                 {"dataWindowNDC": (0.0, 0.0, 0.3828125, 1.0)}),
        "Right": (str(tmp_path / "right.exr"), None, (64, 16), [("color", "color", "color4f", "raw")],
                  {"dataWindowNDC": (0.3828125, 0.0, 1.0, 1.0)}),
    })
    for product in ("Plain", "Over", "Left", "Right"):
        code, _, err = run(["render", stage, "--product", f"/Render/{product}", *FAST], capsys)
        assert code == 0, err
    plain, over = read_exr(tmp_path / "plain.exr"), read_exr(tmp_path / "over.exr")
    lo, hi = over.header["dataWindow"]
    assert lo.tolist() == [-6, -2] and hi.tolist() == [69, 17]
    assert over.header["displayWindow"][1].tolist() == [63, 15]
    inner = over.rgba()[2:18, 6:70]
    np.testing.assert_allclose(inner, plain.rgba(), rtol=2e-3, atol=1e-6)
    sky = over.rgba()[:4, :, 2]  # the overscan holds sky, continuing the image's
    assert sky[:, :6].min() > 0.0 and np.all(np.abs(sky[:, 5] - sky[:, 6]) < 0.05 * sky[:, 6])
    left, right = read_exr(tmp_path / "left.exr"), read_exr(tmp_path / "right.exr")
    assert [v.tolist() for v in left.header["dataWindow"]] == [[0, 0], [23, 15]]
    assert [v.tolist() for v in right.header["dataWindow"]] == [[24, 0], [63, 15]]
    joined = np.concatenate([left.rgba(), right.rgba()], axis=1)
    np.testing.assert_array_equal(joined, plain.rgba())


def test_husk_tokens_ff_fps_and_a_frame_directory(tmp_path, stage, capsys, monkeypatch):
    """$FF is the unpadded frame, $FPS the stage's frames per second (neither mangled into a frame token), and
    a frame placeholder in a directory name puts each frame in its directory and the shot's log beside them."""
    from pxr import Usd

    from warpsky.usd.render_settings import frame_placeholder

    assert frame_placeholder("img.$FF.exr") == "img.#.exr"
    assert frame_placeholder("$FPS_a.$F4.exr", 24.0) == "24_a.####.exr"
    assert frame_placeholder("${F3}_$F.exr") == "###_#.exr"
    monkeypatch.chdir(tmp_path)
    usd = Usd.Stage.Open(str(stage))
    usd.SetFramesPerSecond(25.0)
    usd.GetRootLayer().Save()
    add_render(stage, {"A": ("out/$FPS_a.$FF.exr", None, None, [("color", "color", "color4f", "raw")], None),
                       "B": ("out/dir_$F4/img.exr", None, None, [("color", "color", "color4f", "raw")], None)})
    for product in ("A", "B"):
        code, _, err = run(["render", stage, "--frames", "9:10", "--product", f"/Render/{product}", *FAST], capsys)
        assert code == 0, err
    assert (tmp_path / "out/25_a.9.exr").is_file() and (tmp_path / "out/25_a.10.exr").is_file()
    assert (tmp_path / "out/dir_0009/img.exr").is_file() and (tmp_path / "out/dir_0010/img.exr").is_file()
    assert (tmp_path / "out/dir.log.json").is_file() and not (tmp_path / "out/dir_####").exists()
