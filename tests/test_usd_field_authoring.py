"""UsdVol volumes as other tools author them: ``field:extinction``, ``fieldIndex``, ``fieldDataType``, level sets and
per-frame ``.vdb`` sequences. Real stages written with pxr, real ``.vdb`` files written by ``vdb_tool``."""

from __future__ import annotations

import re
import shlex
import subprocess

import numpy as np
import pytest
from conftest import StageSpec, render_layer, write_stage
from test_formats import needs_tools

from warpsky.cli.main import main
from warpsky.core.errors import SceneError
from warpsky.media.voxels.fields import load_field
from warpsky.usd.stage import StageReader

pytestmark = needs_tools
ASSET = "/World/Cloud/density"


def vdb_tool(path, *actions):
    """Write ``path`` with ``vdb_tool <actions> -write path``; returns the path."""
    subprocess.run(["vdb_tool", *actions, "-write", str(path)], check=True, capture_output=True)
    return path


def fog_sphere(radius, name="density"):
    """vdb_tool actions making a fog sphere of ``radius`` voxels (1 m voxels) named ``name``."""
    return ["-sphere", f"r={radius}", "voxel=1", f"name={name}", "-l2f", f"name={name}"]


@pytest.fixture(autouse=True)
def field_cache(tmp_path, monkeypatch):
    """A private conversion cache per test."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("WARPSKY_CACHE", str(cache))
    return cache / "nanovdb"


def sphere_spec(vdb, **kwargs) -> StageSpec:
    return StageSpec(volume_file=vdb, field_name="density", camera_position=(1.0, 2.0, 25.0), extinction_scale=0.8,
                     phase="hg", g=0.5, **kwargs)


def edit_asset(stage_path, **attributes):
    """Author OpenVDBAsset attributes (token, or int for fieldIndex; a dict value is time samples)."""
    from pxr import Sdf, Usd

    stage = Usd.Stage.Open(str(stage_path))
    prim = stage.GetPrimAtPath(ASSET)
    for name, value in attributes.items():
        attr = prim.CreateAttribute(name, Sdf.ValueTypeNames.Int if name == "fieldIndex" else Sdf.ValueTypeNames.Token)
        for time, sample in (value.items() if isinstance(value, dict) else [(Usd.TimeCode.Default(), value)]):
            attr.Set(sample, time)
    stage.Save()
    return stage_path


def as_documented(stage_path):
    """Rewrite the Volume as UsdVol's documentation authors it: ``field:extinction`` on a render-purpose asset."""
    from pxr import Usd, UsdGeom, UsdVol

    stage = Usd.Stage.Open(str(stage_path))
    volume = UsdVol.Volume(stage.GetPrimAtPath("/World/Cloud"))
    volume.GetPrim().RemoveProperty("field:density")
    volume.CreateFieldRelationship("extinction", ASSET)
    UsdGeom.Imageable(stage.GetPrimAtPath(ASSET)).CreatePurposeAttr(UsdGeom.Tokens.render)
    stage.Save()
    return stage_path


def test_field_extinction_is_field_density(tmp_path, device):
    vdb = vdb_tool(tmp_path / "sphere.vdb", *fog_sphere(4))
    density = write_stage(tmp_path / "density.usda", sphere_spec(vdb))
    extinction = as_documented(write_stage(tmp_path / "extinction.usda", sphere_spec(vdb)))
    (ref,), (doc,) = StageReader(density).read_media(), StageReader(extinction).read_media()
    assert doc.name == ref.name and doc.species is None and doc.phase == ref.phase
    np.testing.assert_array_equal(doc.density, ref.density)
    np.testing.assert_array_equal(doc.world_from_index, ref.world_from_index)
    np.testing.assert_array_equal(doc.extinction_scale, ref.extinction_scale)  # warpsky:extinctionScale multiplies
    _, ref_layer = render_layer(density, device, 16, 16)
    _, doc_layer = render_layer(extinction, device, 16, 16)
    assert ref_layer.transmittance.min() < 0.9, "the sphere is not in view"
    np.testing.assert_array_equal(doc_layer.radiance, ref_layer.radiance)
    np.testing.assert_array_equal(doc_layer.transmittance, ref_layer.transmittance)


