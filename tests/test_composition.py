"""USD composition as pipeline tools honour it: payloads loaded or not, variant selections on the session layer,
purpose, time-sampled visibility, ``active = false`` and instancing."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from conftest import StageSpec, write_stage

from warpsky.core.errors import SceneError, UsageError
from warpsky.usd.composition import StageOptions, parse_variant
from warpsky.usd.stage import StageReader

EXTENT = ((-10.0, -10.0, -10.0), (10.0, 10.0, 10.0))  # [m], the Volumes' authored extent


def grid(tmp_path, name: str, value: float):
    path = tmp_path / f"{name}.npy"
    np.save(path, np.full((3, 3, 3), value, dtype=np.float32))
    return path


def define_volume(stage, path: str, npy, *, translate=None):
    """A Volume at ``path`` with one dense ``field:density`` on ``npy`` filling EXTENT."""
    from pxr import Gf, Sdf, UsdVol

    volume = UsdVol.Volume.Define(stage, path)
    volume.CreateExtentAttr([Gf.Vec3f(*EXTENT[0]), Gf.Vec3f(*EXTENT[1])])
    if translate is not None:
        volume.AddTranslateOp().Set(Gf.Vec3d(*translate))
    asset = UsdVol.OpenVDBAsset.Define(stage, f"{path}/density")
    asset.CreateFilePathAttr(Sdf.AssetPath(str(npy)))
    asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(0.05)
    volume.CreateFieldRelationship("density", asset.GetPath())
    return volume


def base_stage(tmp_path, name: str = "shot.usda"):
    """A Y-up metre stage with a camera and a sun, no cloud; returns (path, open stage) for adding prims."""
    from pxr import Usd

    path = write_stage(tmp_path / name, StageSpec())
    return path, Usd.Stage.Open(str(path))


def media_names(reader, time=None) -> list[str]:
    return [medium.name for medium in reader.scene_at(time).media]


def render(scene, size: int = 16) -> np.ndarray:
    from warpsky.render.plan import make_plan
    from warpsky.techniques.single_scatter.single_scatter import SingleScatter

    plan = make_plan(scene, technique="single_scatter", settings={}, resolution=(size, size), device="cpu")
    return SingleScatter(plan.settings, device="cpu").render(scene, size, size).radiance


# ------------------------------------------------------------------------------------------------------- options
def test_options_validate_and_pickle():
    options = StageOptions(load="none", variants=[("shape", "big"), "lod=high"], purposes=["default", "proxy"])
    assert options.variants == (("shape", "big"), ("lod", "high"))
    assert options.purposes == ("default", "proxy")
    assert pickle.loads(pickle.dumps(options)) == options
    assert hash(options) == hash(pickle.loads(pickle.dumps(options)))
    assert parse_variant("shape = big") == ("shape", "big")
    for kwargs, flag in (({"load": "some"}, "--load"), ({"purposes": ("render", "hero")}, "--purpose"),
                         ({"purposes": ()}, "--purpose"), ({"variants": (("shape", ""),)}, "--variant")):
        with pytest.raises(UsageError, match=flag):
            StageOptions(**kwargs)
    for text in ("shape", "=big", "shape="):
        with pytest.raises(UsageError, match="--variant SET=SELECTION"):
            parse_variant(text)


# ------------------------------------------------------------------------------------------------------ payloads
def test_payloaded_volume_loads_unless_load_none(tmp_path):
    from pxr import Usd

    asset = Usd.Stage.CreateNew(str(tmp_path / "cloud_asset.usda"))
    define_volume(asset, "/Cloud", grid(tmp_path, "d", 1.0))
    asset.SetDefaultPrim(asset.GetPrimAtPath("/Cloud"))
    asset.Save()
    path, stage = base_stage(tmp_path)
    stage.DefinePrim("/World/Cloud").GetPayloads().AddPayload("./cloud_asset.usda")
    stage.Save()

    loaded = StageReader(path)
    assert media_names(loaded) == ["/World/Cloud"]
    assert "payloads: 1 loaded" in loaded.composition_summary()
    unloaded = StageReader(path, StageOptions(load="none"))
    assert media_names(unloaded) == []
    assert "payloads: 1 not loaded (--load none)" in unloaded.composition_summary()

    # A payload whose file is missing breaks a loaded stage but not an unloaded one, which never reads it.
    stage.DefinePrim("/World/Missing").GetPayloads().AddPayload("./missing.usda")
    stage.Save()
    with pytest.raises(SceneError, match="missing.usda"):
        StageReader(path)
    assert media_names(StageReader(path, StageOptions(load="none"))) == []


# ------------------------------------------------------------------------------------------------------ variants
def variant_stage(tmp_path):
    """/World/Cloud with variant set ``shape`` (thin: density 0.2, thick: density 4), authored selection thin."""
    from pxr import Sdf, UsdVol

    path, stage = base_stage(tmp_path)
    volume = define_volume(stage, "/World/Cloud", grid(tmp_path, "thin", 0.2))
    stage.GetPrimAtPath("/World/Cloud/density").GetAttribute("filePath").Clear()  # the variants author it
    variant_set = volume.GetPrim().GetVariantSets().AddVariantSet("shape")
    for name, value in (("thin", 0.2), ("thick", 4.0)):
        variant_set.AddVariant(name)
        variant_set.SetVariantSelection(name)
        with variant_set.GetVariantEditContext():
            file_path = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Cloud/density")).GetFilePathAttr()
            file_path.Set(Sdf.AssetPath(str(grid(tmp_path, name, value))))
    variant_set.SetVariantSelection("thin")
    stage.Save()
    return path


def test_variant_selection_switches_the_density_file(tmp_path):
    path = variant_stage(tmp_path)
    before = path.read_bytes()
    thin = StageReader(path).scene_at(None)
    reader = StageReader(path, StageOptions(variants=(("shape", "thick"),)))
    thick = reader.scene_at(None)
    assert [m.name for m in thick.media] == ["/World/Cloud"]
    assert float(thin.media[0].density.max()) == pytest.approx(0.2)
    assert float(thick.media[0].density.max()) == pytest.approx(4.0)
    assert "variants: /World/Cloud shape=thick (session layer)" in reader.composition_summary()
    assert np.abs(render(thick) - render(thin)).max() > 1e-3 * render(thick).max()
    assert path.read_bytes() == before


def test_unknown_variant_set_or_selection_lists_the_choices(tmp_path):
    path = variant_stage(tmp_path)
    before = path.read_bytes()
    with pytest.raises(SceneError, match=r"no prim has a variant set 'size'.*shape \(thick, thin\)"):
        StageReader(path, StageOptions(variants=(("size", "big"),)))
    with pytest.raises(SceneError, match=r"--variant shape=huge: variant set 'shape' \(/World/Cloud\) offers thick, "
                                         r"thin, not 'huge'"):
        StageReader(path, StageOptions(variants=(("shape", "huge"),)))
    assert path.read_bytes() == before


def test_variant_applies_to_every_instance_offering_it(tmp_path):
    from pxr import Usd, UsdGeom

    asset = Usd.Stage.CreateNew(str(tmp_path / "cloud_asset.usda"))
    root = UsdGeom.Xform.Define(asset, "/Asset").GetPrim()
    shape = root.GetVariantSets().AddVariantSet("shape")
    for name, value in (("thin", 0.2), ("thick", 4.0)):
        shape.AddVariant(name)
        shape.SetVariantSelection(name)
        with shape.GetVariantEditContext():
            define_volume(asset, "/Asset/Cloud", grid(tmp_path, name, value))
    shape.SetVariantSelection("thin")
    asset.DefinePrim("/Asset/Inner").GetVariantSets().AddVariantSet("lod").AddVariant("high")
    asset.SetDefaultPrim(root)
    asset.Save()
    path, stage = base_stage(tmp_path)
    for prim_path in ("/World/A", "/World/B"):
        prim = UsdGeom.Xform.Define(stage, prim_path).GetPrim()
        prim.GetReferences().AddReference("./cloud_asset.usda")
        prim.SetInstanceable(True)
    stage.Save()

    reader = StageReader(path, StageOptions(variants=(("shape", "thick"),)))
    assert [float(m.density.max()) for m in reader.scene_at(None).media] == pytest.approx([4.0, 4.0])
    summary = reader.composition_summary()
    assert [line for line in summary if line.startswith("variants:")] == [
        "variants: /World/A shape=thick (session layer)", "variants: /World/B shape=thick (session layer)"]
    assert "instances: 2 instance(s) of 1 prototype(s)" in summary
    with pytest.raises(SceneError, match=r"variant set 'lod' exists only inside instances \(e.g. /World/A/Inner\)"):
        StageReader(path, StageOptions(variants=(("lod", "high"),)))


# ------------------------------------------------------------------------------------------------------- purpose
@pytest.mark.parametrize("purpose,on_parent", [("proxy", False), ("guide", True)])
def test_proxy_and_guide_volumes_render_only_when_asked(tmp_path, purpose, on_parent):
    from pxr import UsdGeom

    path, stage = base_stage(tmp_path)
    parent = UsdGeom.Xform.Define(stage, "/World/Group")
    volume = define_volume(stage, "/World/Group/Cloud", grid(tmp_path, "d", 1.0))
    (parent if on_parent else volume).CreatePurposeAttr(purpose)
    define_volume(stage, "/World/Hero", grid(tmp_path, "d", 1.0))
    stage.Save()
    assert media_names(StageReader(path)) == ["/World/Hero"]
    options = StageOptions(purposes=("default", "render", purpose))
    assert media_names(StageReader(path, options)) == ["/World/Group/Cloud", "/World/Hero"]
    assert media_names(StageReader(path, StageOptions(purposes=(purpose,)))) == ["/World/Group/Cloud"]
    assert StageReader(path, options).composition_summary()[-1] == f"purposes rendered: default, render, {purpose}"


def add_surfaces(stage, tmp_path) -> dict[str, str]:
    """A ground plane, an atmosphere prim and a stratiform layer (a small thickness map); returns their paths."""
    from pxr import Gf, Sdf, UsdGeom

    UsdGeom.Plane.Define(stage, "/World/Ground").CreateAxisAttr(UsdGeom.Tokens.y)
    stage.DefinePrim("/World/Atmosphere", "Scope").CreateAttribute(
        "warpsky:atmosphere:scaleHeight", Sdf.ValueTypeNames.Float).Set(8000.0)
    np.save(tmp_path / "thickness.npy", np.full((8, 8), 100.0, dtype=np.float32))
    layer = UsdGeom.Xform.Define(stage, "/World/Stratus")
    layer.AddTranslateOp().Set(Gf.Vec3d(0.0, 1000.0, 0.0))
    layer.GetPrim().CreateAttribute("warpsky:kind", Sdf.ValueTypeNames.Token, custom=False).Set("stratiformLayer")
    layer.GetPrim().CreateAttribute("warpsky:stratiform:thicknessMap", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath(str(tmp_path / "thickness.npy")))
    return {"ground": "/World/Ground", "atmosphere": "/World/Atmosphere", "layer": "/World/Stratus"}


def surfaces(scene) -> dict[str, str | None]:
    """Names of the scene's ground, atmosphere and (first) stratiform layer; None where absent."""
    return {"ground": scene.ground and scene.ground.name, "atmosphere": scene.atmosphere and scene.atmosphere.name,
            "layer": scene.stratiform_layers[0].name if scene.stratiform_layers else None}


