"""The transmittance of the air in front of the media, per pixel, as the sky pass takes it (without its radiance),
on a flat or a round earth.

A technique that traces the air itself (hybrid's multiple scattering) carries the air between the camera and each
event, while the frame's composite multiplies the media's layer by the sky pass's front transmittance; dividing by
this (the same float operations as :func:`~warpsky.passes.sky.sky_kernels.sky_kernel`, through the same
:func:`~warpsky.media.air.analytic.air_ray`) gives back exactly what the tracer carried.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core.numerics import exp3
from warpsky.light.sun import Sun
from warpsky.media.air.analytic import AnalyticAir, air_ray, analytic_air
from warpsky.media.air.mixture_kernels import split_transmittance
from warpsky.media.air.round_earth_kernels import RoundAir
from warpsky.media.air.round_earth_light import RoundMultiple
from warpsky.model.camera_rays import PinholeCamera, pinhole_camera, primary_ray
from warpsky.passes.sky.round_kernels import RoundView, front_light, round_ray
from warpsky.passes.sky.round_sky import round_front_inputs
from warpsky.surfaces.plane import Ground, ground_struct


@wp.kernel
def round_front_kernel(cam: PinholeCamera, air: AnalyticAir, ra: RoundAir, ms: RoundMultiple, view_table: RoundView,
                       sun: Sun, sun_radius: float, media_depth: wp.array2d(dtype=float),
                       transmittance: wp.array2d(dtype=wp.vec3)):
    """:func:`front_transmittance_kernel` on a round earth, through the same functions as
    :func:`~warpsky.passes.sky.round_kernels.round_sky_kernel`."""
    row, col = wp.tid()
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    along = round_ray(air, ra, cam, ray.origin[1], ray.direction, ray.cos_axis, media_depth[row, col])
    transmittance[row, col] = exp3(front_light(air, ra, ms, view_table, along, ray.direction, sun, sun_radius).depth)


@wp.kernel
def front_transmittance_kernel(cam: PinholeCamera, air: AnalyticAir, has_ground: int, ground: Ground,
                               media_depth: wp.array2d(dtype=float), transmittance: wp.array2d(dtype=wp.vec3)):
    """Per pixel, the air's transmittance (RGB) from the camera to the media's depth ``media_depth`` along the
    view axis [m] (the far plane or beyond: to where the air ends)."""
    row, col = wp.tid()
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    along = air_ray(air, cam, ray, has_ground, ground, media_depth[row, col])
    transmittance[row, col] = split_transmittance(air, along, ray.direction[1])


def front_air_transmittance(scene, width: int, height: int, media_depth: np.ndarray | None, device: str) -> np.ndarray:
    """(height, width, 3) float32: the front transmittance the sky pass gives ``scene`` (which has an atmosphere)
    at ``media_depth`` [m] along the view axis ((height, width); None: no media), bit for bit."""
    camera = scene.camera.conformed(width, height)
    if media_depth is None:
        media_depth = np.full((height, width), float(camera.far), np.float32)
    with wp.ScopedDevice(device):
        depth = wp.array(np.ascontiguousarray(media_depth, dtype=np.float32), dtype=float, device=device)
        out = wp.zeros((height, width), dtype=wp.vec3, device=device)
        if scene.atmosphere.round:
            wp.launch(round_front_kernel, dim=(height, width), device=device,
                      inputs=[*round_front_inputs(scene, camera, width, height, device), depth, out])
            return out.numpy()
        wp.launch(front_transmittance_kernel, dim=(height, width), inputs=[
            pinhole_camera(camera, width, height), analytic_air(scene.atmosphere, camera.position),
            int(scene.ground is not None), ground_struct(scene.ground, camera.position), depth, out,
        ], device=device)
        return out.numpy()
