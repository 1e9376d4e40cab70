"""The planet under the path tracer's air: where a path meets the ground (the plane, or a round earth's floor, a
sphere), the ground's normal there (the local vertical) and its cosine-weighted bounce, and the air's transmittance
from a point to the sun (a flat earth's in closed form, a round one's from its table of optical depths with the
part of the disk above the point's own horizon)."""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import exp3
from warpsky.light.sun import Sun
from warpsky.media.air.medium import Air, air_coefficient, altitude, as_analytic, vertical
from warpsky.media.air.mixture_kernels import air_column
from warpsky.media.air.round_earth_kernels import floor_distance, sun_transmittance
from warpsky.surfaces.plane import Ground


@wp.func
def floor_hit(air: Air, origin: wp.vec3, d: wp.vec3) -> float:
    """Distance [m] from ``origin`` along ``d`` to a round earth's floor (its sphere); -1 when the ray misses it."""
    return floor_distance(air.planet, altitude(air, origin), wp.dot(d, vertical(air, origin)))


@wp.func
def ground_point(air: Air, ground: Ground, p: wp.vec3) -> wp.vec3:
    """Where a flight that ended on the ground at ``p`` meets it: on the plane, or on a round earth's floor."""
    if air.round != 0:
        return p - vertical(air, p) * (altitude(air, p) - air.planet.floor)
    return wp.vec3(p[0], ground.offset, p[2])


@wp.func
def ground_cosine(air: Air, sun: Sun, q: wp.vec3) -> float:
    """The cosine of the sunlight's incidence on the ground at ``q`` (0 from below its horizontal)."""
    if air.round != 0:
        return wp.max(wp.dot(sun.direction, vertical(air, q)), 0.0)
    return wp.max(sun.direction[1], 0.0)


@wp.struct
class DirectionSample:
    direction: wp.vec3
    state: wp.uint32


@wp.func
def cosine_up(state: wp.uint32) -> DirectionSample:
    """A cosine-weighted direction about +y (two random draws: radius, then azimuth)."""
    u1 = wp.randf(state)
    phi = 2.0 * wp.pi * wp.randf(state)
    rr = wp.sqrt(u1)
    out = DirectionSample()
    out.direction = wp.vec3(rr * wp.cos(phi), wp.sqrt(wp.max(1.0 - u1, 0.0)), rr * wp.sin(phi))
    out.state = state
    return out


@wp.func
def cosine_about(normal: wp.vec3, state: wp.uint32) -> DirectionSample:
    """A cosine-weighted direction about the unit ``normal`` (:func:`cosine_up`'s draws, turned onto it)."""
    out = cosine_up(state)
    sign = wp.sign(normal[2])
    if normal[2] == 0.0:
        sign = 1.0
    a = -1.0 / (sign + normal[2])
    b = normal[0] * normal[1] * a
    tangent = wp.vec3(1.0 + sign * normal[0] * normal[0] * a, sign * b, -sign * normal[0])
    bitangent = wp.vec3(b, sign + normal[1] * normal[1] * a, -normal[1])
    local = out.direction
    out.direction = wp.normalize(tangent * local[0] + normal * local[1] + bitangent * local[2])
    return out


@wp.func
def disk_radius(sun: Sun) -> float:
    """The angular radius [rad] of the sun's disk (0 without one)."""
    if sun.cos_radius > 1.0:
        return 0.0
    return wp.acos(sun.cos_radius)


@wp.func
def round_air_to_sun(air: Air, sun: Sun, p: wp.vec3) -> wp.vec3:
    """A round earth's air's transmittance from ``p`` to the sun (the table of optical depths), times the part of
    the disk above the floor's horizon seen from ``p``."""
    mu_s = wp.dot(sun.direction, vertical(air, p))
    return sun_transmittance(air.planet, altitude(air, p), mu_s, disk_radius(sun))


@wp.func
def air_to_sun(air: Air, sun: Sun, p: wp.vec3) -> wp.vec3:
    """The air's transmittance from ``p`` to the sun (ones without air): on a flat earth in closed form, its
    vertical column above ``p`` over ``air_sine``; on a round one :func:`round_air_to_sun`."""
    out = wp.vec3(1.0)
    if air.enabled != 0:
        if air.round != 0:
            out = round_air_to_sun(air, sun, p)
        elif air.mixed == 0:
            out = exp3(air_coefficient(air, p) / (air.gamma * sun.air_sine))
        else:
            out = exp3(air_column(as_analytic(air), air.camera_altitude + p[1]) / sun.air_sine)
    return out