def test_density_and_extinction_together_are_ambiguous(tmp_path):
    from pxr import Usd, UsdVol

    path = write_stage(tmp_path / "both.usda", sphere_spec(vdb_tool(tmp_path / "s.vdb", *fog_sphere(2))))
    stage = Usd.Stage.Open(str(path))
    UsdVol.Volume(stage.GetPrimAtPath("/World/Cloud")).CreateFieldRelationship("extinction", ASSET)
    stage.Save()
    with pytest.raises(SceneError, match="/World/Cloud has both field:density and field:extinction"):
        StageReader(path).read_media()


def vdb_print_resolutions(path) -> list[tuple[int, ...]]:
    """Index-box sizes of the grids of ``path`` in file order, as OpenVDB's own vdb_print lists them."""
    out = subprocess.run(["vdb_print", str(path)], check=True, capture_output=True, text=True).stdout
    return [tuple(int(n) for n in m) for m in re.findall(r"\s(\d+)x(\d+)x(\d+)\s", out)]


def test_field_index_picks_among_same_named_grids(tmp_path, field_cache):
    """vdb_tool writes two grids both named density; OpenVDB's vdb_print gives their order in the file, and each
    is compared with the same sphere written alone."""
    vdb = vdb_tool(tmp_path / "two.vdb", *fog_sphere(2), *fog_sphere(4))
    alone = {vdb_print_resolutions(f)[0]: load_field(f).values
             for f in (vdb_tool(tmp_path / f"r{r}.vdb", *fog_sphere(r)) for r in (2, 4))}
    expected = [alone[resolution] for resolution in vdb_print_resolutions(vdb)]
    assert len(expected) == 2
    path = write_stage(tmp_path / "two.usda", sphere_spec(vdb))
    np.testing.assert_array_equal(StageReader(path).read_media()[0].density, expected[0])  # fieldIndex unauthored
    edit_asset(path, fieldIndex={1.0: 0, 2.0: 1})
    reader = StageReader(path)
    for time, index in ((1.0, 0), (2.0, 1), (9.0, 1)):  # held after the last sample
        np.testing.assert_array_equal(reader.read_media(time)[0].density, expected[index])
    assert len(list(field_cache.glob("*.nvdb"))) == 3  # two.vdb converted once for both grids, plus the two alone


def test_field_index_out_of_range(tmp_path):
    vdb = vdb_tool(tmp_path / "two.vdb", *fog_sphere(2), *fog_sphere(3))
    path = edit_asset(write_stage(tmp_path / "s.usda", sphere_spec(vdb)), fieldIndex=2)
    with pytest.raises(SceneError) as info:
        StageReader(path).read_media()
    message = str(info.value)
    assert "\n" not in message
    for part in (ASSET, str(vdb), "2 grid(s) named 'density'", "fieldIndex 2"):
        assert part in message
    edit_asset(path, fieldIndex=-1)
    with pytest.raises(SceneError, match=f"{ASSET}.fieldIndex must be an int >= 0"):
        StageReader(path).read_media()


@pytest.mark.parametrize("data_type", ["float3", "vector3f", "int", "matrix4d"])
def test_vector_field_data_type_is_refused(tmp_path, data_type):
    vdb = vdb_tool(tmp_path / "s.vdb", *fog_sphere(2))
    path = edit_asset(write_stage(tmp_path / "s.usda", sphere_spec(vdb)), fieldDataType=data_type)
    with pytest.raises(SceneError, match=rf"{ASSET}\.fieldDataType is '{data_type}' \(file .*s\.vdb\)"):
        StageReader(path).read_media()


@pytest.mark.parametrize("data_type", ["float", "half", "double"])
def test_scalar_field_data_types_are_read(tmp_path, data_type):
    vdb = vdb_tool(tmp_path / "s.vdb", *fog_sphere(2))
    path = edit_asset(write_stage(tmp_path / "s.usda", sphere_spec(vdb)), fieldDataType=data_type)
    assert StageReader(path).read_media()[0].density.max() > 0


