"""Animated detail baked into a finer grid for one frame: the density with its detail factor, sampled at voxel
centres ``refinement`` times finer than the field's, so the path tracer's collisions read one trilinear value
instead of evaluating the advected noise (nine texture lookups) at every tentative collision, and its majorants
bound the detailed density itself instead of the coarse density times the detail's bound ``1 + 3 amplitude``.

The baked field is the detailed field resampled: trilinear between fine voxel centres instead of the coarse field's
trilinear value times the noise's. The refinement puts a fine voxel within one detail texel (``scale / 2``), at
most :data:`MAX_REFINEMENT` per axis; where the coarse density is zero the fine one is too. It is an approximation
of the procedural field, not that field: a technique uses it where the light it computes is smooth (the multiple
scattering of ``hybrid``), and the path tracer only when asked (``bake_detail``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import warp as wp

from warpsky.media.voxels.detail import MediumDetail, detail_value, medium_details
from warpsky.media.voxels.voxel import VoxelGrid, grid_value

#: Most fine voxels per coarse voxel edge.
MAX_REFINEMENT = 4


@wp.kernel
def bake_kernel(values: wp.array(dtype=float), grid: VoxelGrid, detail: MediumDetail, refinement: int,
                index_to_camera: wp.mat33, origin_from_camera: wp.vec3, out: wp.array3d(dtype=float)):
    """Fine voxel (i, j, k): the detailed field at its centre."""
    i, j, k = wp.tid()
    scale = 1.0 / float(refinement)
    shift = 0.5 * (scale - 1.0)
    c = wp.vec3(float(i) * scale + shift, float(j) * scale + shift, float(k) * scale + shift)
    value = grid_value(values, grid, c)
    if value > 0.0:
        p = index_to_camera * c + origin_from_camera  # camera-relative metres
        value = detail_value(detail, value, p)
    out[i, j, k] = value


def refinement(medium) -> int:
    """Fine voxels per coarse voxel edge for ``medium``: enough that one is at most a detail texel wide."""
    texel = 0.5 * float(medium.detail.scale)
    return max(1, min(MAX_REFINEMENT, math.ceil(float(np.max(medium.voxel_size)) / texel)))


def baked_bytes(media) -> int:
    """Bytes of the float32 grids :func:`baked_media` makes for ``media`` (those with active detail)."""
    return sum(4 * int(np.prod(m.shape)) * refinement(m) ** 3 for m in media if m.has_detail)


def fine_world_from_index(world_from_index: np.ndarray, r: int) -> np.ndarray:
    """The index-to-world map of a grid ``r`` times finer over the same box: fine index i sits at coarse index
    (i + 0.5) / r - 0.5."""
    scale = np.eye(4)
    scale[:3, :3] *= 1.0 / r
    scale[:3, 3] = 0.5 * (1.0 / r - 1.0)
    return np.asarray(world_from_index, dtype=np.float64) @ scale


def baked_media(media: tuple, time_s: float, camera_position, device) -> tuple:
    """``media`` with every medium's active detail baked into a finer grid at ``time_s`` [s] (see the module
    docstring); media without detail are returned as they are."""
    details = medium_details(tuple(media), time_s, camera_position, device)
    if details is None:
        return tuple(media)
    camera = np.asarray(camera_position, dtype=np.float64)
    out = []
    with wp.ScopedDevice(device):
        for medium, detail in zip(media, details, strict=True):
            if not medium.has_detail:
                out.append(medium)
                continue
            r = refinement(medium)
            values = wp.array(np.ascontiguousarray(medium.density, dtype=np.float32).reshape(-1), dtype=float)
            grid = VoxelGrid()
            grid.offset = 0
            grid.shape = wp.vec3i(*medium.shape)
            matrix = np.asarray(medium.world_from_index, dtype=np.float64)
            fine = wp.zeros(tuple(n * r for n in medium.shape), dtype=float)
            wp.launch(bake_kernel, dim=fine.shape, inputs=[
                values, grid, detail, r, wp.mat33(*matrix[:3, :3].reshape(-1).tolist()),
                wp.vec3(*(matrix[:3, 3] - camera).tolist()), fine])
            out.append(dataclasses.replace(medium, density=fine.numpy(),
                                           world_from_index=fine_world_from_index(matrix, r), detail=None))
    return tuple(out)
