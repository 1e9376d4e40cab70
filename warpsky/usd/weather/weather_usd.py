"""The USD side of an imported weather stage (see :mod:`warpsky.usd.weather.author` for what it holds)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from warpsky.core.errors import OutputError
from warpsky.usd.authoring import author_earth_air
from warpsky.usd.weather.weather_state import SPECIES_ORDER, WeatherState

#: The camera's lens: 24 mm on a 36 x 24 mm back (74 x 53 degrees).
FOCAL_LENGTH = 24.0
APERTURE = (36.0, 24.0)
#: Ground albedo of the plane and the terrain mesh (grass and soil).
GROUND_ALBEDO = (0.12, 0.14, 0.09)


def camera_pose(lower: np.ndarray, upper: np.ndarray, ground: float, fov: tuple[float, float]
                ) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) [m]: south of the box, at a third of its centre's height over the ground (looking a little
    up, as from a hill), far enough that the box's width and height fit the (horizontal, vertical) field of view
    [radians] with a fifth to spare."""
    centre = 0.5 * (lower + upper)
    half = np.maximum(0.5 * (upper - lower), 100.0)
    distance = 1.2 * max(max(half[0], half[1]) / math.tan(0.5 * fov[0]), half[2] / math.tan(0.5 * fov[1])) + half[1]
    eye = np.array([centre[0], centre[1] - distance, ground + max((centre[2] - ground) / 3.0, 2.0)])
    return eye, centre


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector towards the sun (east, north, up) at ``elevation_deg`` over the horizon and ``azimuth_deg``
    clockwise from north."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def author_stage(path: Path, states: list[WeatherState], grids: list[dict[str, Path]], codes: list[float],
                 per_second: float, *, framing, sun: tuple[float, float], resolution: tuple[int, int],
                 doc: str, water: list[dict[str, tuple[float, float]]] | None = None) -> Path:
    """Write the stage at ``path`` referencing ``grids`` (per state: field -> file) at time ``codes``; ``water``
    (per code: species -> (peak [kg/m³], total [kg]), :func:`~warpsky.model.water_optics.species_water`) is
    authored on each species' field as ``warpsky:water:peak`` and ``warpsky:water:total``."""
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = doc
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(codes[0])
    stage.SetEndTimeCode(codes[-1])
    stage.SetTimeCodesPerSecond(per_second)
    stage.SetFramesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    ground = min(float(s.terrain.height.min()) if s.terrain is not None else 0.0 for s in states)
    _volume(stage, path, grids, codes, water)
    _camera(stage, framing, ground)
    _sun(stage, sun)
    atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
    atmosphere.CreateAttribute("warpsky:atmosphere:altitude", Sdf.ValueTypeNames.Float).Set(0.0)
    author_earth_air(atmosphere)
    _ground(stage, states, ground)
    _render_settings(stage, resolution)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        stage.GetRootLayer().Export(str(path))
    except Exception as exc:  # noqa: BLE001 - USD raises its own Tf.ErrorException
        raise OutputError(f"cannot write {path}: {exc}") from None
    return path


def _volume(stage, path: Path, grids: list[dict[str, Path]], codes: list[float], water=None) -> None:
    """/World/Weather: one OpenVDBAsset per species (and the velocity), filePath time-sampled (and each species'
    water, when given)."""
    from pxr import Sdf, UsdVol

    volume = UsdVol.Volume.Define(stage, "/World/Weather")
    fields = [f for f in (*SPECIES_ORDER, "velocity") if any(f in g for g in grids)]
    for field in fields:
        asset = UsdVol.OpenVDBAsset.Define(stage, f"/World/Weather/{field}")
        attr = asset.CreateFilePathAttr()
        for code, files in zip(codes, grids, strict=True):
            attr.Set(Sdf.AssetPath(Path(os.path.relpath(files[field], path.parent)).as_posix()), code)
        asset.CreateFieldNameAttr("")
        if field == "velocity":
            asset.CreateFieldDataTypeAttr("float3")
        else:
            asset.CreateFieldDataTypeAttr("float")
            asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(1.0)
            if water is not None:
                peak = asset.GetPrim().CreateAttribute("warpsky:water:peak", Sdf.ValueTypeNames.Float)
                total = asset.GetPrim().CreateAttribute("warpsky:water:total", Sdf.ValueTypeNames.Double)
                for code, amounts in zip(codes, water, strict=True):
                    most, whole = amounts.get(field, (0.0, 0.0))
                    peak.Set(most, code)
                    total.Set(whole, code)
        volume.CreateFieldRelationship(field, asset.GetPath())


