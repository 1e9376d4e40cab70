"""The analytic sky against the path tracer's air: sky radiance and the ground's sky irradiance over a grid of sun
elevations, views and ground albedos, each case a small narrow-field frame traced with every order of scattering.

A sky case looks at a view 1 deg across (8 x 8 pixels) from 1 m above a flat ground: the sky pass (single
scattering in closed form plus the multiple-scattering table, or single scattering alone) against the path
tracer's mean over the same pixels, with its standard error. A ground case looks straight down at the ground from
1 m: the path tracer's radiance is the ground's, albedo / pi (sunlight + sky irradiance), against the same from
the sunlight through the air and the sky irradiance the surfaces pass takes (:func:`~warpsky.light.sky.sky_light`).
"""

from __future__ import annotations

import math

import numpy as np

from warpsky.light.sky import sky_light
from warpsky.light.sun import sunlight
from warpsky.media.air.mixture import sunlight_transmittance
from warpsky.model.scene import EARTH_AEROSOLS, EARTH_OZONE, EARTH_RADIUS, Atmosphere, Camera, Ground, Scene, Sun

#: Sun elevations [deg] of the grid, down to the horizon (a flat earth's air is dark once the disk has set) and, on
#: a round earth, through civil twilight.
SUN_ELEVATIONS = (90.0, 60.0, 30.0, 10.0, 5.0, 2.0, 0.0)
TWILIGHT_ELEVATIONS = (-2.0, -4.0, -6.0)
#: Suns at or below the horizon are traced with this many times the paths (few reach the sunlit air).
LOW_SUN_PATHS = 8
#: The earths compared: Riley's flat one and a round one of the Earth's radius.
EARTHS = {"flat": 0.0, "round": EARTH_RADIUS}
#: Views (elevation, azimuth from the sun) [deg], all >= 2 deg above the horizon.
VIEWS = ((90.0, 0.0), (45.0, 0.0), (45.0, 180.0), (10.0, 90.0), (10.0, 180.0), (2.0, 45.0), (2.0, 90.0),
         (2.0, 180.0))
ALBEDOS = (0.0, 0.3, 0.9)
#: The airs compared: Riley's Rayleigh gas alone, with Bruneton's and Hillaire's Earth aerosols, and with their
#: ozone too (:data:`~warpsky.model.scene.EARTH_AEROSOLS`, :data:`~warpsky.model.scene.EARTH_OZONE`).
AIRS = {"rayleigh": {}, "aerosols": EARTH_AEROSOLS, "earth": {**EARTH_AEROSOLS, **EARTH_OZONE}}
#: Pixels across a case's frame and the frame's width [deg].
PIXELS = 8
FIELD_DEG = 1.0


def _rotation(forward: np.ndarray) -> np.ndarray:
    """Camera rotation (columns right, up, back) looking along ``forward``."""
    back = -np.asarray(forward, dtype=np.float64) / np.linalg.norm(forward)
    up = np.array([0.0, 1.0, 0.0]) if abs(back[1]) < 0.999 else np.array([0.0, 0.0, -1.0])
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(back, right), back], axis=1)


def direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector ``elevation_deg`` above the horizon, ``azimuth_deg`` from the sun's azimuth (-z)."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)])


def clear_of_the_sun(sun_elevation: float, view: tuple[float, float]) -> bool:
    """Whether a view's frame (:data:`FIELD_DEG` across) stays clear of the sun's disk (the sky, not the disk, is
    compared)."""
    cos = float(direction(*view) @ direction(sun_elevation, 0.0))
    return math.degrees(math.acos(min(max(cos, -1.0), 1.0))) > 2.0 * FIELD_DEG


def sun_elevations(earth: str) -> tuple[float, ...]:
    """The grid's sun elevations for ``earth`` (a round one adds twilight)."""
    return SUN_ELEVATIONS + (TWILIGHT_ELEVATIONS if EARTHS[earth] > 0.0 else ())


def case_scene(sun_elevation: float, view: np.ndarray, albedo: float, *, multiple: bool = True,
               air: str = "rayleigh", earth: str = "flat") -> Scene:
    """The scene of one case: the air ``air`` of :data:`AIRS` on the earth ``earth`` of :data:`EARTHS`, a sun of
    unit irradiance, a ground of ``albedo`` (none for 0: the path tracer's black sea level), the camera 1 m up
    looking along ``view``."""
    focal = 0.5 * 36.0 / math.tan(math.radians(0.5 * FIELD_DEG))
    camera = Camera("cam", np.array([0.0, 1.0, 0.0]), _rotation(view), focal, 36.0, 36.0)
    ground = Ground(0.0, albedo=np.full(3, albedo)) if albedo > 0.0 else None
    return Scene(camera, Sun(direction(sun_elevation, 0.0), np.ones(3)), ground=ground,
                 atmosphere=Atmosphere(multiple_scattering=multiple, planet_radius=EARTHS[earth], **AIRS[air]))