def test_purpose_skips_ground_atmosphere_and_layers_but_not_the_sun(tmp_path):
    from pxr import UsdGeom

    path, stage = base_stage(tmp_path)
    paths = add_surfaces(stage, tmp_path)
    for prim_path in (*paths.values(), "/World/Sun"):
        UsdGeom.Imageable(stage.GetPrimAtPath(prim_path)).CreatePurposeAttr("proxy")
    stage.Save()
    default = StageReader(path).scene_at(None)
    assert surfaces(default) == dict.fromkeys(paths)
    assert default.sun is not None  # lights ignore purpose, as in Hydra
    assert surfaces(StageReader(path, StageOptions(purposes=("default", "proxy"))).scene_at(None)) == paths


# -------------------------------------------------------------------------------------- visibility and activity
def test_time_sampled_invisibility_and_inactive_prims(tmp_path):
    from pxr import UsdGeom

    path, stage = base_stage(tmp_path)
    blinking = define_volume(stage, "/World/Blink", grid(tmp_path, "d", 1.0))
    visibility = blinking.CreateVisibilityAttr()
    for time, value in ((1.0, UsdGeom.Tokens.inherited), (2.0, UsdGeom.Tokens.invisible),
                        (3.0, UsdGeom.Tokens.inherited)):
        visibility.Set(value, time)
    define_volume(stage, "/World/Off", grid(tmp_path, "d", 1.0)).GetPrim().SetActive(False)
    define_volume(stage, "/World/OffGroup/Cloud", grid(tmp_path, "d", 1.0))
    stage.GetPrimAtPath("/World/OffGroup").SetActive(False)  # an inactive parent takes its subtree with it
    define_volume(stage, "/World/Steady", grid(tmp_path, "d", 1.0))
    paths = add_surfaces(stage, tmp_path)
    for prim_path in paths.values():
        attr = UsdGeom.Imageable(stage.GetPrimAtPath(prim_path)).CreateVisibilityAttr()
        attr.Set(UsdGeom.Tokens.inherited, 1.0)
        attr.Set(UsdGeom.Tokens.invisible, 2.0)
        attr.Set(UsdGeom.Tokens.inherited, 3.0)
    stage.Save()
    reader = StageReader(path)
    assert media_names(reader, 1.0) == ["/World/Blink", "/World/Steady"]
    assert media_names(reader, 2.0) == ["/World/Steady"]
    assert media_names(reader, 3.0) == ["/World/Blink", "/World/Steady"]
    assert surfaces(reader.scene_at(1.0)) == surfaces(reader.scene_at(3.0)) == paths
    assert surfaces(reader.scene_at(2.0)) == dict.fromkeys(paths)


