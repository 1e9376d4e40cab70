"""The optical depth of the voxel media along a shadow ray: the march towards the sun (or the zenith, or the nadir)
that the single-scatter march, slicing's ground and the surfaces pass share."""

from __future__ import annotations

import functools

import warp as wp

from warpsky.media.voxels.detail import detailed_value
from warpsky.media.voxels.voxel import VoxelMedia, grid_interval, grid_value


@functools.cache
def sun_depth_function(has_detail: bool):
    """``sun_optical_depth(media, origin, t, view_dir, sun_dir, shadow_step) -> vec4``: optical depth (RGB in xyz)
    from the point ``origin + t * view_dir`` of the view ray to the sun, summed over all grids, and the number of
    grid lookups it took (w); with ``has_detail`` the media's animated detail is included."""

    @wp.func
    def sun_optical_depth(media: VoxelMedia, origin: wp.vec3, t: float, view_dir: wp.vec3, sun_dir: wp.vec3,
                          shadow_step: float) -> wp.vec4:
        tau = wp.vec3(0.0)
        lookups = float(0.0)
        for m in range(media.count):
            grid = media.grids[m]
            start = grid.eye_index + grid.index_from_world * origin + t * (grid.index_from_world * view_dir)
            toward_sun = grid.index_from_world * sun_dir  # index steps per metre towards the sun
            span = grid_interval(grid, start, toward_sun, 0.0, 1.0e30)
            if span[1] > span[0]:
                length = span[1] - span[0]
                count = wp.max(int(wp.ceil(length / shadow_step)), 1)
                dt = length / float(count)
                total = float(0.0)
                # No early exit at large depth: a step's integral depends on the true depth at its far end through
                # (exp(-a) - exp(-b)) / (b - a), so a truncated b would brighten optically thick steps.
                for i in range(count):
                    s = span[0] + (float(i) + 0.5) * dt
                    value = grid_value(media.values, grid, start + s * toward_sun)
                    if wp.static(has_detail):
                        value = detailed_value(value, media.details, m, origin + t * view_dir + s * sun_dir)
                    total += value
                tau += grid.extinction * (total * dt)
                lookups += float(count)
        return wp.vec4(tau[0], tau[1], tau[2], lookups)

    return sun_optical_depth
