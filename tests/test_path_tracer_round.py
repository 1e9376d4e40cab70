"""The path tracer's round earth: a huge planet is the flat earth, single scattering and the sunlit floor against a
float64 quadrature in the sphere's own geometry (the sun above and below the horizon), a white furnace, twilight.

The quadrature shares nothing with the kernels: every point's altitude is |c| - R of its float64 position c from the
planet's centre, the sun's optical depth a brute-force trapezoid along the ray to the disk's centre (the grazing ray
where the floor hides the centre, as the round earth's model takes it), and the disk's part above each point's
horizon the circular segment above the chord at the horizon's elevation, acos(R_floor / r) below the horizontal.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import warp as wp
from conftest import look_rotation

from evaluation.sky_error import case_scene, direction
from warpsky.media.air.medium import Air, air_coefficient, air_struct
from warpsky.model.scene import EARTH_RADIUS, Atmosphere, Camera, Ground, Scene, Sun
from warpsky.techniques.path_tracer.majorants import air_segment
from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings
from warpsky.techniques.path_tracer.planet import floor_hit

#: Pixels across a frame and its field [deg] (narrow: the pixels' mean is the centre's radiance).
PIXELS = 8
FIELD_DEG = 0.01
#: The quadrature's air ends at this altitude [m] (the density there is 1e-8 of sea level's).
REFERENCE_TOP = 150.0e3
#: Points of the quadrature along a view ray and along each point's ray to the sun.
VIEW_POINTS = 6000
SUN_POINTS = 1500


def rounded(scene: Scene, radius: float) -> Scene:
    """``scene`` over a round earth of sea level's ``radius`` [m]."""
    return dataclasses.replace(scene, atmosphere=dataclasses.replace(scene.atmosphere, planet_radius=radius))


def sky_scene(sun_elevation: float, view: np.ndarray, *, height: float = 1.0, albedo: float = 0.0,
              radius: float = EARTH_RADIUS) -> Scene:
    """Riley's air over a round earth, a sun of unit irradiance at ``sun_elevation`` [deg] (azimuth 0), the camera
    ``height`` [m] up looking along ``view`` over a ground of ``albedo`` (none for 0: a black sea level)."""
    focal = 0.5 * 36.0 / math.tan(math.radians(0.5 * FIELD_DEG))
    camera = Camera("cam", np.array([0.0, height, 0.0]), look_rotation(view), focal, 36.0, 36.0)
    ground = Ground(0.0, albedo=np.full(3, albedo)) if albedo > 0.0 else None
    return Scene(camera, Sun(direction(sun_elevation, 0.0), np.ones(3)), ground=ground,
                 atmosphere=Atmosphere(planet_radius=radius))


def render(scene: Scene, device: str, spp: int, seed: int = 1, **settings):
    """(mean radiance, its standard error, mean transmittance) over the frame's pixels, RGB, and the layer."""
    layer = PathTracer(PathTracerSettings(spp=spp, seed=seed, **settings), device=device).render(scene, PIXELS,
                                                                                                 PIXELS)
    n = PIXELS * PIXELS
    mean = layer.radiance.reshape(-1, 3).mean(axis=0).astype(np.float64)
    error = np.sqrt(layer.aovs["variance"].reshape(-1, 3).astype(np.float64).sum(axis=0)) / n
    return mean, error, layer.transmittance.reshape(-1, 3).mean(axis=0).astype(np.float64), layer


# ---- the float64 quadrature -----------------------------------------------------------------------------------


def sphere_crossings(c0: np.ndarray, v: np.ndarray, radius: float) -> tuple[float, float] | None:
    """Distances (near, far) along the ray c0 + t v (unit v) where it crosses the sphere of ``radius`` about the
    origin, or None when it misses."""
    b = float(c0 @ v)
    disc = b * b - (float(c0 @ c0) - radius * radius)
    if disc < 0.0:
        return None
    return -b - math.sqrt(disc), -b + math.sqrt(disc)


