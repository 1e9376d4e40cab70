"""The simulated storm's shots and render-time detail: a camera on the ground south of the rain shaft with the sun at
its back, aimed so that the primary rainbow crosses the shaft under the cloud base; a camera that keeps the whole storm
in frame from the side; and the detail that gives the solver's 500 m cells crisp, lumpy edges.

The primary bow is a cone of :data:`RAINBOW_DEG` around the antisolar point (the direction away from the sun, as
far below the horizon as the sun is above it). A direction at elevation η and ``Δ`` degrees of azimuth from the
antisolar point makes the angle θ with it, cos θ = cos e cos η cos Δ - sin e sin η (e the sun's elevation); the
camera looks at the shaft from where Δ puts θ at the bow's radius halfway up the shaft. The sun is fixed for the
run (its azimuth set for a shaft half a kilometre up at :data:`DISTANCE`); each frame's camera follows that frame's
shaft. The view is along the storm's north-south axis from the south, so the anvil spreads to the right (east,
downwind in the default sounding), with the shaft a fifth of the frame's height over its bottom edge.

The storm camera (``/World/StormCam``) stands :data:`STORM_DISTANCE` south of the middle of each frame's grid, which
moves with the storm, and looks north at a point :data:`STORM_AIM` up: the tower, the anvil spreading to the right
and the base over the horizon stay in frame as the storm travels, lit from behind the camera's right shoulder.

The detail (``warpsky:detail:*`` on the Volume, :class:`~warpsky.model.scene.DetailSpec`) is Neyret's advected
noise at render time: 35 % amplitude, features of 350 m, carried by the mid-level wind. Each field's
``warpsky:detail:edge`` (:data:`EDGES`) takes a small extinction off the detailed field: the cloud's thin fringe,
a trilinear ramp across a 500 m cell where the real boundary of a liquid cloud is sharp, clears where the noise is
low, so the tower's boundary becomes crisp and lumpy at the noise's scale. The ice and snow of the anvil get a
smaller edge (their fringe is real: crystals sublimate slowly), the rain none (its shaft keeps its soft sides).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: [deg] radius of the primary bow around the antisolar point (Descartes' minimum deviation for water, red 42.3,
#: violet 40.6).
RAINBOW_DEG = 42.0
#: [deg] the sun's elevation: high enough that the anvil shades its own underside (at 12 deg the light came in under
#: it and the whole storm was front-lit and flat), low enough that the bow's top (42 - 35 = 7 deg) stands over the
#: horizon, above the shaft.
SUN_ELEVATION = 35.0
#: [deg] azimuth (clockwise from north) of the view when the shaft is half a kilometre up at DISTANCE.
VIEW_AZIMUTH = 0.0
#: [m] the camera's distance from the shaft, its height over the ground, and [deg] how far it looks up and right
#: of the shaft (the tower and the anvil stand downwind, east of the shaft).
DISTANCE, EYE_HEIGHT, PITCH, YAW = 14000.0, 150.0, 30.0, 15.0
#: [mm] the shot camera's lens and film back.
FOCAL_LENGTH, APERTURE = 14.0, (36.0, 24.0)
#: Extinction [1/m] that counts as rain in the shaft and as cloud at the base.
RAINY, CLOUDY = 1.0e-5, 1.0e-3
#: [m] the storm camera's distance south of the grid's middle, its height, and the height it looks at; [mm] its lens.
STORM_DISTANCE, STORM_EYE_HEIGHT, STORM_AIM, STORM_FOCAL_LENGTH = 30000.0, 300.0, 5000.0, 28.0
#: [1/m] ``warpsky:detail:edge`` per field (module docstring).
EDGES = {"cloud": 0.01, "ice": 0.005, "snow": 0.005}
#: The Volume's render-time detail (USD attribute suffix, Sdf value type name, value).
DETAIL = (("amplitude", "Float", 0.35), ("scale", "Float", 350.0), ("wind", "Float3", (9.0, 0.0, 1.0)),
          ("curlSpeed", "Float", 3.0), ("period", "Float", 240.0), ("seed", "Int", 5))


@dataclass(frozen=True)
class Shaft:
    """Where a frame's rain shaft stands: its centre (east, north) [m] and the cloud base over it [m]."""

    centre: tuple[float, float]
    base: float


def bow_azimuth(sun_elevation: float, elevation: float) -> float:
    """Azimuth [deg] from the antisolar point of a direction at ``elevation`` [deg] on the primary bow, the sun at
    ``sun_elevation`` [deg] (module docstring); 0 when the bow does not reach that elevation."""
    e, eta = math.radians(sun_elevation), math.radians(elevation)
    cosine = (math.cos(math.radians(RAINBOW_DEG)) + math.sin(e) * math.sin(eta)) / (math.cos(e) * math.cos(eta))
    return math.degrees(math.acos(min(cosine, 1.0)))


def shot_sun() -> tuple[float, float]:
    """(elevation, azimuth clockwise from north) [deg] of the shot's sun: behind the camera, the antisolar point
    left of the view by the bow's azimuth half a kilometre up the shaft at :data:`DISTANCE`."""
    offset = bow_azimuth(SUN_ELEVATION, math.degrees(math.atan2(500.0, DISTANCE)))
    return SUN_ELEVATION, (VIEW_AZIMUTH - offset + 180.0) % 360.0


