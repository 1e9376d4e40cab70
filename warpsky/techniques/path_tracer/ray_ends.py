"""Where a path tracer's ray ends before its far distance: the ground plane, sea level (the air's floor; on a round
earth the floor's sphere), an opaque surface another pass draws, or a mesh the paths trace; and how far it runs.

Positions are camera-relative metres, y up (:mod:`warpsky.media.voxels.voxel`).
"""

from __future__ import annotations

import warp as wp

from warpsky.media.air.medium import Air, sea_level_distance
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.planet import floor_hit

#: What ends a ray before the far distance: nothing, the ground plane, sea level (the air's floor), an opaque
#: surface another pass draws behind the media (a mesh: the camera ray ends there, the path with nothing more), or a
#: mesh the path tracer traces itself (:mod:`~warpsky.techniques.path_tracer.surface_hits`: a Lambertian bounce).
SURFACE_NONE = wp.constant(0)
SURFACE_GROUND = wp.constant(1)
SURFACE_SEA = wp.constant(2)
SURFACE_OPAQUE = wp.constant(3)
SURFACE_MESH = wp.constant(4)
#: "No end": flights after the first bounce and rays toward the sun run this far [m].
UNBOUNDED = wp.constant(1.0e30)
#: A ground plane at sea level and sea level itself are one surface: distances within this relative difference
#: (rounding of two formulas) count as a tie, which the ground wins.
SURFACE_TIE = wp.constant(1.0e-5)

@wp.struct
class RayEnd:
    t: float  # distance [m] at which the ray ends
    surface: int  # SURFACE_* that ends it


@wp.func
def reaches_ground(ground: Ground, origin: wp.vec3, d: wp.vec3) -> bool:
    return d[1] < 0.0 and origin[1] > ground.offset


@wp.func
def ground_distance(ground: Ground, origin: wp.vec3, d: wp.vec3) -> float:
    """Distance [m] along ``d`` to the ground plane (for rays that reach it)."""
    return (ground.offset - origin[1]) / d[1]


@wp.func
def floor_surface(air: Air) -> int:
    """What a round earth's floor is: the ground (the scene's plane at or above sea level) or a black sea level."""
    if air.floor_ground != 0:
        return SURFACE_GROUND
    return SURFACE_SEA


@wp.func
def round_end(air: Air, ground: Ground, origin: wp.vec3, d: wp.vec3, t_end: float) -> RayEnd:
    """Where a ray ends on a round earth: at ``t_end``, else at the floor's sphere where it is nearer."""
    out = RayEnd()
    out.t = t_end
    out.surface = SURFACE_NONE
    t_floor = floor_hit(air, origin, d)
    if t_floor >= 0.0 and t_floor < t_end:
        out.t = t_floor
        out.surface = SURFACE_SEA
        if ground.enabled != 0:
            out.surface = floor_surface(air)
    return out


@wp.func
def primary_end(air: Air, ground: Ground, origin: wp.vec3, view: wp.vec3, t_end: float) -> RayEnd:
    """Where a camera ray from the near plane ends: the far plane at ``t_end``, else sea level, else the
    ground (the nearer wins; a ground at sea level wins within ``SURFACE_TIE`` of the distance); on a round
    earth the floor's sphere."""
    if air.enabled != 0 and air.round != 0:
        return round_end(air, ground, origin, view, t_end)
    out = RayEnd()
    out.t = t_end
    out.surface = SURFACE_NONE
    if air.enabled != 0 and view[1] < 0.0:
        t_sea = sea_level_distance(air, origin, view)
        if t_sea < out.t:
            out.t = t_sea
            out.surface = SURFACE_SEA
    if ground.enabled != 0:
        if reaches_ground(ground, origin, view):
            tg = ground_distance(ground, origin, view)
            if tg < out.t or (out.surface == SURFACE_SEA and tg <= out.t * (1.0 + SURFACE_TIE)):
                out.t = tg
                out.surface = SURFACE_GROUND
    return out


@wp.func
def flight_end(air: Air, ground: Ground, origin: wp.vec3, d: wp.vec3, bounce: int, first: RayEnd) -> RayEnd:
    """Where the flight of bounce ``bounce`` ends: the camera ray's end ``first`` for bounce 0, else the ground
    (or no end), then sea level where it is nearer (within ``SURFACE_TIE`` the ground); on a round earth the
    camera ray's end, else the floor's sphere (or no end)."""
    if air.enabled != 0 and air.round != 0:
        if bounce == 0:
            return first
        return round_end(air, ground, origin, d, UNBOUNDED)
    out = RayEnd()
    out.t = first.t
    out.surface = SURFACE_NONE
    if bounce > 0:
        out.t = UNBOUNDED
        if ground.enabled != 0:
            if reaches_ground(ground, origin, d):
                out.t = ground_distance(ground, origin, d)
                out.surface = SURFACE_GROUND
    elif first.surface == SURFACE_GROUND or first.surface == SURFACE_OPAQUE:
        out.surface = first.surface
    if air.enabled != 0 and d[1] < 0.0:
        t_sea = sea_level_distance(air, origin, d)
        if t_sea < out.t * (1.0 - SURFACE_TIE):
            out.t = t_sea  # the air ends at a black sea level (no ground plane above it here)
            out.surface = SURFACE_SEA
    return out
