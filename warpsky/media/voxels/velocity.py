"""Velocity blur: a density grid moved along its velocity field to a time between two of its cached states.

A simulation cache stores the density at its frames and, beside it, the velocity it was moving with (Houdini's
``vel``, EmberGen's and Blender's ``velocity``). Within a frame's shutter the density at a time ``dt`` seconds after
the cached state is taken, as production volume renderers do, from one semi-Lagrangian step of the Eulerian
advection equation: rho(x, t + dt) = rho(x - s v(x) dt, t), with ``s`` the Volume's ``warpsky:velocityScale``. The
step is exact for a uniform velocity (a translating volume) and first order in ``dt`` otherwise; it moves the
density only, so a velocity that varies across the grid stretches and compresses the density as the flow does,
without the sub-voxel accuracy of a solver.

The moved density is a new dense grid, grown by the largest displacement (in voxels, capped at
:data:`MAX_PADDING`) on every side so that what leaves the cached box stays visible; each voxel of it reads the
velocity at its own centre (trilinear, and beyond the grid's outer voxel centres the value at its edge: a VDB grid's
dense copy has a voxel of background there, so the velocity is 0 outside the simulated region as production
renderers read it, while a dense ``.npy`` grid of a uniform flow stays uniform) and the density
at the point it came from (trilinear between voxel centres, clamped to the edge inside the medium's box and zero
outside it, as the medium itself is evaluated).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import warp as wp

from warpsky.core.numerics import TrilinearCell, trilinear_cell

#: Most voxels a grid grows by on each side for the displacement (a velocity that moves further is clipped there).
MAX_PADDING = 64


@wp.struct
class VelocityStep:
    """One semi-Lagrangian step: ``vel_from_dens`` maps a density index to a velocity index (both voxel centres
    at integers), ``displacement`` maps a velocity vector to the density-index displacement over the step
    (``s dt`` times the inverse of the density's index-to-space matrix), ``padding`` voxels added on each side."""

    vel_from_dens: wp.mat44
    displacement: wp.mat33
    padding: int


@wp.func
def trilinear_at(grid: wp.array3d(dtype=Any), c: TrilinearCell):
    """``grid`` (of floats or vectors) interpolated in the cell ``c``."""
    f = c.frac
    c00 = wp.lerp(grid[c.lo[0], c.lo[1], c.lo[2]], grid[c.hi[0], c.lo[1], c.lo[2]], f[0])
    c10 = wp.lerp(grid[c.lo[0], c.hi[1], c.lo[2]], grid[c.hi[0], c.hi[1], c.lo[2]], f[0])
    c01 = wp.lerp(grid[c.lo[0], c.lo[1], c.hi[2]], grid[c.hi[0], c.lo[1], c.hi[2]], f[0])
    c11 = wp.lerp(grid[c.lo[0], c.hi[1], c.hi[2]], grid[c.hi[0], c.hi[1], c.hi[2]], f[0])
    return wp.lerp(wp.lerp(c00, c10, f[1]), wp.lerp(c01, c11, f[1]), f[2])


@wp.func
def boxed_density(grid: wp.array3d(dtype=float), p: wp.vec3) -> float:
    """The medium's value at index position ``p``: trilinear, clamped to the edge inside [-0.5, n - 0.5], 0
    outside."""
    n = wp.vec3i(grid.shape[0], grid.shape[1], grid.shape[2])
    for a in range(3):
        if p[a] < -0.5 or p[a] > float(n[a]) - 0.5:
            return 0.0
    return trilinear_at(grid, trilinear_cell(p, n))


@wp.kernel
def advect_density(density: wp.array3d(dtype=float), velocity: wp.array3d(dtype=wp.vec3), step: VelocityStep,
                   out: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    p = wp.vec3(float(i - step.padding), float(j - step.padding), float(k - step.padding))
    q = wp.transform_point(step.vel_from_dens, p)  # clamped to the edge beyond the outer voxel centres
    v = trilinear_at(velocity, trilinear_cell(q, wp.vec3i(velocity.shape[0], velocity.shape[1], velocity.shape[2])))
    out[i, j, k] = boxed_density(density, p - step.displacement * v)


def advected_grid(density: np.ndarray, dens_from_index: np.ndarray, velocity: np.ndarray,
                  vel_from_index: np.ndarray, seconds: float, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """(density moved by ``velocity`` over ``seconds``, its index-to-space matrix): see the module docstring.

    ``dens_from_index`` and ``vel_from_index`` map each grid's indices to one space (the Volume's), in which the
    velocity's vectors are given per second (already times the velocity scale)."""
    linear = dens_from_index[:3, :3]
    to_index = np.linalg.inv(linear) * seconds
    speed = np.linalg.norm(velocity.reshape(-1, 3) @ to_index.T, axis=1)
    reach = float(speed.max()) if speed.size else 0.0
    padding = min(MAX_PADDING, int(math.ceil(reach)) + 1) if reach > 0.0 else 0
    shape = tuple(n + 2 * padding for n in density.shape)
    step = VelocityStep()
    step.vel_from_dens = wp.mat44(*(np.linalg.inv(vel_from_index) @ dens_from_index).astype(np.float32).ravel())
    step.displacement = wp.mat33(*to_index.astype(np.float32).ravel())
    step.padding = padding
    with wp.ScopedDevice(device):
        out = wp.zeros(shape, dtype=float)
        wp.launch(advect_density, dim=shape, inputs=[wp.array(np.ascontiguousarray(density, np.float32)),
                                                     wp.array(np.ascontiguousarray(velocity, np.float32),
                                                              dtype=wp.vec3), step, out])
        moved = out.numpy()
    grown = dens_from_index.copy()
    grown[:3, 3] = dens_from_index[:3, 3] - linear @ np.full(3, float(padding))
    return moved, grown
