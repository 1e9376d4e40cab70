"""The solver's flow kernels: semi-Lagrangian advection, buoyancy with condensate loading, vorticity confinement
and the sponge.

Advection is semi-Lagrangian (Staniforth & Côté 1991; Stam 1999): each sample traces back along the velocity over
the step (midpoint rule; the first stage's velocity is the face's own, its other components means of four faces)
and takes the trilinear value there, stable at any Courant number. Buoyancy is the
anelastic one of Ogura & Phillips (1962) with the condensate's weight: B = g (θ'/θ0 + 0.608 q_v' - q_c - q_r).
Vorticity confinement (Steinhoff & Underhill 1994; Fedkiw et al. 2001; used for clouds by Harris et al. 2003)
gives back the small eddies the interpolation smooths: f = ε h (N x ω), N = ∇|ω| / |∇|ω||, ε [1/s]. The sponge
relaxes the flow to the environment's wind and θ to the environment's at its Rayleigh rate (Klemp & Lilly 1978).
"""

from __future__ import annotations

import warp as wp

from warpsky.simulate.fields import Column, Flow, Grid, Water, cell_velocity, lerp3, velocity_at, wrap

GRAVITY = 9.81  # [m/s^2]


@wp.func
def departure(flow: Flow, grid: Grid, p: wp.vec3, start: wp.vec3, dt: float) -> wp.vec3:
    """Where the air at ``p`` [cells], moving at ``start`` [m/s] there, was ``dt`` [s] ago (midpoint rule) [cells]."""
    to_cells = wp.vec3(1.0 / grid.dx, 1.0 / grid.dy, 1.0 / grid.dx)
    half = p - 0.5 * dt * wp.cw_mul(start, to_cells)
    return p - dt * wp.cw_mul(velocity_at(flow, half), to_cells)


@wp.func
def x_face_velocity(flow: Flow, grid: Grid, i: int, j: int, k: int) -> wp.vec3:
    """The velocity [m/s] on x-face (i, j, k): its own component and the four-face means of the others (the
    trilinear values there, without the general lookup)."""
    a = wrap(i - 1, grid.nx)
    c = wrap(k + 1, grid.nz)
    v = 0.25 * (flow.vel_y[a, j, k] + flow.vel_y[i, j, k] + flow.vel_y[a, j + 1, k] + flow.vel_y[i, j + 1, k])
    w = 0.25 * (flow.vel_z[a, j, k] + flow.vel_z[i, j, k] + flow.vel_z[a, j, c] + flow.vel_z[i, j, c])
    return wp.vec3(flow.vel_x[i, j, k], v, w)


@wp.func
def y_face_velocity(flow: Flow, grid: Grid, i: int, j: int, k: int) -> wp.vec3:
    """The velocity [m/s] on y-face (i, j, k), 0 < j < ny (as :func:`x_face_velocity`)."""
    a = wrap(i + 1, grid.nx)
    c = wrap(k + 1, grid.nz)
    u = 0.25 * (flow.vel_x[i, j - 1, k] + flow.vel_x[a, j - 1, k] + flow.vel_x[i, j, k] + flow.vel_x[a, j, k])
    w = 0.25 * (flow.vel_z[i, j - 1, k] + flow.vel_z[i, j - 1, c] + flow.vel_z[i, j, k] + flow.vel_z[i, j, c])
    return wp.vec3(u, flow.vel_y[i, j, k], w)


@wp.func
def z_face_velocity(flow: Flow, grid: Grid, i: int, j: int, k: int) -> wp.vec3:
    """The velocity [m/s] on z-face (i, j, k) (as :func:`x_face_velocity`)."""
    a = wrap(i + 1, grid.nx)
    c = wrap(k - 1, grid.nz)
    u = 0.25 * (flow.vel_x[i, j, c] + flow.vel_x[a, j, c] + flow.vel_x[i, j, k] + flow.vel_x[a, j, k])
    v = 0.25 * (flow.vel_y[i, j, c] + flow.vel_y[i, j, k] + flow.vel_y[i, j + 1, c] + flow.vel_y[i, j + 1, k])
    return wp.vec3(u, v, flow.vel_z[i, j, k])


@wp.kernel
def advect(grid: Grid, flow: Flow, target: Flow, dt: float, x_offset: int):
    """``target`` = ``flow`` carried by itself over ``dt`` [s], all three components in one launch over
    (nx, ny + 1, nz); the floor's and the lid's vertical samples are kept."""
    t, j, k = wp.tid()
    i = t + x_offset
    p = wp.vec3(float(i), float(j) + 0.5, float(k) + 0.5)
    if j < grid.ny:
        q = departure(flow, grid, p, x_face_velocity(flow, grid, i, j, k), dt)
        target.vel_x[i, j, k] = lerp3(flow.vel_x, q[0], q[1] - 0.5, q[2] - 0.5)
        p = wp.vec3(float(i) + 0.5, float(j) + 0.5, float(k))
        q = departure(flow, grid, p, z_face_velocity(flow, grid, i, j, k), dt)
        target.vel_z[i, j, k] = lerp3(flow.vel_z, q[0] - 0.5, q[1] - 0.5, q[2])
    if j == 0 or j == grid.ny:
        target.vel_y[i, j, k] = flow.vel_y[i, j, k]
        return
    p = wp.vec3(float(i) + 0.5, float(j), float(k) + 0.5)
    q = departure(flow, grid, p, y_face_velocity(flow, grid, i, j, k), dt)
    target.vel_y[i, j, k] = lerp3(flow.vel_y, q[0] - 0.5, q[1], q[2] - 0.5)


