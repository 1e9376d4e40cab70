"""What a pipeline's USD files hold that warpsky does not render, and how it reads them the way husk does: RenderVars
it cannot write are left out with a warning, RenderMan's channel names, the UsdRender resolution fallback and
``--res-scale``.

Each stage is a scene layer (written with pxr by :func:`conftest.write_stage`) under a render layer written as text,
the way a Solaris or RenderMan export puts its ``/Render`` prims in a layer of their own.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from conftest import StageSpec, write_stage
from conftest import run_cli as run

from warpsky.output.exr import read_exr

FAST = ["--device", "cpu", "--technique", "single_scatter", "--set", "step_length=1"]


def render_layer(tmp_path, scene, body: str, *, settings: str = "uniform int2 resolution = (12, 8)",
                 product: str = "", name: str = "shot.usda") -> str:
    """``name`` (a new file each time: USD keeps the layers it has opened): ``scene`` as a sublayer under
    /Render/Settings (with the ``settings`` line) and its product /Render/Products/beauty (with the ``product``
    line), whose RenderVars ``body`` defines under /Render/Products/Vars (``orderedVars`` names them in order)."""
    names = [line.split('"')[1] for line in body.splitlines() if line.strip().startswith("def RenderVar")]
    targets = ", ".join(f"</Render/Products/Vars/{name}>" for name in names)
    text = f"""\
        #usda 1.0
        (
            subLayers = [@./{scene.name}@]
            metersPerUnit = 1
            upAxis = "Y"
            renderSettingsPrimPath = "/Render/Settings"
        )

        def Scope "Render"
        {{
            def RenderSettings "Settings"
            {{
                rel camera = </World/Camera>
                {settings}
                rel products = </Render/Products/beauty>
            }}
            def Scope "Products"
            {{
                def RenderProduct "beauty"
                {{
                    token productName = "{tmp_path / 'out' / 'beauty.$F4.exr'}"
                    rel orderedVars = [{targets}]
                    {product}
                }}
                def Scope "Vars"
                {{
{textwrap.indent(textwrap.dedent(body), ' ' * 20)}
                }}
            }}
        }}
        """
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return str(path)


def var(name: str, source: str, data_type: str, source_type: str = "raw") -> str:
    return (f'def RenderVar "{name}"\n{{\n    uniform string sourceName = "{source}"\n'
            f'    uniform token dataType = "{data_type}"\n    uniform token sourceType = "{source_type}"\n}}\n')


@pytest.fixture
def scene(tmp_path, homogeneous_npy):
    return write_stage(tmp_path / "scene.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))


def warning_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("warpsky: warning:")]


def test_unsupported_render_vars_are_left_out_with_a_warning_each(tmp_path, scene, capsys):
    stage = render_layer(tmp_path, scene, var("Ci", "C.*", "color3f", "lpe") + var("a", "a", "float")
                         + var("diffuse", "C<RD>.*", "color3f", "lpe") + var("N", "N", "normal3f", "primvar")
                         + var("id", "id", "int") + var("depth", "depth", "float"))
    code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 0, err
    lines = warning_lines(err)
    assert len(lines) == 3, err
    for name, reason in (("diffuse", "light path expression 'C<RD>.*' is not supported"),
                         ("N", ".sourceType 'primvar' is not supported"),
                         ("id", ".sourceName 'id' is not a warpsky output")):
        (line,) = [line for line in lines if f"RenderVar /Render/Products/Vars/{name}" in line]
        assert reason in line and line.endswith("left out of product /Render/Products/beauty"), line
    image = read_exr(tmp_path / "out" / "beauty.0001.exr")
    assert image.metadata["orderedChannels"].split(",")[-1] == "depth.Z"
    assert not any(name.startswith(("diffuse", "N.", "id")) for name in image.channels)
    assert image.channels["depth.Z"].max() > 0.0
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0
    listed = [line for line in stdout.splitlines() if line.startswith("warning     RenderVar")]
    assert len(listed) == 3 and "/Render/Products/Vars/id" in listed[2]


def test_a_product_with_no_supported_render_var_is_refused_by_name(tmp_path, scene, capsys):
    stage = render_layer(tmp_path, scene, var("diffuse", "C<RD>.*", "color3f", "lpe") + var("id", "id", "int"))
    code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "/Render/Products/beauty: none of its 2 RenderVars is one warpsky writes" in err
    assert "/Render/Products/Vars/diffuse" in err
    assert not (tmp_path / "out").exists()
    np.testing.assert_equal(warning_lines(err), [])


def test_renderman_channel_names_ci_a_and_z(tmp_path, scene, capsys):
    """RenderMan's EXR driver writes ``Ci`` as R, G, B and the vars ``a`` and ``z`` as A and Z: the product's
    channels are those a default render writes as R, G, B, A and depth.Z, pixel for pixel."""
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color3f") + var("a", "a", "float")
                         + var("z", "z", "float") + var("tau", "transmittance", "color3f"))
    code, stdout, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 0, err
    image = read_exr(tmp_path / "out" / "beauty.0001.exr")
    assert image.metadata["orderedChannels"] == "R,G,B,A,Z,tau.R,tau.G,tau.B"
    reference = tmp_path / "default.exr"
    assert run(["render", scene, reference, "--res", "12x8", "--float", *FAST], capsys)[0] == 0
    plain = read_exr(reference)
    for ours, theirs in (("R", "R"), ("B", "B"), ("A", "A"), ("Z", "depth.Z"), ("tau.G", "transmittance.G")):
        np.testing.assert_array_equal(image.channels[ours], plain.channels[theirs], err_msg=ours)
    assert image.channels["A"].max() > 0.0
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert "/Render/Products/Vars/a: alpha -> A (float)" in stdout
    assert "/Render/Products/Vars/z: depth -> Z (float)" in stdout


def test_a_beauty_with_alpha_and_a_var_a_clash_by_channel(tmp_path, scene, capsys):
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color4f") + var("a", "a", "float"))
    code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 2 and "both write channel 'A'" in err and "/Render/Products/Vars/a" in err, err


def plan_line(stdout: str, name: str) -> str:
    (line,) = [line.strip() for line in stdout.splitlines() if line.strip().startswith(name)]
    return line


def test_unauthored_resolution_is_the_usdrender_fallback(tmp_path, scene, capsys):
    """A RenderSettings prim without ``resolution`` renders the schema's fallback 2048 x 1080 (as husk does), and so
    do its products that author none; ``--res`` still wins, and a stage without RenderSettings keeps 512 wide."""
    from pxr import Usd, UsdRender

    memory = Usd.Stage.CreateInMemory()
    assert tuple(UsdRender.Settings.Define(memory, "/S").GetResolutionAttr().Get()) == (2048, 1080)
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color4f"), settings="")
    code, stdout, err = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0, err
    assert "resolution 2048x1080 (not authored: the UsdRender fallback)" in stdout
    assert "-> " + str(tmp_path / "out" / "beauty.####.exr") + ": camera /World/Camera, resolution 2048x1080" in stdout
    assert plan_line(stdout, "resolution") == "resolution  2048 x 1080"
    code, stdout, _ = run(["info", stage, "--device", "cpu", "--res", "16x10"], capsys)
    assert plan_line(stdout, "resolution") == "resolution  16 x 10"
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color4f"), settings="",
                         product="uniform int2 resolution = (20, 10)", name="product.usda")
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert plan_line(stdout, "resolution") == "resolution  20 x 10"
    code, stdout, _ = run(["info", scene, "--device", "cpu"], capsys)
    assert plan_line(stdout, "resolution") == "resolution  512 x 512"  # the camera's square film back


def test_res_scale_scales_the_authored_fallback_and_given_resolution(tmp_path, scene, capsys):
    """``--res-scale`` is a percentage, as husk's: of the schema's fallback, of a product's resolution and of
    ``--res``; each side rounds to the nearest pixel."""
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color4f"), settings="")
    code, _, err = run(["render", stage, "--frames", "1", "--res-scale", "1", *FAST], capsys)
    assert code == 0, err
    image = read_exr(tmp_path / "out" / "beauty.0001.exr")
    assert (image.width, image.height) == (20, 11)  # 2048 x 1080 at 1 %: 20.48 x 10.8
    stage = render_layer(tmp_path, scene, var("Ci", "Ci", "color4f"), name="authored.usda")
    for flags, size in ((["--res-scale", "50"], "6 x 4"), (["--res", "16x10", "--res-scale", "50"], "8 x 5"),
                        (["--res", "10", "--res-scale", "150"], "15 x 15"), (["--res-scale", "100"], "12 x 8")):
        code, stdout, err = run(["info", stage, "--device", "cpu", *flags], capsys)
        assert code == 0 and plan_line(stdout, "resolution") == f"resolution  {size}", (flags, err)
    code, stdout, _ = run(["info", scene, "--device", "cpu", "--res-scale", "25"], capsys)
    assert plan_line(stdout, "resolution") == "resolution  128 x 128"  # warpsky's default 512 wide


@pytest.mark.parametrize("value", ["0", "-50", "half", "nan", "inf"])
def test_bad_res_scale_is_one_line_naming_the_flag(tmp_path, scene, capsys, value):
    with pytest.raises(SystemExit) as stop:
        run(["render", scene, tmp_path / "x.exr", "--res-scale", value, *FAST], capsys)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert "--res-scale" in err and "percentage" in err and repr(value) in err
    assert not (tmp_path / "x.exr").exists()


def prim(kind: str, name: str, *lines: str, meta: str = "") -> str:
    """A usda prim definition with one attribute per line."""
    body = "".join(f"    {line}\n" for line in lines)
    return f'def {kind} "{name}"{f" ({meta})" if meta else ""}\n{{\n{body}}}\n'


#: A layer over the test scene with what a stage made for another renderer holds besides the sun and the cloud.
SCENE_EXTRAS = "\n".join([
    '#usda 1.0\n(\n    subLayers = [@./scene.usda@]\n    metersPerUnit = 1\n    upAxis = "Y"\n)\n',
    'over "World"\n{',
    prim("DomeLight", "Sky", "float inputs:intensity = 0.5"),
    prim("DomeLight", "Fill", "float inputs:intensity = 0.25"),
    prim("DomeLight", "Off", 'token visibility = "invisible"'),
    prim("RectLight", "Key", "float inputs:width = 2"),
    prim("SphereLight", "Bulb", "float inputs:radius = 0.5"),
    prim("DiskLight", "Spot"), prim("CylinderLight", "Tube"),
    prim("Cube", "Crate", "double size = 2"), prim("Sphere", "Ball"), prim("Cylinder", "Post"),
    prim("Sphere", "Guide", 'uniform token purpose = "guide"'),
    prim("Sphere", "Hidden", 'token visibility = "invisible"'),
    prim("Plane", "Ground", 'uniform token axis = "Y"'), prim("Plane", "Pond", 'uniform token axis = "Y"'),
    prim("Xform", "Props", meta="instanceable = true\n    references = </Prototypes/Prop>"),
    prim("Xform", "Props2", meta="instanceable = true\n    references = </Prototypes/Prop>"),
    "}\n",
    'class "Prototypes"\n{', prim("Xform", "Prop", 'def Cone "Cap"\n    {\n    }'), "}\n",
])


def test_lights_and_gprims_warpsky_does_not_render_are_warned_about_once_each(tmp_path, scene, capsys):
    stage = tmp_path / "extras.usda"
    stage.write_text(SCENE_EXTRAS)
    code, _, err = run(["render", stage, tmp_path / "x.####.exr", "--frames", "1:2", "--res", "8", *FAST], capsys)
    assert code == 0, err
    lines = warning_lines(err)
    expected = {
        "/World/Fill": "DomeLight /World/Fill ignored: only the first visible DomeLight (/World/Sky) lights",
        "/World/Key": "RectLight /World/Key ignored: warpsky renders DistantLight suns and the first visible DomeLight",
        "/World/Bulb": "SphereLight /World/Bulb ignored", "/World/Spot": "DiskLight /World/Spot ignored",
        "/World/Tube": "CylinderLight /World/Tube ignored",
        "/World/Crate": "Cube /World/Crate ignored: warpsky renders Mesh surfaces, one ground Plane and Volumes",
        "/World/Ball": "Sphere /World/Ball ignored", "/World/Post": "Cylinder /World/Post ignored",
        "/World/Pond": "Plane /World/Pond ignored: the first rendered Plane (/World/Ground) is the only ground",
        "/World/Props/Cap": "Cone /World/Props/Cap ignored",
    }
    assert len(lines) == len(expected), "\n".join(lines)  # once each, over two frames and the first frame's plan
    for path, text in expected.items():
        (line,) = [line for line in lines if f" {path} " in line]
        assert text in line, line
    assert "in every other instance" in expected_line(lines, "/World/Props/Cap")
    assert not any(name in err for name in ("/World/Off", "/World/Guide", "/World/Hidden", "/World/Props2"))
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0
    assert len([line for line in stdout.splitlines() if line.startswith("warning     ")]) == len(expected)
    assert "warning     RectLight /World/Key ignored" in stdout


def expected_line(lines: list[str], path: str) -> str:
    (line,) = [line for line in lines if f" {path} " in line]
    return line


@pytest.mark.parametrize("name,expected", [
    ("ACES - ACEScg", "ACEScg"), ("lin_ap1", "ACEScg"), ("scene_linear", "ACEScg"),
    ("Utility - Linear - sRGB", "lin_rec709"), ("Linear Rec.709 (sRGB)", "lin_rec709"), (" lin_srgb ", "lin_rec709"),
])
def test_opencolorio_names_and_aliases_select_the_output_space(tmp_path, scene, capsys, name, expected):
    """renderingColorSpace by any of OpenColorIO's names, aliases or roles for the two spaces warpsky writes (the
    built-in CG config: its scene_linear role is ACEScg), and the same names for --colorspace."""
    stage = render_layer(tmp_path, scene, var("Ci", "C.*", "color3f", "lpe"),
                         settings=f'uniform int2 resolution = (12, 8)\n                uniform token '
                                  f'renderingColorSpace = "{name}"')
    code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
    assert code == 0, err
    assert read_exr(tmp_path / "out" / "beauty.0001.exr").metadata["colorspace"] == expected
    out = tmp_path / "flag.exr"
    code, _, err = run(["render", scene, out, "--res", "8", "--colorspace", name, *FAST], capsys)
    assert code == 0 and read_exr(out).metadata["colorspace"] == expected, err


def test_a_colour_space_warpsky_does_not_write_is_named_as_such(tmp_path, scene, capsys):
    """Display P3's linear space exists in OpenColorIO but is not written: one line naming the prim, the value and
    OpenColorIO's name for it; a name nobody knows is refused as unsupported; --colorspace the same, exit 2."""
    for value, words in (("lin_p3d65", "OpenColorIO's 'Linear P3-D65'"), ("sRGB-ish", "is not supported")):
        stage = render_layer(tmp_path, scene, var("Ci", "C.*", "color3f", "lpe"), name=f"{value}.usda",
                             settings=f'uniform int2 resolution = (12, 8)\n                uniform token '
                                      f'renderingColorSpace = "{value}"')
        code, _, err = run(["render", stage, "--frames", "1", *FAST], capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"/Render/Settings.renderingColorSpace '{value}'" in err and words in err and "ACEScg" in err
        assert not (tmp_path / "out").exists()
    with pytest.raises(SystemExit) as stop:
        run(["render", scene, tmp_path / "x.exr", "--colorspace", "lin_p3d65", *FAST], capsys)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and len(err.strip().splitlines()) <= 2 and "Linear P3-D65" in err, err


def test_a_centimetre_stage_warns_that_extinction_is_per_metre(tmp_path, homogeneous_npy, capsys):
    """metersPerUnit 0.01: extinction stays per metre, where Hydra renderers read density per stage unit, so one
    warning names the field and the factor 100 that renders as they do; warpsky info lists it; a metre stage says
    nothing."""
    cm = write_stage(tmp_path / "cm.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)),
                     mpu=0.01)
    code, stdout, err = run(["info", str(cm), "--device", "cpu"], capsys)
    lines = [line for line in warning_lines(err) if "per metre" in line]
    assert code == 0 and len(lines) == 1, err
    assert "metersPerUnit is 0.01" in lines[0] and "warpsky:extinctionScale = 100" in lines[0]
    assert "/World/" in lines[0] and any("per metre" in line for line in stdout.splitlines()
                                          if line.startswith("warning"))
    metre = write_stage(tmp_path / "m.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    code, _, err = run(["info", str(metre), "--device", "cpu"], capsys)
    assert code == 0 and "per metre" not in err


def test_a_stage_without_a_camera_is_framed_by_a_free_camera(tmp_path, homogeneous_npy, capsys):
    """No Camera prim and no RenderSettings camera (OpenUSD's DomeLight test stages, made for usdview's free
    camera): as usdrecord does, a free camera frames the stage's bounds, its bounding sphere filling the frame's
    height with a 50 mm lens on 36 x 24 mm, looking along -Z; one warning names the stage and the camera."""
    import math

    stage = tmp_path / "nocam.usda"
    stage.write_text(f"""#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)

def Volume "Cloud"
{{
    float3[] extent = [(0, -10, -10), (20, 10, 10)]
    rel field:density = </Cloud/density>

    def OpenVDBAsset "density"
    {{
        asset filePath = @{homogeneous_npy}@
        float warpsky:extinctionScale = 0.05
    }}
}}
""")
    out = tmp_path / "x.exr"
    code, _, err = run(["render", stage, out, "--res", "12x8", *FAST], capsys)
    assert code == 0 and out.is_file(), err
    lines = [line for line in warning_lines(err) if "free camera" in line]
    assert len(lines) == 1 and str(stage) in lines[0] and "as usdrecord does" in lines[0]
    distance = math.sqrt(3.0) * 10.0 / math.sin(math.atan(12.0 / 50.0))
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    camera_line = next(line for line in stdout.splitlines() if line.startswith("camera "))
    assert f"[10.0, 0.0, {round(distance, 3)}]" in camera_line, camera_line
    assert read_exr(out).channels["A"].astype(np.float64).max() > 0.1  # the volume is in view


def test_many_ignored_prims_of_one_type_are_counted_in_one_line(tmp_path, scene, capsys):
    """Twelve Spheres (OpenUSD's sphereGrid has a hundred): five lines name the first five, one more counts the
    other seven with the first and last of their paths; warpsky info lists the same six."""
    from warpsky.usd.ignored import WARNED_PER_TYPE

    spheres = "\n".join(f'    def Sphere "S{k:02d}"\n    {{\n        double radius = 1\n    }}' for k in range(12))
    stage = tmp_path / "grid.usda"
    stage.write_text(f"""#usda 1.0
(
    subLayers = [@./{scene.name}@]
)

over "World"
{{
{spheres}
}}
""")
    code, _, err = run(["render", stage, tmp_path / "x.exr", "--res", "8", *FAST], capsys)
    lines = [line for line in warning_lines(err) if "Sphere" in line]
    assert code == 0 and len(lines) == WARNED_PER_TYPE + 1, err
    assert lines[-1].endswith("7 more Sphere prims ignored as the 5 above (/World/S05 .. /World/S11)"), lines[-1]
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert len([line for line in stdout.splitlines() if line.startswith("warning") and "Sphere" in line]) == 6


def test_volumes_without_a_field_warpsky_renders_are_skipped_with_a_warning(tmp_path, scene, capsys):
    """A procedural Volume its material makes (no fields, as in OpenUSD's volumeMaterial.usda) and one whose only
    field is a temperature are each named in one warning and skipped; the stage's cloud still renders."""
    from pxr import Usd, UsdVol

    usd = Usd.Stage.Open(str(scene))
    UsdVol.Volume.Define(usd, "/World/Procedural")
    heat = UsdVol.Volume.Define(usd, "/World/Heat")
    UsdVol.OpenVDBAsset.Define(usd, "/World/Heat/temperature").CreateFilePathAttr("heat.vdb")
    heat.CreateFieldRelationship("temperature", "/World/Heat/temperature")
    usd.GetRootLayer().Save()
    out = tmp_path / "x.exr"
    code, _, err = run(["render", scene, out, "--res", "8", "--float", *FAST], capsys)
    assert code == 0, err
    lines = warning_lines(err)
    assert any("Volume /World/Procedural ignored: it has no fields" in line for line in lines), err
    assert any("Volume /World/Heat ignored: it has fields temperature but none warpsky renders" in line
               for line in lines), err
    assert read_exr(out).channels["A"].max() > 0.1  # the cloud
    code, stdout, _ = run(["info", scene, "--device", "cpu"], capsys)
    assert code == 0 and "warning     Volume /World/Procedural ignored" in stdout
