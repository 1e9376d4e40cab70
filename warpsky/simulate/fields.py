"""The solver's grid and its state on the device, as the typed structs its kernels take.

The grid is warpsky's world frame (+y up), cells indexed ``[x, y, z]`` like the NanoVDB grids the frames are
written as: ``nx`` by ``nz`` columns of ``ny`` levels. Scalars live at cell centres. The velocity is staggered on a
MAC grid (Harlow & Welch 1965): ``vel_x[i, j, k]`` on the face between cells i - 1 and i, ``vel_y[i, j, k]`` on the
face below cell j (``ny + 1`` of them; the floor's and the lid's stay 0), ``vel_z`` likewise along z. The staggering
makes the discrete divergence the exact adjoint of the gradient, so the projection leaves a divergence equal to
the linear solver's residual and no checkerboard mode. Lateral boundaries are periodic.

Sample positions inside kernels are in cell units: cell (i, j, k) spans [i, i + 1] x [j, j + 1] x [k, k + 1].
"""

from __future__ import annotations

import warp as wp


@wp.struct
class Grid:
    """The solver's regular grid."""

    nx: int  # cells along x
    ny: int  # levels (along +y, up)
    nz: int  # cells along z
    dx: float  # [m] horizontal spacing (x and z)
    dy: float  # [m] level spacing


@wp.struct
class Column:
    """The hydrostatic environment per level (``ny`` centres; the ``*_face`` arrays ``ny + 1`` faces)."""

    theta: wp.array(dtype=float)  # [K] potential temperature
    vapour: wp.array(dtype=float)  # [kg/kg] water-vapour mixing ratio
    exner: wp.array(dtype=float)  # (p / p0)^(R/cp)
    pressure: wp.array(dtype=float)  # [Pa]
    density: wp.array(dtype=float)  # [kg/m^3]
    density_face: wp.array(dtype=float)  # [kg/m^3] at the levels' boundaries
    wind_x: wp.array(dtype=float)  # [m/s] the environment's wind along +x
    wind_z: wp.array(dtype=float)  # [m/s] along +z
    damping: wp.array(dtype=float)  # [1/s] Rayleigh damping rate of the sponge at the centres
    damping_face: wp.array(dtype=float)  # [1/s] at the faces


@wp.struct
class Flow:
    """The MAC velocity [m/s]."""

    vel_x: wp.array3d(dtype=float)  # (nx, ny, nz), face i between cells i - 1 and i (periodic)
    vel_y: wp.array3d(dtype=float)  # (nx, ny + 1, nz), face j below cell j
    vel_z: wp.array3d(dtype=float)  # (nx, ny, nz), face k between cells k - 1 and k (periodic)


@wp.struct
class Water:
    """The thermodynamic state at the cell centres."""

    theta: wp.array3d(dtype=float)  # [K] potential temperature
    vapour: wp.array3d(dtype=float)  # [kg/kg] water-vapour mixing ratio
    cloud: wp.array3d(dtype=float)  # [kg/kg] cloud condensate (droplets, or ice above the freezing level)
    rain: wp.array3d(dtype=float)  # [kg/kg] precipitation falling at its terminal speed


@wp.func
def wrap(i: int, n: int) -> int:
    """``i`` taken periodically into [0, n), for i in [-n, 2n) (neighbours; cheaper than a modulo)."""
    if i < 0:
        return i + n
    if i >= n:
        return i - n
    return i


@wp.func
def wrap_coordinate(f: float, n: int) -> float:
    """Array-index coordinate ``f`` taken periodically into [0, n)."""
    size = float(n)
    g = f - size * wp.floor(f / size)
    if g >= size:  # rounding of a tiny negative f
        g = 0.0
    return g


@wp.func
def lerp3(a: wp.array3d(dtype=float), fx: float, fy: float, fz: float) -> float:
    """Trilinear value of ``a`` at array-index coordinates (fx, fy, fz): periodic along x and z, held at the first
    and last index along y."""
    n0 = a.shape[0]
    n1 = a.shape[1]
    n2 = a.shape[2]
    gy = wp.clamp(fy, 0.0, float(n1 - 1))
    gx = wrap_coordinate(fx, n0)
    gz = wrap_coordinate(fz, n2)
    x0 = wp.floor(gx)
    y0 = wp.floor(gy)
    z0 = wp.floor(gz)
    tx = gx - x0
    ty = gy - y0
    tz = gz - z0
    i0 = int(x0)
    i1 = wrap(i0 + 1, n0)
    j0 = int(y0)
    j1 = wp.min(j0 + 1, n1 - 1)
    k0 = int(z0)
    k1 = wrap(k0 + 1, n2)
    c00 = wp.lerp(a[i0, j0, k0], a[i1, j0, k0], tx)
    c10 = wp.lerp(a[i0, j1, k0], a[i1, j1, k0], tx)
    c01 = wp.lerp(a[i0, j0, k1], a[i1, j0, k1], tx)
    c11 = wp.lerp(a[i0, j1, k1], a[i1, j1, k1], tx)
    return wp.lerp(wp.lerp(c00, c10, ty), wp.lerp(c01, c11, ty), tz)


@wp.func
def velocity_at(flow: Flow, p: wp.vec3) -> wp.vec3:
    """The MAC velocity [m/s] at ``p`` [cells]."""
    return wp.vec3(lerp3(flow.vel_x, p[0], p[1] - 0.5, p[2] - 0.5),
                   lerp3(flow.vel_y, p[0] - 0.5, p[1], p[2] - 0.5),
                   lerp3(flow.vel_z, p[0] - 0.5, p[1] - 0.5, p[2]))


@wp.func
def cell_velocity(flow: Flow, grid: Grid, i: int, j: int, k: int) -> wp.vec3:
    """The velocity [m/s] at the centre of cell (i, j, k), its faces averaged (i, k taken periodically)."""
    a = wrap(i, grid.nx)
    b = wp.clamp(j, 0, grid.ny - 1)
    c = wrap(k, grid.nz)
    return wp.vec3(0.5 * (flow.vel_x[a, b, c] + flow.vel_x[wrap(a + 1, grid.nx), b, c]),
                   0.5 * (flow.vel_y[a, b, c] + flow.vel_y[a, b + 1, c]),
                   0.5 * (flow.vel_z[a, b, c] + flow.vel_z[a, b, wrap(c + 1, grid.nz)]))