def find_shaft(beta: dict[str, np.ndarray], origin: np.ndarray, spacing: np.ndarray) -> Shaft:
    """The shaft of a frame's extinction (``beta`` per species, [x east, y north, z up]): the centre of the rain
    in the lowest 2 km weighted by its extinction (the condensate's centre when nothing falls yet, the grid's middle
    when all is clear), and the height of the lowest cloudy level over it."""
    shape = next(iter(beta.values())).shape if beta else (1, 1, 1)
    low = max(1, int(2000.0 / spacing[2]))
    rain = beta.get("rain", np.zeros(shape))[:, :, :low].sum(axis=2)
    weight = rain if rain.max() > RAINY else sum(beta.values()).sum(axis=2) if beta else np.zeros(shape[:2])
    if weight.max() <= 0.0:
        weight = np.ones(shape[:2])
    x, y = (origin[a] + spacing[a] * np.arange(shape[a]) for a in range(2))
    total = float(weight.sum())
    centre = (float((weight.sum(axis=1) * x).sum() / total), float((weight.sum(axis=0) * y).sum() / total))
    i = int(np.clip(np.searchsorted(x, centre[0]), 0, shape[0] - 1))
    j = int(np.clip(np.searchsorted(y, centre[1]), 0, shape[1] - 1))
    condensate = sum(beta[s][max(i - 2, 0):i + 3, max(j - 2, 0):j + 3].max(axis=(0, 1))
                     for s in ("cloud", "ice") if s in beta)
    levels = np.nonzero(np.asarray(condensate) > CLOUDY)[0] if beta else []
    base = origin[2] + spacing[2] * (levels.min() - 0.5) if len(levels) else 1000.0
    return Shaft(centre, float(base))


def shot_camera(shaft: Shaft, sun: tuple[float, float], ground: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) [m] of the frame's shot: :data:`DISTANCE` from the shaft at the azimuth where the bow crosses
    it halfway up to its base, looking :data:`PITCH` up and :data:`YAW` right of it."""
    height = max(shaft.base - ground, 200.0)
    elevation = math.degrees(math.atan2(0.5 * height - EYE_HEIGHT, DISTANCE))
    azimuth = math.radians(sun[1] - 180.0 + bow_azimuth(sun[0], elevation))
    pitch, view = math.radians(PITCH), azimuth + math.radians(YAW)
    toward = np.array([math.sin(azimuth), math.cos(azimuth)])
    eye = np.array([*(np.asarray(shaft.centre) - DISTANCE * toward), ground + EYE_HEIGHT])
    look = np.array([math.sin(view) * math.cos(pitch), math.cos(view) * math.cos(pitch), math.sin(pitch)])
    return eye, eye + DISTANCE * look


def storm_camera(middle: tuple[float, float], ground: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) [m] of the storm camera for a grid whose middle is ``middle`` (east, north) [m]."""
    eye = np.array([middle[0], middle[1] - STORM_DISTANCE, ground + STORM_EYE_HEIGHT])
    return eye, np.array([middle[0], middle[1], ground + STORM_AIM])


def _camera(stage, path: str, focal_length: float, poses) -> None:
    """Define the camera ``path`` with a pose per (time code, eye, target)."""
    from pxr import Gf, UsdGeom

    cam = UsdGeom.Camera.Define(stage, path)
    cam.CreateFocalLengthAttr(focal_length)
    cam.CreateHorizontalApertureAttr(APERTURE[0])
    cam.CreateVerticalApertureAttr(APERTURE[1])
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 300000.0))
    op = UsdGeom.Xformable(cam).AddTransformOp()
    for code, eye, target in poses:
        look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye.tolist()), Gf.Vec3d(*target.tolist()), Gf.Vec3d(0, 0, 1))
        op.Set(look.GetInverse(), code)


def author_shot(path, shafts: list[Shaft], middles: list[tuple[float, float]], codes: list[float],
                sun: tuple[float, float], ground: float = 0.0) -> None:
    """Add to the stage at ``path``: ``/World/RainbowCam`` (the render settings' camera) with a pose per time code
    following ``shafts``, ``/World/StormCam`` following the grid's ``middles``, the detail on ``/World/Weather`` and
    the edges on its fields."""
    from pxr import Gf, Sdf, Usd, UsdRender

    stage = Usd.Stage.Open(str(path))
    _camera(stage, "/World/RainbowCam", FOCAL_LENGTH,
            [(code, *shot_camera(shaft, sun, ground)) for code, shaft in zip(codes, shafts, strict=True)])
    _camera(stage, "/World/StormCam", STORM_FOCAL_LENGTH,
            [(code, *storm_camera(middle, ground)) for code, middle in zip(codes, middles, strict=True)])
    prim = stage.GetPrimAtPath("/World/Weather")
    for name, kind, value in DETAIL:
        typed = Gf.Vec3f(*value) if kind == "Float3" else value
        prim.CreateAttribute(f"warpsky:detail:{name}", getattr(Sdf.ValueTypeNames, kind)).Set(typed)
    for species, edge in EDGES.items():
        field_prim = stage.GetPrimAtPath(f"/World/Weather/{species}")
        if field_prim:
            field_prim.CreateAttribute("warpsky:detail:edge", Sdf.ValueTypeNames.Float).Set(edge)
    UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings")).GetCameraRel().SetTargets(
        [Sdf.Path("/World/RainbowCam")])
    stage.GetRootLayer().Save()
