"""The sky pass: per pixel, air in front of the media's midplane, air behind it, and the sun's disk (Riley §4):
Riley's single scattering in closed form (with aerosols or ozone, :mod:`~warpsky.media.air.mixture_kernels`) plus
the light scattered more than once (:mod:`~warpsky.media.air.multiple_kernels`).
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import exp3
from warpsky.light.sun import Sun
from warpsky.media.air.analytic import INFINITE, AnalyticAir, air_ray
from warpsky.media.air.mixture_kernels import AirScatter, air_optical_depth, air_scatter
from warpsky.media.air.multiple_kernels import (
    AirMultiple,
    multiple_along_air,
    quadrupole_angular,
    whole_ray,
    whole_single,
)
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.optics.phase import phase_hg, phase_rayleigh
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
    sun_dir = sun.direction
    cos_theta = wp.dot(sun_dir, view)  # light travels along -sun, leaves towards the eye along -view
    phase = phase_rayleigh(cos_theta)
    phase_mie = phase_hg(cos_theta, air.mie_g)
    sun_y = sun.air_sine  # the sun's optical depth at height h is the vertical column over air_sine
    whole = ms.view_nodes > 0 and split >= t_end  # the frame's view table holds the whole ray's integrals
    single = AirScatter()
    if whole and air.mixed != 0:
        single = whole_single(ms, view[1])
    else:
        single = air_scatter(air, altitude, view[1], sun_y, split)
    front = single.rayleigh * phase + single.mie * phase_mie
    front_depth = air_optical_depth(air, altitude, view[1], split)
    t_front = exp3(front_depth)
    # the light scattered more than once: from the frame's view table for a whole ray, else integrated
    angular = quadrupole_angular(view, sun_dir)
    front_ms = wp.vec3(0.0)
    if whole:
        front_ms = whole_ray(ms, view[1], angular)
    else:
        front_ms = multiple_along_air(ms, air, altitude, view[1], angular, split)
    front_radiance[row, col] = wp.cw_mul(sun.irradiance, front + front_ms)
    front_transmittance[row, col] = t_front
    back = wp.vec3(0.0)
    if split < t_end:
        h_split = altitude + view[1] * split
        rest = t_end
        if t_end < INFINITE:
            rest = t_end - split
        rest_single = air_scatter(air, h_split, view[1], sun_y, rest)
        back = rest_single.rayleigh * phase + rest_single.mie * phase_mie
        if ms.view_nodes > 0:
            # the whole ray's less the front's, seen from the split: (whole - front) / T_front
            rest_ms = whole_ray(ms, view[1], angular) - front_ms
            for c in range(3):
                if t_front[c] > 1.0e-30:
                    back[c] += wp.max(rest_ms[c], 0.0) / t_front[c]
        else:
            back += multiple_along_air(ms, air, h_split, view[1], angular, rest)
        back = wp.cw_mul(sun.irradiance, back)
    # the sun's disk, behind everything, through the air beyond the split (to the top of the atmosphere); the
    # horizon clips it where the view ray ends on the ground or at sea level
    if t_end >= INFINITE and wp.dot(sun.disk_direction, view) >= sun.cos_radius and sun.lit != 0:
        beyond = wp.vec3(1.0)  # no media: the front layer's transmittance already holds all the air
        if split < INFINITE:
            beyond = exp3(air_optical_depth(air, altitude + view[1] * split, view[1], INFINITE))
        back += wp.cw_mul(sun.disk_radiance, beyond)
    back_radiance[row, col] = back
