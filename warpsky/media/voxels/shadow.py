"""The optical depth of the voxel media along a shadow ray: the march towards the sun (or the zenith, or the nadir)
that the single-scatter march, slicing's ground and the surfaces pass share."""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.numerics import trilinear_cell
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


@wp.func
def column_above(values: wp.array(dtype=float), columns: wp.array(dtype=float), base: int, sy: int, ny: int,
                 y: float) -> float:
    """The integral of one column's field (nodes ``base + j * sy``, j = 0 .. ny - 1) from index height ``y`` in
    [-0.5, ny - 0.5] to the top, in index units: the stored sum above the node below ``y`` less the exact integral
    of the linear (constant past the outer nodes) field from that node to ``y``."""
    if y < 0.0:
        return columns[base] - y * values[base]
    j = wp.min(int(y), ny - 1)
    u = y - float(j)
    v = values[base + j * sy]
    if j == ny - 1:
        return columns[base + j * sy] - u * v
    w = values[base + (j + 1) * sy]
    return columns[base + j * sy] - u * (v + 0.5 * u * (w - v))


@wp.func
def column_depth(media: VoxelMedia, m: int, p: wp.vec3, down: int) -> float:
    """The integral of medium ``m``'s trilinear field straight up (``down`` 0) or down (1) from the index point
    ``p`` out of its box [m of field]: exact, the bilinear blend of the four columns around ``p`` (the trilinear
    field along a vertical line is that blend of theirs). Needs the grid's column sums (``up_metres`` > 0)."""
    grid = media.grids[m]
    n = grid.shape
    if p[0] < -0.5 or p[2] < -0.5 or p[0] > float(n[0]) - 0.5 or p[2] > float(n[2]) - 0.5:
        return 0.0
    y = wp.clamp(p[1], -0.5, float(n[1]) - 0.5)
    cell = trilinear_cell(p, n)
    sy = n[2]
    sx = n[1] * n[2]
    total = float(0.0)
    for c in range(4):
        i = wp.where(c / 2 == 0, cell.lo[0], cell.hi[0])
        k = wp.where(c % 2 == 0, cell.lo[2], cell.hi[2])
        wx = wp.where(c / 2 == 0, 1.0 - cell.frac[0], cell.frac[0])
        wz = wp.where(c % 2 == 0, 1.0 - cell.frac[2], cell.frac[2])
        base = grid.offset + i * sx + k
        above = column_above(media.values, media.columns, base, sy, n[1], y)
        if down != 0:
            above = column_above(media.values, media.columns, base, sy, n[1], -0.5) - above
        total += wx * wz * above
    return total * grid.up_metres


@functools.cache
def walk_function(has_detail: bool):
    """``medium_depth(media, m, start, world, direction, shadow_step) -> vec2``, specialised on animated detail:
    (the integral of medium ``m``'s value from the index point ``start`` (camera-relative ``world``) along
    ``direction`` out of its box [m of field], lookups). The chord is walked cell by cell
    (:func:`~warpsky.media.voxels.bricks.cell_step`); every run of non-empty cells is integrated by the midpoint
    rule in equal steps of at most ``shadow_step``, and empty cells, where every lookup is exactly 0, are skipped. A
    grid without cells, or whose cells are all occupied, is one run over its whole chord."""

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
    def medium_depth(media: VoxelMedia, m: int, start: wp.vec3, world: wp.vec3, sun_dir: wp.vec3,
                     shadow_step: float) -> wp.vec2:
        """(integral of medium ``m``'s value from the index point ``start`` (camera-relative ``world``) along
        ``sun_dir`` out of its box [m of field], lookups), its empty cells skipped."""
        grid = media.grids[m]
        toward_sun = grid.index_from_world * sun_dir  # index steps per metre towards the sun
        span = grid_interval(grid, start, toward_sun, 0.0, 1.0e30)
        total = wp.vec2(0.0)
        if span[1] <= span[0]:
            return total
        if grid.cells.shape[0] == 0:
            return run_depth(media, m, start, toward_sun, world, sun_dir, span[0], span[1], shadow_step)
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
                total += run_depth(media, m, start, toward_sun, world, sun_dir, run_start, run_end, shadow_step)
                in_run = 0
            u = cell.end
        return total

    return medium_depth


@functools.cache
def depth_functions(has_detail: bool):
    """``(sun_optical_depth, vertical_optical_depth)``, specialised on animated detail:

    ``sun_optical_depth(media, origin, t, view_dir, sun_dir, shadow_step) -> vec4``: optical depth (RGB in xyz)
    from the point ``origin + t * view_dir`` of the view ray towards ``sun_dir``, summed over all grids, and the
    number of grid lookups it took (w); each grid walked by :func:`walk_function`.

    ``vertical_optical_depth(media, origin, t, view_dir, down, shadow_step) -> vec4``: the same straight up
    (``down`` 0) or down (1), exact from the column sums (:func:`column_depth`) in grids whose index y is vertical
    when the media carry no detail, else walked."""

    medium_depth = walk_function(has_detail)

    @wp.func
    def sun_optical_depth(media: VoxelMedia, origin: wp.vec3, t: float, view_dir: wp.vec3, sun_dir: wp.vec3,
                          shadow_step: float) -> wp.vec4:
        tau = wp.vec3(0.0)
        lookups = float(0.0)
        world = origin + t * view_dir
        for m in range(media.count):
            grid = media.grids[m]
            start = grid.eye_index + grid.index_from_world * origin + t * (grid.index_from_world * view_dir)
            total = medium_depth(media, m, start, world, sun_dir, shadow_step)
            tau += grid.extinction * total[0]
            lookups += total[1]
        return wp.vec4(tau[0], tau[1], tau[2], lookups)

    @wp.func
    def vertical_optical_depth(media: VoxelMedia, origin: wp.vec3, t: float, view_dir: wp.vec3, down: int,
                               shadow_step: float) -> wp.vec4:
        tau = wp.vec3(0.0)
        lookups = float(0.0)
        world = origin + t * view_dir
        vertical = wp.where(down != 0, wp.vec3(0.0, -1.0, 0.0), wp.vec3(0.0, 1.0, 0.0))
        for m in range(media.count):
            grid = media.grids[m]
            start = grid.eye_index + grid.index_from_world * origin + t * (grid.index_from_world * view_dir)
            total = wp.vec2(0.0)
            use_columns = grid.up_metres > 0.0
            if wp.static(has_detail):  # detail multiplies the field: no column sums hold it
                use_columns = False
            if use_columns:
                total = wp.vec2(column_depth(media, m, start, down), 4.0)
            else:
                total = medium_depth(media, m, start, world, vertical, shadow_step)
            tau += grid.extinction * total[0]
            lookups += total[1]
        return wp.vec4(tau[0], tau[1], tau[2], lookups)

    return sun_optical_depth, vertical_optical_depth
