"""Coarse cells over a voxel grid: the largest field value per block of voxels, and the walk of a ray from cell to
cell.

A point in cell c (index positions c*block - 0.5 .. (c+1)*block - 0.5 along each axis) interpolates voxels
c*block - 1 .. (c+1)*block, so a cell holds the maximum over its voxels dilated by one voxel, edge-clamped like the
lookup (:func:`cell_maxima`). A cell holding 0 is empty: every trilinear lookup inside it, detail included (detail
multiplies the coarse value), is exactly 0. The shadow marches skip such cells (:mod:`~warpsky.media.voxels.shadow`)
and the path tracer's majorants are these maxima times the extinction (:mod:`warpsky.techniques.path_tracer.
majorants`), both through :func:`cell_step`.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class CoarseCells:
    """Coarse cells over one grid: cell (i, j, k) covers voxels [i*block, (i+1)*block) along each axis."""

    offset: int  # first cell in its flat buffer
    shape: wp.vec3i  # cells along index x, y, z (0: no cells, the grid is walked as one)
    block: float  # voxels per cell edge


@wp.struct
class CellStep:
    """The cell a ray is in just ahead of ``t`` and where the ray leaves it."""

    index: int  # the cell's index in its flat buffer (offset included)
    end: float  # where the ray leaves the cell, at most the walk's end, but at least a nudge ahead [m along the ray]


@wp.func
def cell_step(cells: CoarseCells, p0: wp.vec3, dir_index: wp.vec3, t: float, t_end: float) -> CellStep:
    """The cell holding the point just ahead of ``t`` on the index-space ray ``p0 + t * dir_index`` (a point on a
    boundary belongs to the next cell) and the ray's exit from it, at most ``t_end`` unless that is within the
    nudge.

    Float rounding can put a computed exit a hair before ``t``: the step forward is at least a nudge of 1e-4 voxel
    (or 1e-6 of t far from the camera), so a walk always progresses."""
    reach = wp.max(wp.max(wp.abs(dir_index[0]), wp.abs(dir_index[1])), wp.abs(dir_index[2]))
    nudge = wp.max(1.0e-4 / wp.max(reach, 1.0e-30), 1.0e-6 * wp.abs(t))
    probe = p0 + (t + nudge) * dir_index
    exit_t = t_end
    cell = wp.vec3i(0, 0, 0)
    for a in range(3):
        c = int(wp.floor((probe[a] + 0.5) / cells.block))
        c = wp.clamp(c, 0, cells.shape[a] - 1)
        cell[a] = c
        if dir_index[a] > 0.0:
            exit_t = wp.min(exit_t, (float(c + 1) * cells.block - 0.5 - p0[a]) / dir_index[a])
        elif dir_index[a] < 0.0:
            exit_t = wp.min(exit_t, (float(c) * cells.block - 0.5 - p0[a]) / dir_index[a])
    out = CellStep()
    out.index = cells.offset + (cell[0] * cells.shape[1] + cell[1]) * cells.shape[2] + cell[2]
    out.end = wp.max(exit_t, t + nudge)
    return out


def effective_block(shape: tuple[int, ...], block: int) -> int:
    """Cell edge [voxels] actually used for a grid of ``shape``: at most its largest edge."""
    return max(1, min(int(block), max(shape)))


def cell_maxima(density: np.ndarray, block: int) -> np.ndarray:
    """The largest trilinearly interpolated value of ``density`` in each cell of ``block`` voxels: the maximum over
    the cell's voxels dilated by one voxel (module docstring). ``block`` is clamped to the largest grid edge
    (:func:`effective_block`), where one cell holds the whole grid. The maximum over a box is taken one axis at a
    time, each axis shrinking the array ``block`` times, so the temporaries stay a fraction of the grid (a dilated
    full-size copy and its padded shifts held five grids at once: 2.6 GiB on a 510 MiB voxelised deck)."""
    d = np.asarray(density, dtype=np.float32)
    block = effective_block(d.shape, block)
    for axis in range(3):
        d = _axis_maxima(d, axis, block)
    return d


def _axis_maxima(values: np.ndarray, axis: int, block: int) -> np.ndarray:
    """``values`` reduced along ``axis`` to ceil(n / block) cells, cell c holding the maximum over indices
    c*block - 1 .. (c+1)*block clamped to 0 .. n - 1."""
    n = values.shape[axis]
    starts = np.arange(0, n, block)
    out = np.maximum.reduceat(values, starts, axis=axis)  # c*block .. (c+1)*block - 1
    before = np.maximum(starts - 1, 0)
    np.maximum(out, values.take(before, axis=axis), out=out)
    after = np.minimum(starts + block, n - 1)
    np.maximum(out, values.take(after, axis=axis), out=out)
    return out
