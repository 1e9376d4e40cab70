"""The ground behind the media in half-angle slicing: a Lambertian plane lit by the sun through the media (shadow
rays marched per voxel) and by the sky above it, occluded towards the zenith. It runs after the sweep, on the sweep's
images still on the device, and ends every eye ray that reaches it."""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3
from warpsky.light.dome import ambient_ground
from warpsky.light.sun import Sun
from warpsky.media.voxels.shadow import depth_functions
from warpsky.media.voxels.voxel import VoxelMedia
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.surfaces.plane import Ground


@kernel_variants(has_detail=(False, True), has_dome=(False, True))
@functools.cache
def ground_kernel(has_detail: bool = False, has_dome: bool = False):
    """The ground pass, specialised on animated detail (the shadow rays see the same detailed media) and on a dome
    (its ambient light, occluded by the media towards the zenith)."""

    sun_optical_depth, vertical_optical_depth = depth_functions(has_detail)

    @wp.kernel(module="unique")
    def ground_pass(
        media: VoxelMedia,
        cam: PinholeCamera,
        sun: Sun,
        ground: Ground,
        shadow_step: float,
        ground_ambient: wp.vec3,
        radiance: wp.array2d(dtype=wp.vec3),
        transmittance: wp.array2d(dtype=wp.vec3),
        depth: wp.array2d(dtype=float),
        row_offset: int,
    ):
        """The Lambertian ground behind the media, lit by the sun through them; it ends every ray that reaches it."""
        r, col = wp.tid()
        row = r + row_offset
        ray = primary_ray(cam, row, col, 0.5, 0.5)  # a pinhole's: from the eye
        view = ray.direction
        if view[1] >= 0.0 or ground.offset >= 0.0:
            return
        t = ground.offset / view[1]
        z = t * ray.cos_axis
        if z > cam.far:
            return
        sun_dir = sun.direction
        lit = wp.vec3(0.0)
        if sun.lit != 0:
            tau = sun_optical_depth(media, wp.vec3(0.0), t, view, sun_dir, shadow_step)  # rays from the eye
            lit = wp.cw_mul(sun.irradiance, exp3(wp.vec3(tau[0], tau[1], tau[2]))) * (wp.max(sun_dir[1], 0.0) / wp.pi)
        before = transmittance[row, col]
        radiance[row, col] = radiance[row, col] + wp.cw_mul(before, wp.cw_mul(ground.albedo, lit))
        if wp.static(has_dome):
            up = vertical_optical_depth(media, wp.vec3(0.0), t, view, 0, shadow_step)
            shown = ambient_ground(ground.albedo, ground_ambient, wp.vec3(up[0], up[1], up[2]))
            radiance[row, col] = radiance[row, col] + wp.cw_mul(before, shown)
        if (before[0] + before[1] + before[2]) > 1.5:  # mostly clear: the ground is what the pixel shows
            depth[row, col] = z
        transmittance[row, col] = wp.vec3(0.0)

    return ground_pass