def test_vector_grid_in_the_file_is_refused(tmp_path):
    vdb = vdb_tool(tmp_path / "grad.vdb", *fog_sphere(2), "-grad")  # a vec3s grid named grad_density
    spec = sphere_spec(vdb)
    spec.field_name = "grad_density"
    with pytest.raises(SceneError, match=rf"{ASSET}: grid 'grad_density' of .*grad\.vdb is a vector grid"):
        StageReader(write_stage(tmp_path / "s.usda", spec)).read_media()


@pytest.mark.parametrize("attribute", ["fieldClass", "vdbGridClass"])
def test_authored_level_set_class_is_refused(tmp_path, attribute):
    vdb = vdb_tool(tmp_path / "s.vdb", *fog_sphere(2))
    path = edit_asset(write_stage(tmp_path / "s.usda", sphere_spec(vdb)), **{attribute: "levelSet"})
    with pytest.raises(SceneError, match=rf"{ASSET}\.{attribute} is 'levelSet'.*fog volumes.*vdb_tool .* -ls2fog"):
        StageReader(path).read_media()


def test_level_set_in_the_file_is_refused_with_a_working_command(tmp_path):
    """The error's vdb_tool command, run as printed, makes a fog volume that renders."""
    vdb = vdb_tool(tmp_path / "ls.vdb", "-sphere", "r=3", "voxel=1", "name=density")
    path = write_stage(tmp_path / "s.usda", sphere_spec(vdb))
    with pytest.raises(SceneError, match=rf"{ASSET}: grid 'density' of .*ls\.vdb is a level set") as info:
        StageReader(path).read_media()
    command = str(info.value).split("convert it with ", 1)[1]
    subprocess.run(shlex.split(command), check=True, capture_output=True, cwd=tmp_path)
    fog = StageReader(write_stage(tmp_path / "fog.usda", sphere_spec(tmp_path / "ls_fog.vdb"))).read_media()
    assert fog[0].density.max() == pytest.approx(1.0)


def test_time_sampled_vdb_sequence_renders_per_frame(tmp_path, device):
    """Houdini Solaris style: one OpenVDBAsset whose filePath is time-sampled over a .vdb per frame."""
    from pxr import Sdf, Usd, UsdVol

    frames = {1.0: vdb_tool(tmp_path / "cloud.0001.vdb", *fog_sphere(2)),
              2.0: vdb_tool(tmp_path / "cloud.0002.vdb", *fog_sphere(4))}
    path = write_stage(tmp_path / "seq.usda", sphere_spec(frames[1.0]))
    stage = Usd.Stage.Open(str(path))
    attr = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(ASSET)).GetFilePathAttr()
    attr.Clear()
    for time, vdb in frames.items():
        attr.Set(Sdf.AssetPath(str(vdb)), time)
    stage.Save()
    reader = StageReader(path)
    media = {time: reader.read_media(time)[0] for time in frames}
    assert 4 * media[1.0].density.sum() < media[2.0].density.sum()  # the radius-2 sphere, then the radius-4 one
    for time, vdb in frames.items():
        (static,) = StageReader(write_stage(tmp_path / f"static{int(time)}.usda", sphere_spec(vdb))).read_media()
        np.testing.assert_array_equal(media[time].density, static.density)
        np.testing.assert_array_equal(media[time].world_from_index, static.world_from_index)
    _, frame2 = render_layer(path, device, 16, 16, time=2.0)
    _, static2 = render_layer(tmp_path / "static2.usda", device, 16, 16)
    assert frame2.transmittance.min() < 0.9, "the sphere is not in view"
    np.testing.assert_array_equal(frame2.radiance, static2.radiance)


def test_cli_prints_one_line_and_exits_2(tmp_path, capsys):
    vdb = vdb_tool(tmp_path / "two.vdb", *fog_sphere(2), *fog_sphere(3))
    path = edit_asset(write_stage(tmp_path / "s.usda", sphere_spec(vdb)), fieldIndex=5)
    assert main(["info", str(path), "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and ASSET in err and "fieldIndex 5" in err
