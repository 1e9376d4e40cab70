"""The sky pass: per pixel, air in front of the media's midplane, air behind it, and the sun's disk (Riley §4):
Riley's single scattering in closed form plus the light scattered more than once (:mod:`~warpsky.media.air_multiple`).
"""

from __future__ import annotations

import warp as wp

from warpsky.camera_rays import PinholeCamera, primary_ray
from warpsky.light.sun import Sun
from warpsky.media.air_analytic import INFINITE, AnalyticAir, air_depth, air_inscatter, air_ray
from warpsky.media.air_multiple import AirMultiple, multiple_along, quadrupole_angular, whole_ray
from warpsky.numerics import exp3
from warpsky.optics.phase import phase_rayleigh
from warpsky.surfaces.plane import Ground


@wp.kernel
def sky_kernel(
    cam: PinholeCamera,
    air: AnalyticAir,
    ms: AirMultiple,
    sun: Sun,
    has_ground: int,
    ground: Ground,
    media_depth: wp.array2d(dtype=float),
    front_radiance: wp.array2d(dtype=wp.vec3),
    front_transmittance: wp.array2d(dtype=wp.vec3),
    back_radiance: wp.array2d(dtype=wp.vec3),
):
    row, col = wp.tid()
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    view = ray.direction
    along = air_ray(air, cam, ray, has_ground, ground, media_depth[row, col])
    altitude = along.altitude
    t_end = along.t_end
    split = along.split
    beta_sl = air.beta_sea_level
    gamma = air.gamma
    sun_dir = sun.direction
    cos_theta = wp.dot(sun_dir, view)  # light travels along -sun, leaves towards the eye along -view
    phase = phase_rayleigh(cos_theta)
    sun_y = sun.air_sine  # the sun's optical depth at height h is the vertical column over air_sine
    front = air_inscatter(beta_sl, gamma, altitude, view[1], sun_y, split) * phase
    front_depth = air_depth(beta_sl, gamma, altitude, view[1], split)
    t_front = exp3(front_depth)
    # the light scattered more than once: from the frame's view table for a whole ray, else integrated
    angular = quadrupole_angular(view, sun_dir)
    front_ms = wp.vec3(0.0)
    if ms.view_nodes > 0 and split >= t_end:
        front_ms = whole_ray(ms, view[1], angular)
    else:
        front_ms = multiple_along(ms, beta_sl, gamma, altitude, view[1], angular, front_depth)
    front_radiance[row, col] = wp.cw_mul(sun.irradiance, front + front_ms)
    front_transmittance[row, col] = t_front
    back = wp.vec3(0.0)
    if split < t_end:
        h_split = altitude + view[1] * split
        rest = t_end
        if t_end < INFINITE:
            rest = t_end - split
        back = air_inscatter(beta_sl, gamma, h_split, view[1], sun_y, rest) * phase
        if ms.view_nodes > 0:
            # the whole ray's less the front's, seen from the split: (whole - front) / T_front
            rest_ms = whole_ray(ms, view[1], angular) - front_ms
            for c in range(3):
                if t_front[c] > 1.0e-30:
                    back[c] += wp.max(rest_ms[c], 0.0) / t_front[c]
        else:
            back += multiple_along(ms, beta_sl, gamma, h_split, view[1], angular,
                                   air_depth(beta_sl, gamma, h_split, view[1], rest))
        back = wp.cw_mul(sun.irradiance, back)
    # the sun's disk, behind everything, through the air beyond the split (to the top of the atmosphere); the
    # horizon clips it where the view ray ends on the ground or at sea level
    if t_end >= INFINITE and wp.dot(sun.disk_direction, view) >= sun.cos_radius and sun.lit != 0:
        beyond = wp.vec3(1.0)  # no media: the front layer's transmittance already holds all the air
        if split < INFINITE:
            beyond = exp3(air_depth(beta_sl, gamma, altitude + view[1] * split, view[1], INFINITE))
        back += wp.cw_mul(sun.disk_radiance, beyond)
    back_radiance[row, col] = back