@wp.kernel
def vorticity(grid: Grid, flow: Flow, curl: wp.array3d(dtype=wp.vec3), x_offset: int):
    """The vorticity ω = ∇ x u [1/s] at the cell centres (central differences of the centred velocity)."""
    t, j, k = wp.tid()
    i = t + x_offset
    dxp = cell_velocity(flow, grid, i + 1, j, k)
    dxm = cell_velocity(flow, grid, i - 1, j, k)
    dyp = cell_velocity(flow, grid, i, j + 1, k)
    dym = cell_velocity(flow, grid, i, j - 1, k)
    dzp = cell_velocity(flow, grid, i, j, k + 1)
    dzm = cell_velocity(flow, grid, i, j, k - 1)
    hx = 0.5 / grid.dx
    hy = 1.0 / (grid.dy * float(wp.min(j + 1, grid.ny - 1) - wp.max(j - 1, 0)))
    curl[i, j, k] = wp.vec3((dyp[2] - dym[2]) * hy - (dzp[1] - dzm[1]) * hx,
                            (dzp[0] - dzm[0]) * hx - (dxp[2] - dxm[2]) * hx,
                            (dxp[1] - dxm[1]) * hx - (dyp[0] - dym[0]) * hy)


@wp.func
def curl_size(curl: wp.array3d(dtype=wp.vec3), grid: Grid, i: int, j: int, k: int) -> float:
    return wp.length(curl[wrap(i, grid.nx), wp.clamp(j, 0, grid.ny - 1), wrap(k, grid.nz)])


@wp.kernel
def confinement(grid: Grid, curl: wp.array3d(dtype=wp.vec3), strength: float, force: wp.array3d(dtype=wp.vec3),
                x_offset: int):
    """The confinement force ε h (N x ω) [m/s^2] at the cell centres, h the horizontal spacing."""
    t, j, k = wp.tid()
    i = t + x_offset
    gradient = wp.vec3((curl_size(curl, grid, i + 1, j, k) - curl_size(curl, grid, i - 1, j, k)) / grid.dx,
                       (curl_size(curl, grid, i, j + 1, k) - curl_size(curl, grid, i, j - 1, k)) / grid.dy,
                       (curl_size(curl, grid, i, j, k + 1) - curl_size(curl, grid, i, j, k - 1)) / grid.dx)
    size = wp.length(gradient)
    if size <= 1.0e-20:
        force[i, j, k] = wp.vec3(0.0)
        return
    force[i, j, k] = strength * grid.dx * wp.cross(gradient / size, curl[i, j, k])


@wp.func
def buoyancy(column: Column, water: Water, i: int, j: int, k: int) -> float:
    """B [m/s^2] of cell (i, j, k) against the environment, with the condensate's weight."""
    return GRAVITY * ((water.theta[i, j, k] - column.theta[j]) / column.theta[j]
                      + 0.608 * (water.vapour[i, j, k] - column.vapour[j])
                      - water.cloud[i, j, k] - water.rain[i, j, k])


@wp.kernel
def apply_forces(grid: Grid, column: Column, water: Water, force: wp.array3d(dtype=wp.vec3), flow: Flow,
                 dt: float, x_offset: int):
    """Add buoyancy and the confinement force over ``dt`` [s] to the face velocities, then damp them towards the
    environment's wind in the sponge (implicitly, stable at any rate). Launched over (nx, ny + 1, nz)."""
    t, j, k = wp.tid()
    i = t + x_offset
    if j < grid.ny:
        rate = dt * column.damping[j]
        fx = 0.5 * (force[wrap(i - 1, grid.nx), j, k][0] + force[i, j, k][0])
        fz = 0.5 * (force[i, j, wrap(k - 1, grid.nz)][2] + force[i, j, k][2])
        flow.vel_x[i, j, k] = (flow.vel_x[i, j, k] + dt * fx + rate * column.wind_x[j]) / (1.0 + rate)
        flow.vel_z[i, j, k] = (flow.vel_z[i, j, k] + dt * fz + rate * column.wind_z[j]) / (1.0 + rate)
    if j > 0 and j < grid.ny:
        lift = 0.5 * (buoyancy(column, water, i, j - 1, k) + buoyancy(column, water, i, j, k))
        fy = 0.5 * (force[i, j - 1, k][1] + force[i, j, k][1])
        flow.vel_y[i, j, k] = (flow.vel_y[i, j, k] + dt * (lift + fy)) / (1.0 + dt * column.damping_face[j])


@wp.kernel
def damp_theta(column: Column, water: Water, dt: float, x_offset: int):
    """Relax θ towards the environment's in the sponge (implicitly)."""
    t, j, k = wp.tid()
    i = t + x_offset
    rate = dt * column.damping[j]
    water.theta[i, j, k] = (water.theta[i, j, k] + rate * column.theta[j]) / (1.0 + rate)
