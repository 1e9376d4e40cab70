"""The optical depth of the voxel media along a shadow ray: the march towards the sun (or the zenith, or the nadir)
that the single-scatter march, slicing's ground and the surfaces pass share."""

from __future__ import annotations

import functools

import warp as wp

from warpsky.media.voxels.bricks import cell_step
from warpsky.media.voxels.detail import detailed_value
from warpsky.media.voxels.voxel import VoxelMedia, grid_interval, grid_value


@wp.func
def empty_until(media: VoxelMedia, origin: wp.vec3, direction: wp.vec3, t: float) -> float:
    """How far [m along the ray ``origin + t * direction``] every medium stays exactly 0 from ``t`` on: ``t`` itself
    when the point at ``t`` lies in an occupied cell (or a grid without cells), else the nearest end of the empty
    cell or the nearest entry of a grid ahead (1e30 when no grid lies ahead)."""
    until = float(1.0e30)
    for m in range(media.count):
        grid = media.grids[m]
        p0 = grid.eye_index + grid.index_from_world * origin
        dir_index = grid.index_from_world * direction
        span = grid_interval(grid, p0, dir_index, t, 1.0e30)
        if span[1] <= span[0]:
            continue
        if span[0] > t:
            until = wp.min(until, span[0])
            continue
        if grid.cells.shape[0] == 0:
            return t
        cell = cell_step(grid.cells, p0, dir_index, t, span[1])
        if media.occupancy[cell.index] > 0.0:
            return t
        until = wp.min(until, cell.end)
    return until


@functools.cache
def sun_depth_function(has_detail: bool):
    """``sun_optical_depth(media, origin, t, view_dir, sun_dir, shadow_step) -> vec4``: optical depth (RGB in xyz)
    from the point ``origin + t * view_dir`` of the view ray to the sun, summed over all grids, and the number of
    grid lookups it took (w); with ``has_detail`` the media's animated detail is included.

    Each grid's chord is walked cell by cell (:func:`~warpsky.media.voxels.bricks.cell_step`); every run of
    non-empty cells is integrated by the midpoint rule in equal steps of at most ``shadow_step``, and empty cells,
    where every lookup is exactly 0, are skipped. A grid without cells, or whose cells are all occupied, is one run
    over its whole chord."""

    @wp.func
    def run_depth(media: VoxelMedia, m: int, start: wp.vec3, toward_sun: wp.vec3, world: wp.vec3, sun_dir: wp.vec3,
                  a: float, b: float, shadow_step: float) -> wp.vec2:
        """(integral of medium ``m``'s value over [a, b] [m along the shadow ray], lookups): the midpoint rule in
        equal steps of at most ``shadow_step``; ``start`` and ``world`` the ray's origin in index space and
        camera-relative metres. No early exit at large depth: a step's integral depends on the true depth at its
        far end through (exp(-a) - exp(-b)) / (b - a), so a truncated b would brighten optically thick steps."""
        grid = media.grids[m]
        count = wp.max(int(wp.ceil((b - a) / shadow_step)), 1)
        dt = (b - a) / float(count)
        total = float(0.0)
        for i in range(count):
            s = a + (float(i) + 0.5) * dt
            value = grid_value(media.values, grid, start + s * toward_sun)
            if wp.static(has_detail):
                value = detailed_value(value, media.details, m, world + s * sun_dir)
            total += value
        return wp.vec2(total * dt, float(count))

    @wp.func
    def sun_optical_depth(media: VoxelMedia, origin: wp.vec3, t: float, view_dir: wp.vec3, sun_dir: wp.vec3,
                          shadow_step: float) -> wp.vec4:
        tau = wp.vec3(0.0)
        lookups = float(0.0)
        world = origin + t * view_dir
        for m in range(media.count):
            grid = media.grids[m]
            start = grid.eye_index + grid.index_from_world * origin + t * (grid.index_from_world * view_dir)
            toward_sun = grid.index_from_world * sun_dir  # index steps per metre towards the sun
            span = grid_interval(grid, start, toward_sun, 0.0, 1.0e30)
            if span[1] <= span[0]:
                continue
            total = wp.vec2(0.0)
            if grid.cells.shape[0] == 0:
                total = run_depth(media, m, start, toward_sun, world, sun_dir, span[0], span[1], shadow_step)
            else:
                run_start = span[0]
                in_run = int(0)
                u = span[0]
                while u < span[1]:
                    cell = cell_step(grid.cells, start, toward_sun, u, span[1])
                    occupied = media.occupancy[cell.index] > 0.0
                    if occupied and in_run == 0:
                        run_start = u
                        in_run = 1
                    if in_run != 0 and (not occupied or cell.end >= span[1]):
                        run_end = wp.where(occupied, wp.min(cell.end, span[1]), u)
                        total += run_depth(media, m, start, toward_sun, world, sun_dir, run_start, run_end,
                                           shadow_step)
                        in_run = 0
                    u = cell.end
            tau += grid.extinction * total[0]
            lookups += total[1]
        return wp.vec4(tau[0], tau[1], tau[2], lookups)

    return sun_optical_depth
