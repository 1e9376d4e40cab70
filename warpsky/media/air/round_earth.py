"""A round earth's air for host code: the sunlight's transmittance to an altitude, the transmittance to space and
the sky's radiance along given directions, each evaluated by the device functions the sky pass uses
(:mod:`~warpsky.media.air.round_earth_kernels`, :mod:`~warpsky.media.air.round_earth_light`) on the CPU, so the light on
media, ground and layers is the light the sky pass draws.

On a round earth the sun can light the high air after it has set for the ground (twilight): the scene's sunlight
is the whole disk along its centre (:func:`round_sunlight`) whenever any of it stands above the horizon seen from
the top of the air, and every point takes its own share of the disk above its own horizon
(:func:`~warpsky.media.air.round_earth_kernels.sun_transmittance`).
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.media.air.analytic import AnalyticAir, analytic_air
from warpsky.media.air.multiple import floor_of
from warpsky.media.air.round_earth_kernels import (
    RoundAir,
    air_top,
    floor_distance,
    ray_depth,
    round_struct,
    sun_transmittance,
    table_depth,
    top_distance,
)
from warpsky.media.air.round_earth_light import RoundMultiple, SunGeometry, round_light
from warpsky.media.air.round_earth_multiple import multiple_struct, round_table
from warpsky.optics.phase import phase_hg, phase_rayleigh

#: Host evaluations run on this device.
HOST = "cpu"


def sun_radius(angular_diameter: float) -> float:
    """The disk's angular radius [rad] of a sun of ``angular_diameter`` [rad]."""
    return 0.5 * float(angular_diameter)


def air_lit(atm, floor: float, elevation: float, radius: float) -> bool:
    """Whether a sun at ``elevation`` [rad, at the eye] of angular ``radius`` lights any of the air: part of its disk
    above the floor's horizon seen from the top of the air."""
    r_floor, r_top = atm.planet_radius + floor, atm.planet_radius + air_top(atm)
    dip = math.acos(min(r_floor / r_top, 1.0))
    return elevation + radius > -dip


def scene_floor(scene) -> float:
    """Altitude [m above sea level] where ``scene``'s air ends below (the ground at or above sea level, else sea
    level)."""
    return floor_of(scene)[0]


