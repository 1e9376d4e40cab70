"""The media's shadow on their own sky light in half-angle slicing: optical depths towards the zenith and nadir.

The slicing sweep carries the sun's light through the media slice by slice; the sky's light comes from every
direction and has no such buffer. The march (single_scatter) occludes the sky's upper hemisphere by the
transmittance towards the zenith and the lower one by that towards the nadir, each marched per sample. Slicing
takes the same two transmittances from a grid computed once per frame: over the box around the media, nodes at most
the finest voxel apart (at most :data:`MAX_NODES` per axis), each holding the optical depth from it straight up to
the box's top and straight down to its bottom, RGB. Each column is integrated from its end with two midpoint
samples per node spacing; the eye gather interpolates the optical depths trilinearly and takes exp(-tau).
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import launch_rows
from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3, trilinear_cell
from warpsky.media.voxels.voxel import VoxelMedia, media_functions

#: Most grid nodes along one axis of the occlusion grid.
MAX_NODES = 64
#: Midpoint samples per node spacing when a column is integrated.
SUBSTEPS = wp.constant(2)


@wp.struct
class SkyShadow:
    """Optical depths towards the zenith (``up``) and nadir (``down``) at the nodes of a box, RGB.

    Attributes:
        up, down: (nx, ny, nz) optical depth from node (i, j, k) to the box's top / bottom.
        origin: Camera-relative position of node (0, 0, 0) [m].
        cell: Node spacing along x, y, z [m].
        on: 0: no grid (every transmittance is 1).
    """

    up: wp.array3d(dtype=wp.vec3)
    down: wp.array3d(dtype=wp.vec3)
    origin: wp.vec3
    cell: wp.vec3
    on: int


@wp.func
def shadow_depth(grid: wp.array3d(dtype=wp.vec3), shadow: SkyShadow, p: wp.vec3) -> wp.vec3:
    """Trilinear optical depth of ``grid`` at camera-relative ``p`` (clamped to the box)."""
    cell = trilinear_cell(wp.cw_div(p - shadow.origin, shadow.cell),
                          wp.vec3i(grid.shape[0], grid.shape[1], grid.shape[2]))
    lo = cell.lo
    hi = cell.hi
    f = cell.frac
    c00 = grid[lo[0], lo[1], lo[2]] * (1.0 - f[2]) + grid[lo[0], lo[1], hi[2]] * f[2]
    c01 = grid[lo[0], hi[1], lo[2]] * (1.0 - f[2]) + grid[lo[0], hi[1], hi[2]] * f[2]
    c10 = grid[hi[0], lo[1], lo[2]] * (1.0 - f[2]) + grid[hi[0], lo[1], hi[2]] * f[2]
    c11 = grid[hi[0], hi[1], lo[2]] * (1.0 - f[2]) + grid[hi[0], hi[1], hi[2]] * f[2]
    return (c00 * (1.0 - f[1]) + c01 * f[1]) * (1.0 - f[0]) + (c10 * (1.0 - f[1]) + c11 * f[1]) * f[0]


@wp.func
def sky_transmittances(shadow: SkyShadow, p: wp.vec3):
    """(transmittance towards the zenith, towards the nadir), RGB, at camera-relative ``p``."""
    if shadow.on == 0:
        return wp.vec3(1.0), wp.vec3(1.0)
    up = shadow_depth(shadow.up, shadow, p)
    down = shadow_depth(shadow.down, shadow, p)
    return exp3(up), exp3(down)


@kernel_variants(has_detail=(False, True))
@functools.cache
def column_depth_kernel(has_detail: bool = False):
    """Integrate each (i, k) column of the occlusion grid from both ends (see the module docstring)."""
    sample_media = media_functions(has_detail)

    @wp.kernel(module="unique")
    def column_depths(media: VoxelMedia, shadow: SkyShadow, row_offset: int):
        r, k = wp.tid()
        i = r + row_offset
        ny = shadow.up.shape[1]
        h = shadow.cell[1] / float(SUBSTEPS)
        base = shadow.origin + wp.vec3(float(i) * shadow.cell[0], 0.0, float(k) * shadow.cell[2])
        tau = wp.vec3(0.0)
        shadow.down[i, 0, k] = tau
        for j in range(1, ny):  # upwards: depth down to the bottom
            for s in range(SUBSTEPS):
                y = (float(j - 1) + (float(s) + 0.5) / float(SUBSTEPS)) * shadow.cell[1]
                tau += sample_media(media, base + wp.vec3(0.0, y, 0.0)).extinction * h
            shadow.down[i, j, k] = tau
        tau = wp.vec3(0.0)
        shadow.up[i, ny - 1, k] = tau
        for r in range(1, ny):  # downwards: depth up to the top
            j = ny - 1 - r
            for s in range(SUBSTEPS):
                y = (float(j) + 1.0 - (float(s) + 0.5) / float(SUBSTEPS)) * shadow.cell[1]
                tau += sample_media(media, base + wp.vec3(0.0, y, 0.0)).extinction * h
            shadow.up[i, j, k] = tau

    return column_depths


def sky_shadow(media_buffers, corners: np.ndarray, finest: float, device, *, on: bool) -> SkyShadow:
    """The frame's :class:`SkyShadow` over the box of camera-relative ``corners`` (N, 3) [m], nodes at most
    ``finest`` [m] apart, kept on the device under ``slicing:sky_shadow_*``; an empty struct (``on`` 0) when
    ``on`` is False (no ambient light)."""
    out = SkyShadow()
    out.on = int(on)
    if not on:
        out.origin, out.cell = wp.vec3(0.0), wp.vec3(1.0)
        out.up = out.down = device_buffers.reusable("slicing:sky_shadow_none", (1, 1, 1), wp.vec3, device)
        return out
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    extent = np.maximum(hi - lo, 1e-6)
    nodes = np.clip(np.ceil(extent / max(finest, 1e-9)).astype(int) + 1, 2, MAX_NODES)
    cell = extent / (nodes - 1)
    out.origin = wp.vec3(*lo.tolist())
    out.cell = wp.vec3(*cell.tolist())
    shape = tuple(int(n) for n in nodes)
    out.up = device_buffers.reusable("slicing:sky_shadow_up", shape, wp.vec3, device)
    out.down = device_buffers.reusable("slicing:sky_shadow_down", shape, wp.vec3, device)
    launch_rows(column_depth_kernel(media_buffers.has_detail), shape[0], shape[2], [media_buffers.media, out],
                device)
    return out