# ---------------------------------------------------------------------------------------------------- instancing
def test_instances_of_a_volume_become_one_medium_each_at_their_transforms(tmp_path):
    from pxr import Gf, Sdf, Usd, UsdGeom

    asset = Usd.Stage.CreateNew(str(tmp_path / "cloud_asset.usda"))
    UsdGeom.Xform.Define(asset, "/Asset")
    define_volume(asset, "/Asset/Cloud", grid(tmp_path, "d", 1.0), translate=(0.0, 5.0, 0.0))
    asset.SetDefaultPrim(asset.GetPrimAtPath("/Asset"))
    asset.Save()
    path, stage = base_stage(tmp_path)
    offsets = {"/World/A": (-30.0, 0.0, 0.0), "/World/B": (40.0, 0.0, -20.0)}
    for prim_path, offset in offsets.items():
        xform = UsdGeom.Xform.Define(stage, prim_path)
        xform.AddTranslateOp().Set(Gf.Vec3d(*offset))
        xform.GetPrim().GetReferences().AddReference(Sdf.Reference("./cloud_asset.usda"))
        xform.GetPrim().SetInstanceable(True)
    stage.Save()

    reader = StageReader(path)
    media = reader.scene_at(None).media
    assert [m.name for m in media] == ["/World/A/Cloud", "/World/B/Cloud"]
    for medium, offset in zip(media, offsets.values(), strict=True):
        corners = medium.world_corners()
        expected_lo = np.array(EXTENT[0]) + np.array(offset) + (0.0, 5.0, 0.0)
        np.testing.assert_allclose(corners.min(axis=0), expected_lo, atol=1e-9)
        np.testing.assert_allclose(corners.max(axis=0), expected_lo + 20.0, atol=1e-9)
    assert "instances: 2 instance(s) of 1 prototype(s)" in reader.composition_summary()
    assert "references: 2 prim(s) with references" in reader.composition_summary()