def column_to_top(atm: Atmosphere, r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """(N,) air column [m of sea-level air] from radii ``r`` along elevation sines ``mu`` to the quadrature's top
    (trapezoid rule in distance)."""
    planet = atm.planet_radius
    r_top = planet + REFERENCE_TOP
    length = -r * mu + np.sqrt(np.maximum(r * r * mu * mu + r_top * r_top - r * r, 0.0))
    s = np.linspace(0.0, 1.0, SUN_POINTS)[None, :] * length[:, None]
    h = np.sqrt(r[:, None] ** 2 + 2.0 * (r * mu)[:, None] * s + s * s) - planet
    return np.trapezoid(np.exp(-h / atm.scale_height), s, axis=1)


def disk_fraction(elevation: np.ndarray, radius: float) -> np.ndarray:
    """Part of a disk of angular ``radius`` centred ``elevation`` [rad] above a horizon's chord."""
    x = np.clip(elevation / radius, -1.0, 1.0)
    return np.clip((np.arccos(-x) + x * np.sqrt(1.0 - x * x)) / np.pi, 0.0, 1.0)


def sunlight_at(atm: Atmosphere, sun: Sun, c: np.ndarray, floor_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) transmittance of the sunlight to the points ``c`` (N, 3) about the planet's centre, times the part of
    its disk above their horizon; (N,) the sun's elevation sine there)."""
    r = np.linalg.norm(c, axis=1)
    mu_s = c @ sun.direction / r
    mu_h = -np.sqrt(np.maximum(1.0 - (floor_radius / r) ** 2, 0.0))
    visible = disk_fraction(np.arcsin(np.clip(mu_s, -1.0, 1.0)) - np.arcsin(mu_h), 0.5 * sun.angular_diameter)
    column = np.concatenate([column_to_top(atm, r[i:i + 500], np.maximum(mu_s, mu_h)[i:i + 500])
                             for i in range(0, len(r), 500)])
    return np.exp(-column[:, None] * atm.beta_sea_level[None, :]) * visible[:, None], mu_s


def single_scattering(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(radiance, transmittance) RGB along the camera's axis of the sunlight scattered once in Riley's air over a
    round earth, plus the sunlit ground (Lambertian, where the ray ends on it) seen through the air."""
    atm, sun = scene.atmosphere, scene.sun
    planet = atm.planet_radius
    v = -scene.camera.rotation[:, 2] / np.linalg.norm(scene.camera.rotation[:, 2])
    c0 = np.array([0.0, planet + atm.altitude + scene.camera.position[1], 0.0])
    air = sphere_crossings(c0, v, planet + REFERENCE_TOP)
    floor = sphere_crossings(c0, v, planet)
    if air is None:
        return np.zeros(3), np.ones(3)
    start, end = max(air[0], 0.0), air[1]
    hits = floor is not None and floor[0] > 0.0
    if hits:
        end = floor[0]
    t = np.linspace(start, end, VIEW_POINTS)
    c = c0[None, :] + t[:, None] * v[None, :]
    sigma = np.exp(-(np.linalg.norm(c, axis=1) - planet) / atm.scale_height)[:, None] * atm.beta_sea_level
    depth = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (sigma[1:] + sigma[:-1]) * np.diff(t)[:, None],
                                                        axis=0)])
    lit, _ = sunlight_at(atm, sun, c, planet)
    nu = float(v @ sun.direction)
    phase = 3.0 / (16.0 * math.pi) * (1.0 + nu * nu)
    radiance = np.trapezoid(sigma * np.exp(-depth) * lit, t, axis=0) * phase * sun.irradiance
    through = np.exp(-depth[-1])
    if hits:
        ground_lit, mu_s = sunlight_at(atm, sun, c[-1:], planet)
        albedo = scene.ground.albedo if scene.ground is not None else np.zeros(3)
        radiance = radiance + albedo / math.pi * sun.irradiance * ground_lit[0] * max(mu_s[0], 0.0) * through
        through = np.zeros(3)
    return radiance, through


# ---- the tests ------------------------------------------------------------------------------------------------


@wp.kernel
def majorant_check(air: Air, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                   worst: wp.array(dtype=float), segments: wp.array(dtype=int)):
    """Ray i: the air's segments from ``origins[i]`` along ``directions[i]`` to the floor or out of the air, the
    largest extinction over majorant at 65 points of each, and how many segments it took."""
    i = wp.tid()
    origin = origins[i]
    d = directions[i]
    t_max = floor_hit(air, origin, d)
    if t_max < 0.0:
        t_max = 1.0e30
    t = float(0.0)
    count = int(0)
    ratio = float(0.0)
    while t < t_max and count < 100000:
        seg = air_segment(air, origin, d, t, t_max)
        end = wp.min(seg.end, t_max)
        if seg.majorant > 0.0:
            for k in range(65):
                p = origin + (t + (end - t) * float(k) / 64.0) * d
                ratio = wp.max(ratio, wp.max(air_coefficient(air, p)) / seg.majorant)
        elif seg.end >= t_max:
            break
        count += 1
        t = wp.max(end, t)
    worst[i] = ratio
    segments[i] = count


@pytest.mark.parametrize("height", [1.0, 3.0e5])
def test_round_majorants_bound_the_air(device, height):
    """Along rays from the ground and from above the air, at every elevation (grazing ones through their perigee)
    and from points far from the camera, no point of a segment has more extinction than its majorant (the Earth's
    air: Rayleigh gas, aerosols, the ozone layer's tent), and the segments are few."""
    scene = rounded(case_scene(30.0, direction(10.0, 0.0), 0.0, air="earth"), EARTH_RADIUS)
    air = air_struct(scene, np.array([0.0, height, 0.0]), device)
    elevations = np.concatenate([np.linspace(-30.0, 90.0, 121), [-0.01, 0.0, 0.01, -17.2, -17.3, -16.9]])
    azimuths = np.radians([0.0, 37.0, 200.0])
    e, a = np.meshgrid(np.radians(elevations), azimuths)
    dirs = np.stack([np.cos(e) * np.sin(a), np.sin(e), -np.cos(e) * np.cos(a)], axis=-1).reshape(-1, 3)
    starts = np.array([[0.0, 0.0, 0.0], [3.0e5, 0.0, 0.0], [-2.0e5, 5.0e3, 6.0e5]])
    origins = np.repeat(starts, len(dirs), axis=0)
    directions = np.tile(dirs, (len(starts), 1))
    worst = wp.zeros(len(origins), dtype=float, device=device)
    segments = wp.zeros(len(origins), dtype=int, device=device)
    wp.launch(majorant_check, dim=len(origins), inputs=[
        air, wp.array(origins.astype(np.float32), dtype=wp.vec3, device=device),
        wp.array(directions.astype(np.float32), dtype=wp.vec3, device=device), worst, segments], device=device)
    assert worst.numpy().max() <= 1.0
    assert segments.numpy().max() < 200


@pytest.mark.slow  # four views, 8 s
@pytest.mark.parametrize("view, albedo, air", [((10.0, 90.0), 0.0, "rayleigh"), ((45.0, 180.0), 0.3, "aerosols"),
                                               ((90.0, 0.0), 0.0, "earth"), ((-90.0, 0.0), 0.3, "earth")])
def test_a_huge_planet_is_the_flat_earth(device, view, albedo, air):
    """Over a planet of radius 1e9 m every order of scattering and the ground's light agree with Riley's flat earth
    within the noise (4 sigma, and 3%), the sun at 30 deg, in Riley's air, with aerosols and with ozone too; the
    camera ray's transmittance (the round earth's by quadrature, the flat one's in closed form) within 0.2%."""
    flat = case_scene(30.0, direction(*view), albedo, air=air)
    settings = {"samples_per_pass": 256}
    mean, error, through, _ = render(flat, device, 1024, seed=11, **settings)
    mean_r, error_r, through_r, _ = render(rounded(flat, 1.0e9), device, 1024, seed=12, **settings)
    z = (mean_r - mean) / np.hypot(error, error_r)
    assert np.all(np.abs(z) < 4.0), (mean, mean_r, z)
    np.testing.assert_allclose(mean_r, mean, rtol=0.03)
    np.testing.assert_allclose(through_r, through, rtol=2.0e-3, atol=1.0e-6)


@pytest.mark.parametrize("sun, view, height, albedo", [
    (10.0, (5.0, 90.0), 1.0, 0.0), (10.0, (15.0, 150.0), 1.0, 0.0), (10.0, (30.0, 60.0), 1.0, 0.0),
    (-3.0, (5.0, 90.0), 1.0, 0.0), (-3.0, (15.0, 150.0), 1.0, 0.0), (-3.0, (30.0, 60.0), 1.0, 0.0),
    (10.0, (-5.0, 90.0), 3000.0, 0.3), (10.0, (-20.0, 150.0), 3.0e5, 0.3), (-3.0, (-16.5, 0.0), 3.0e5, 0.0)])
def test_single_scattering_matches_a_quadrature(device, sun, view, height, albedo):
    """With one scattering event per path the traced radiance is the sunlight scattered once along the camera ray
    plus the sunlit ground where the ray ends on it, as the float64 quadrature gives it: the sun 10 deg up and 3 deg
    below the horizon (twilight: only the air above the planet's shadow is lit), rays up from the ground, down onto
    the ground 34 km away (its normal 0.3 deg from the camera's vertical), and from 300 km up, above the air, onto
    the ground and past the planet's limb; the camera ray's transmittance within 0.2%."""
    scene = sky_scene(sun, direction(*view), height=height, albedo=albedo)
    reference, through_reference = single_scattering(scene)
    mean, error, through, _ = render(scene, device, 4096, max_bounces=1, samples_per_pass=512)
    z = (mean - reference) / error
    assert np.all(np.abs(z) < 4.0), (reference, mean, z)
    assert np.all(error < 0.05 * reference)  # sharp enough to see a 20% error
    np.testing.assert_allclose(through, through_reference, rtol=2.0e-3, atol=1.0e-6)


@pytest.mark.parametrize("view, height, escapes", [((10.0, 0.0), 1.0, True), ((-1.0, 0.0), 1.0, False),
                                                   ((-1.0, 0.0), 1.0e4, True), ((-90.0, 0.0), 1.0e4, False)])
def test_white_furnace(device, view, height, escapes):
    """A white floor sphere under non-absorbing air, lit by a uniform environment of radiance 1: every path's
    radiance plus what the composite draws behind the camera ray's transmittance is 1, looking up, onto the floor,
    and (from 10 km) 1 deg below the horizontal past the planet, where the ray leaves the top of the air."""
    scene = sky_scene(-30.0, direction(*view), height=height, albedo=1.0)
    scene = dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, irradiance=np.zeros(3)))
    mean, error, through, layer = render(scene, device, 256, environment=1.0)
    assert layer.stats["capped_paths"] == 0
    assert np.all(np.abs(mean + through - 1.0) < 4.0 * error + 1.0e-3), (mean, through, error)
    assert np.all(through > 0.01) if escapes else np.all(through == 0.0)


def test_twilight_fades_out(device):
    """Sunlight after sunset: finite and non-negative everywhere, fading as the sun sinks (3, 6, 10 deg below the
    horizon) and none at all once no part of the air sees it (20 deg); the flat earth is dark already at 3 deg."""
    view = direction(10.0, 0.0)
    totals = []
    for sun in (-3.0, -6.0, -10.0, -20.0):
        _, _, _, layer = render(rounded(case_scene(sun, view, 0.3), EARTH_RADIUS), device, 128)
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
        totals.append(float(layer.radiance.sum()))
    assert totals[0] > 5.0 * totals[1] > 0.0 and totals[1] > 5.0 * totals[2] >= 0.0
    assert totals[3] == 0.0
    _, _, _, flat = render(case_scene(-3.0, view, 0.3), device, 16)
    assert flat.radiance.max() == 0.0