def _camera(stage, framing, ground: float) -> None:
    from pxr import Gf, UsdGeom

    lower, upper = framing
    fov = tuple(2.0 * math.atan(0.5 * a / FOCAL_LENGTH) for a in APERTURE)
    eye, target = camera_pose(np.asarray(lower), np.asarray(upper), ground, fov)
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateFocalLengthAttr(FOCAL_LENGTH)
    cam.CreateHorizontalApertureAttr(APERTURE[0])
    cam.CreateVerticalApertureAttr(APERTURE[1])
    far = 4.0 * float(np.linalg.norm(np.asarray(upper) - eye)) + 1.0e5
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, far))
    look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye.tolist()), Gf.Vec3d(*target.tolist()), Gf.Vec3d(0, 0, 1))
    UsdGeom.Xformable(cam).AddTransformOp().Set(look.GetInverse())


def _sun(stage, sun: tuple[float, float]) -> None:
    from pxr import Gf, UsdGeom, UsdLux

    light = UsdLux.DistantLight.Define(stage, "/World/Sun")
    light.CreateIntensityAttr(1.0)
    light.CreateAngleAttr(0.53)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.98, 0.95))
    toward = Gf.Vec3d(*sun_direction(*sun).tolist())
    # light travels along the light's local -Z, so its local +Z points at the sun
    UsdGeom.Xformable(light).AddOrientOp().Set(Gf.Quatf(Gf.Rotation(Gf.Vec3d(0.0, 0.0, 1.0), toward).GetQuat()))


def _ground(stage, states: list[WeatherState], ground: float) -> None:
    """A ground plane at the lowest ground and, when the files give terrain, its mesh (of the first time)."""
    from pxr import Gf, Sdf, UsdGeom, Vt

    plane = UsdGeom.Plane.Define(stage, "/World/Ground")
    plane.CreateAxisAttr("Z")
    plane.CreateWidthAttr(1.0e6)
    plane.CreateLengthAttr(1.0e6)
    UsdGeom.Xformable(plane).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, ground - (1.0 if _has_relief(states) else 0.0)))
    plane.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*GROUND_ALBEDO))
    if not _has_relief(states):
        return
    state = next(s for s in states if s.terrain is not None)
    height = state.terrain.height
    nx, ny = height.shape
    x, y = state.cell_centres(0), state.cell_centres(1)
    X, Y = np.meshgrid(x, y, indexing="ij")
    points = np.stack([X, Y, height], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    corner = (i * ny + j).reshape(-1)
    quads = np.stack([corner, corner + ny, corner + ny + 1, corner + 1], axis=-1).reshape(-1)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Terrain")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(corner), 4, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(quads.astype(np.int32)))
    mesh.CreateSubdivisionSchemeAttr("none")
    mesh.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*GROUND_ALBEDO))


def _has_relief(states: list[WeatherState]) -> bool:
    """Whether any state's terrain is not flat."""
    return any(s.terrain is not None and float(np.ptp(s.terrain.height)) > 0.0 for s in states)


def _render_settings(stage, resolution: tuple[int, int]) -> None:
    from pxr import Gf, Sdf, UsdRender

    render = UsdRender.Settings.Define(stage, "/Render/Settings")
    render.CreateCameraRel().SetTargets([Sdf.Path("/World/Camera")])
    render.CreateResolutionAttr(Gf.Vec2i(*resolution))
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    if min(resolution) < 1:
        raise OutputError(f"stage resolution must be at least 1x1 pixels, got {resolution}")