def traced(scene: Scene, spp: int, device: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(mean radiance, its standard error) of the path tracer over the case's pixels, RGB."""
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    layer = PathTracer(PathTracerSettings(spp=spp, seed=seed), device=device).render(scene, PIXELS, PIXELS)
    n = PIXELS * PIXELS
    return (layer.radiance.reshape(-1, 3).mean(axis=0).astype(np.float64),
            np.sqrt(layer.aovs["variance"].reshape(-1, 3).astype(np.float64).sum(axis=0)) / n)


def sky_case(sun_elevation: float, view: tuple[float, float], albedo: float, *, spp: int, device: str = "cpu",
             seed: int = 7, air: str = "rayleigh", earth: str = "flat") -> dict:
    """One sky case: the sky pass with and without its multiple scattering against the path tracer."""
    from warpsky.passes.sky.sky import Sky

    v = direction(*view)
    scene = case_scene(sun_elevation, v, albedo, air=air, earth=earth)
    mean, error = traced(scene, spp, device, seed)
    table = Sky(device=device).render(scene, PIXELS, PIXELS)[0].radiance.reshape(-1, 3).mean(axis=0)
    single = Sky(device=device).render(case_scene(sun_elevation, v, albedo, multiple=False, air=air, earth=earth),
                                       PIXELS, PIXELS)[0].radiance.reshape(-1, 3).mean(axis=0)
    return {"kind": "sky", "air": air, "earth": earth, "sun": sun_elevation, "view": list(view), "albedo": albedo,
            "traced": mean.tolist(),
            "noise": error.tolist(), "table": table.astype(np.float64).tolist(),
            "single": single.astype(np.float64).tolist()}


def direct_sun(scene) -> np.ndarray:
    """Irradiance of the sunlight through the air on the case's horizontal ground, RGB."""
    from warpsky.light.frame import FrameLight

    light = sunlight(scene)
    atm = scene.atmosphere
    if atm.round:
        transmittance = FrameLight(scene, True).transmittance_at(0.0)
    else:
        transmittance = sunlight_transmittance(atm, atm.altitude, light.direction[1])
    return light.irradiance * max(light.direction[1], 0.0) * transmittance


def ground_case(sun_elevation: float, albedo: float, *, spp: int, device: str = "cpu", seed: int = 7,
                air: str = "rayleigh", earth: str = "flat") -> dict:
    """One ground case: albedo / pi (sunlight through the air + the sky irradiance the passes take) against the
    path-traced ground seen from 1 m above it."""
    down = np.array([0.0, -1.0, 0.0])
    scene = case_scene(sun_elevation, down, albedo, air=air, earth=earth)
    mean, error = traced(scene, spp, device, seed)
    out = {}
    for name, multiple in (("table", True), ("single", False)):
        s = case_scene(sun_elevation, down, albedo, multiple=multiple, air=air, earth=earth)
        direct = direct_sun(s)
        sky = sky_light(s, analytic=True)[1] * math.pi  # E / pi -> E
        out[name] = (albedo / math.pi * (direct + sky)).tolist()
    return {"kind": "ground", "air": air, "earth": earth, "sun": sun_elevation, "view": [-90.0, 0.0],
            "albedo": albedo,
            "traced": mean.tolist(), "noise": error.tolist(), **out}


def relative_errors(case: dict, key: str = "table") -> tuple[np.ndarray, np.ndarray]:
    """(relative error, relative noise) per channel of ``key`` against the traced mean (0 where it is dark)."""
    traced_mean = np.asarray(case["traced"])
    dark = traced_mean <= 0.0
    safe = np.where(dark, 1.0, traced_mean)
    err = np.where(dark, 0.0, (np.asarray(case[key]) - traced_mean) / safe)
    noise = np.where(dark, 0.0, np.asarray(case["noise"]) / safe)
    return err, noise


def net(case: dict, key: str = "table") -> float:
    """The case's worst channel error net of the path tracer's noise: max(|error| - 2 sigma, 0)."""
    err, noise = relative_errors(case, key)
    return float(np.max(np.maximum(np.abs(err) - 2.0 * noise, 0.0)))
