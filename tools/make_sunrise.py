"""Write usd_scenes/sunrise.usda: the demo cumulus at sunrise, 24 frames, sun elevation 0.5 -> 12 deg.

The sun is a DistantLight whose ``xformOp:orient`` is time-sampled (USD interpolates quaternions by slerp, so the
sun moves along an even arc between samples); a ``warpsky:atmosphere:*`` Scope turns the sky on. Run:

    python tools/make_sunrise.py [--out usd_scenes/sunrise.usda]
    warpsky render usd_scenes/sunrise.usda out/sunrise.####.exr --png     # needs data/ (make data)
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "usd_scenes" / "sunrise.usda")
    parser.add_argument("--frames", type=int, default=24)
    args = parser.parse_args(argv)

    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdVol

    from warpsky.usd.authoring import author_earth_air

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = (
        "warpsky sunrise: the demo cumulus from the ground while the sun climbs from 0.5 to 12 deg; "
        "written by tools/make_sunrise.py. Density: data/cumulus.nvdb (make data).")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(args.frames)
    stage.SetTimeCodesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())

    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.CreateFocalLengthAttr(28.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(24.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(1.0, 200000.0))
    xf = UsdGeom.Xformable(camera)
    xf.AddTranslateOp().Set(Gf.Vec3d(0.0, 150.0, 3600.0))
    xf.AddRotateXYZOp().Set(Gf.Vec3f(12.0, 0.0, 0.0))

    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun.CreateAngleAttr(0.53)
    orient = UsdGeom.Xformable(sun).AddOrientOp()
    azimuth = math.radians(-22.0)  # left of the camera's view, ahead of it
    for frame in range(1, args.frames + 1):
        elevation = math.radians(0.5 + (12.0 - 0.5) * (frame - 1) / max(args.frames - 1, 1))
        toward_sun = Gf.Vec3d(math.cos(elevation) * math.sin(azimuth), math.sin(elevation),
                              -math.cos(elevation) * math.cos(azimuth))
        quat = Gf.Rotation(Gf.Vec3d(0.0, 0.0, 1.0), toward_sun).GetQuat()  # the light's +Z points at the sun
        orient.Set(Gf.Quatf(quat), frame)

    atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
    atmosphere.CreateAttribute("warpsky:atmosphere:scaleHeight", Sdf.ValueTypeNames.Float).Set(8000.0)
    atmosphere.CreateAttribute("warpsky:atmosphere:altitude", Sdf.ValueTypeNames.Float).Set(0.0)
    author_earth_air(atmosphere)

    volume = UsdVol.Volume.Define(stage, "/World/Cumulus")
    volume.CreateExtentAttr([Gf.Vec3f(-1200, 1000, -1200), Gf.Vec3f(1200, 2600, 1200)])
    volume.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Float).Set(1.0)
    volume.GetPrim().CreateAttribute("warpsky:phase", Sdf.ValueTypeNames.Token).Set("hg")
    volume.GetPrim().CreateAttribute("warpsky:phase:g", Sdf.ValueTypeNames.Float).Set(0.85)
    asset = UsdVol.OpenVDBAsset.Define(stage, "/World/Cumulus/density")
    asset.CreateFilePathAttr(Sdf.AssetPath("../data/cumulus.nvdb"))
    asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(0.02)
    volume.CreateFieldRelationship("density", asset.GetPath())

    ground = UsdGeom.Plane.Define(stage, "/World/Ground")
    ground.CreateAxisAttr(UsdGeom.Tokens.y)
    ground.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.18, 0.22, 0.12))

    settings = stage.DefinePrim("/Render/Settings", "RenderSettings")
    settings.CreateRelationship("camera").SetTargets([camera.GetPath()])
    settings.CreateAttribute("resolution", Sdf.ValueTypeNames.Int2, variability=Sdf.VariabilityUniform).Set(
        Gf.Vec2i(384, 256))
    stage.GetRootLayer().pseudoRoot.SetInfo("renderSettingsPrimPath", "/Render/Settings")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    stage.GetRootLayer().Export(str(args.out))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