@wp.kernel
def _sun_kernel(ra: RoundAir, points: wp.array(dtype=wp.vec2), radius: float, out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = sun_transmittance(ra, points[i][0], points[i][1], radius)


def sunlight_transmittance(atm, floor: float, altitude, mu_s: float, radius: float) -> np.ndarray:
    """(..., 3) transmittance of the sunlight down to ``altitude`` [m above sea level] on a round earth, for a sun of
    elevation sine ``mu_s`` at the eye (taken as the local one: the points are near the eye) and angular
    ``radius`` [rad], its disk clipped by each point's horizon."""
    altitude = np.asarray(altitude, dtype=np.float64)
    points = np.stack([altitude.ravel(), np.full(altitude.size, float(mu_s))], axis=-1).astype(np.float32)
    ra = round_struct(atm, floor, HOST)
    out = wp.zeros(len(points), dtype=wp.vec3, device=HOST)
    wp.launch(_sun_kernel, dim=len(points), inputs=[ra, wp.array(points, dtype=wp.vec2, device=HOST), float(radius),
                                                    out], device=HOST)
    return out.numpy().astype(np.float64).reshape(altitude.shape + (3,))


@wp.kernel
def _space_kernel(ra: RoundAir, altitude: float, directions: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    mu = directions[i][1]
    out[i] = wp.vec3(0.0)
    if floor_distance(ra, altitude, mu) < 0.0:
        d = table_depth(ra, altitude, mu)
        out[i] = wp.vec3(wp.exp(-d[0]), wp.exp(-d[1]), wp.exp(-d[2]))


def space_transmittance(atm, floor: float, altitude: float, directions: np.ndarray) -> np.ndarray:
    """(N, 3) transmittance of the air from ``altitude`` along unit ``directions`` (N, 3) to space; 0 where the
    floor is in the way."""
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    ra = round_struct(atm, floor, HOST)
    out = wp.zeros(len(directions), dtype=wp.vec3, device=HOST)
    wp.launch(_space_kernel, dim=len(directions), inputs=[
        ra, float(altitude), wp.array(directions.astype(np.float32), dtype=wp.vec3, device=HOST), out], device=HOST)
    return out.numpy().astype(np.float64)


#: Directions per row of :func:`radiance`'s launch (rows run in parallel bands on the CPU).
RADIANCE_ROW = wp.constant(64)


@wp.kernel
def _radiance_kernel(air: AnalyticAir, ra: RoundAir, ms: RoundMultiple, altitude: float, sun: wp.vec3,
                     radius: float, directions: wp.array(dtype=wp.vec3), distance: wp.array(dtype=float),
                     out: wp.array(dtype=wp.vec3), row_offset: int):
    r, c = wp.tid()
    i = (r + row_offset) * RADIANCE_ROW + c
    if i >= directions.shape[0]:
        return
    view = directions[i]
    end = floor_distance(ra, altitude, view[1])
    if end < 0.0:
        end = top_distance(ra, altitude, view[1])
    geometry = SunGeometry()
    geometry.mu_s0 = sun[1]
    geometry.nu = wp.dot(view, sun)
    geometry.radius = radius
    light = round_light(air, ra, ms, altitude, view[1], geometry, wp.min(end, distance[i]))
    out[i] = (light.rayleigh * phase_rayleigh(geometry.nu) + light.mie * phase_hg(geometry.nu, air.mie_g)
              + light.multiple)


def multiple_for(scene, device=HOST) -> RoundMultiple:
    """Kernel view of the multiple-scattering table of ``scene``'s round air (off when the atmosphere turns it
    off)."""
    atm = scene.atmosphere
    floor, albedo = floor_of(scene)
    table = round_table(atm, floor, albedo, device) if atm.multiple_scattering else None
    return multiple_struct(table, device, name="round_multiple:host" if device == HOST else "round_multiple")


def radiance(scene, light, altitude: float, directions: np.ndarray, distance=np.inf) -> np.ndarray:
    """(N, 3) radiance of ``scene``'s round air seen from ``altitude`` [m above sea level] along unit
    ``directions`` (N, 3) over ``distance`` [m] (scalar or (N,); inf: to the floor or out of the air), for the
    sunlight ``light`` above the air: what the sky pass draws."""
    atm = scene.atmosphere
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    distance = np.broadcast_to(np.minimum(np.asarray(distance, dtype=np.float64), 1.0e30), (len(directions),))
    floor = scene_floor(scene)
    out = wp.zeros(len(directions), dtype=wp.vec3, device=HOST)
    # in row bands over every core: the skylight of a small frame spent a third of its time here on one
    launch_rows(_radiance_kernel, -(-len(directions) // RADIANCE_ROW), RADIANCE_ROW, [
        analytic_air(atm, np.zeros(3)), round_struct(atm, floor, HOST), multiple_for(scene),
        float(min(max(altitude, floor), air_top(atm))), wp.vec3(*np.asarray(light.disk_direction).tolist()),
        sun_radius(light.angular_diameter),
        wp.array(directions.astype(np.float32), dtype=wp.vec3, device=HOST),
        wp.array(distance.astype(np.float32), dtype=float, device=HOST), out], HOST)
    return np.asarray(light.irradiance, dtype=np.float64)[None, :] * out.numpy().astype(np.float64)


@wp.kernel
def _floor_kernel(air: AnalyticAir, ra: RoundAir, altitude: float, directions: wp.array(dtype=wp.vec3),
                  out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    mu = directions[i][1]
    end = floor_distance(ra, altitude, mu)
    out[i] = wp.vec3(0.0)
    if end >= 0.0:
        d = ray_depth(air, ra, altitude, mu, end)
        out[i] = wp.vec3(wp.exp(-d[0]), wp.exp(-d[1]), wp.exp(-d[2]))


def floor_transmittance(atm, floor: float, altitude: float, directions: np.ndarray) -> np.ndarray:
    """(N, 3) transmittance of the air from ``altitude`` along unit ``directions`` (N, 3) down to the floor; 0
    where a direction misses it (it passes above the horizon)."""
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    out = wp.zeros(len(directions), dtype=wp.vec3, device=HOST)
    wp.launch(_floor_kernel, dim=len(directions), inputs=[
        analytic_air(atm, np.zeros(3)), round_struct(atm, floor, HOST), float(max(altitude, floor)),
        wp.array(directions.astype(np.float32), dtype=wp.vec3, device=HOST), out], device=HOST)
    return out.numpy().astype(np.float64)
