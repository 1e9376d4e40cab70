"""Conservative transport of the scalars (θ, q_v, q_c, q_r): finite-volume fluxes of ρ0 u q through the MAC faces.

Semi-Lagrangian interpolation (used for the velocity) does not conserve what it carries: trilinear values of a
convex profile (the vapour falling off with height) come out high, and a deep storm gained 1.1 % of its water in
36 minutes that way (measured on a 24 x 32 x 24 grid). Here each face's flux is ρ0 u q_face with q_face the
upwind cell's value plus half its minmod-limited slope times (1 - |Courant number|) (van Leer 1977's MUSCL with
the Lax-Wendroff correction, one unsplit stage), so what leaves one cell enters its neighbour and the total is
kept to rounding; a constant field stays constant because the projected flow has ∇·(ρ0 u) = 0. The step is split
into sub-steps whose summed Courant numbers stay below :data:`MAX_COURANT`.
"""

from __future__ import annotations

import warp as wp

from warpsky.simulate.fields import Column, Flow, Grid, Water, wrap

#: Largest sum of the three Courant numbers of a transport sub-step.
MAX_COURANT = 0.8


@wp.func
def minmod(a: float, b: float) -> float:
    if a * b <= 0.0:
        return 0.0
    if wp.abs(a) < wp.abs(b):
        return a
    return b


@wp.func
def face_value(q_m2: float, q_m1: float, q_0: float, q_p1: float, courant: float) -> float:
    """The value carried through the face between cells m1 and 0 at ``courant`` (u dt / h, signed)."""
    if courant >= 0.0:
        return q_m1 + 0.5 * (1.0 - courant) * minmod(q_m1 - q_m2, q_0 - q_m1)
    return q_0 - 0.5 * (1.0 + courant) * minmod(q_0 - q_m1, q_p1 - q_0)


@wp.func
def x_flux(grid: Grid, q: wp.array3d(dtype=float), u: float, i: int, j: int, k: int, dt: float) -> float:
    """u q through the face between cells i - 1 and i [(m/s) x q]."""
    n = grid.nx
    value = face_value(q[wrap(i - 2, n), j, k], q[wrap(i - 1, n), j, k], q[wrap(i, n), j, k],
                       q[wrap(i + 1, n), j, k], u * dt / grid.dx)
    return u * value


@wp.func
def z_flux(grid: Grid, q: wp.array3d(dtype=float), w: float, i: int, j: int, k: int, dt: float) -> float:
    n = grid.nz
    value = face_value(q[i, j, wrap(k - 2, n)], q[i, j, wrap(k - 1, n)], q[i, j, wrap(k, n)],
                       q[i, j, wrap(k + 1, n)], w * dt / grid.dx)
    return w * value


@wp.func
def y_flux(grid: Grid, q: wp.array3d(dtype=float), v: float, i: int, j: int, k: int, dt: float) -> float:
    """v q through the face below level j (1 <= j < ny; the floor's and the lid's carry nothing)."""
    below = q[i, j - 1, k]
    here = q[i, j, k]
    courant = v * dt / grid.dy
    if courant >= 0.0:
        slope = float(0.0)
        if j >= 2:
            slope = minmod(below - q[i, j - 2, k], here - below)
        return v * (below + 0.5 * (1.0 - courant) * slope)
    slope = float(0.0)
    if j + 1 < grid.ny:
        slope = minmod(here - below, q[i, j + 1, k] - here)
    return v * (here - 0.5 * (1.0 + courant) * slope)


@wp.func
def carried(grid: Grid, column: Column, q: wp.array3d(dtype=float), i: int, j: int, k: int, faces: wp.vec3,
            far: wp.vec3, dt: float) -> float:
    """q of cell (i, j, k) after a conservative sub-step of ``dt`` [s] through its faces, whose velocities [m/s] are
    ``faces`` (the lower x, y and z faces) and ``far`` (the upper ones)."""
    ip = wrap(i + 1, grid.nx)
    kp = wrap(k + 1, grid.nz)
    horizontal = (x_flux(grid, q, far[0], ip, j, k, dt) - x_flux(grid, q, faces[0], i, j, k, dt)
                  + z_flux(grid, q, far[2], i, j, kp, dt) - z_flux(grid, q, faces[2], i, j, k, dt)) / grid.dx
    up = float(0.0)
    if j + 1 < grid.ny:
        up = column.density_face[j + 1] * y_flux(grid, q, far[1], i, j + 1, k, dt)
    down = float(0.0)
    if j > 0:
        down = column.density_face[j] * y_flux(grid, q, faces[1], i, j, k, dt)
    return q[i, j, k] - dt * (horizontal + (up - down) / (column.density[j] * grid.dy))


@wp.kernel
def transport(grid: Grid, column: Column, flow: Flow, source: Water, target: Water, dt: float, x_offset: int):
    """``target`` = ``source`` (θ, q_v, q_c and q_r) after a conservative sub-step of ``dt`` [s] (module
    docstring)."""
    t, j, k = wp.tid()
    i = t + x_offset
    faces = wp.vec3(flow.vel_x[i, j, k], flow.vel_y[i, j, k], flow.vel_z[i, j, k])
    far = wp.vec3(flow.vel_x[wrap(i + 1, grid.nx), j, k], flow.vel_y[i, j + 1, k],
                  flow.vel_z[i, j, wrap(k + 1, grid.nz)])
    target.theta[i, j, k] = carried(grid, column, source.theta, i, j, k, faces, far, dt)
    target.vapour[i, j, k] = carried(grid, column, source.vapour, i, j, k, faces, far, dt)
    target.cloud[i, j, k] = carried(grid, column, source.cloud, i, j, k, faces, far, dt)
    target.rain[i, j, k] = carried(grid, column, source.rain, i, j, k, faces, far, dt)


@wp.kernel
def column_courant(grid: Grid, flow: Flow, dt: float, partial: wp.array2d(dtype=float), x_offset: int):
    """The largest summed Courant number of each column over ``dt`` [s]."""
    t, k = wp.tid()
    i = t + x_offset
    largest = float(0.0)
    for j in range(grid.ny):
        cx = wp.max(wp.abs(flow.vel_x[i, j, k]), wp.abs(flow.vel_x[wrap(i + 1, grid.nx), j, k])) / grid.dx
        cz = wp.max(wp.abs(flow.vel_z[i, j, k]), wp.abs(flow.vel_z[i, j, wrap(k + 1, grid.nz)])) / grid.dx
        cy = wp.max(wp.abs(flow.vel_y[i, j, k]), wp.abs(flow.vel_y[i, j + 1, k])) / grid.dy
        largest = wp.max(largest, dt * (cx + cy + cz))
    partial[i, k] = largest


@wp.kernel
def largest_value(partial: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    """out[0] = the largest entry of ``partial`` (one thread; fixed order)."""
    largest = float(0.0)
    for i in range(partial.shape[0]):
        for k in range(partial.shape[1]):
            largest = wp.max(largest, partial[i, k])
    out[0] = largest
