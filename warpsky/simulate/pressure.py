"""The pressure projection: the anelastic constraint ∇·(ρ0 u) = 0 (Ogura & Phillips 1962) enforced each step.

u ← u* - ∇φ with ∇·(ρ0 ∇φ) = ∇·(ρ0 u*): a symmetric, positive semi-definite system (the constant is its null
space; the right-hand side sums to zero on the periodic, walled domain) solved by Warp's preconditioned conjugate
gradients on a matrix-free operator, warm-started from the last step's φ. The
preconditioner solves each column's vertical tridiagonal system exactly (line Jacobi; the levels are closer than
the columns, so the vertical couplings dominate). On the MAC grid the divergence left after the update equals the
solver's residual, so the projection's accuracy is the solver's tolerance.

The conjugate gradients are written here rather than taken from ``warp.optim.linear.cg``: on the CPU, that
solver's reductions took 28 ms each on 8,192 cells (1.3 s of a 1.4 s step, measured with cProfile), where these
column-then-row sums take a fraction of a millisecond; they also add in a fixed order, so a run repeats bit for
bit on any device. The scalars α and β stay on the device; the host reads the residual every iteration on the CPU
(every few on a GPU). An iteration is two passes over the columns: A p with its sums of p·A p, then the update of
φ and r with the preconditioner and the sums of r·z and r·r.

The system is scaled by dx^2 so that its entries are densities [kg/m^3] and ratios of spacings.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core.device import is_cpu
from warpsky.simulate.fields import Column, Flow, Grid, wrap
from warpsky.simulate.launch import launch_slabs

#: Slots of the solver's device scalars.
RZ, PAP, RZ_NEW, RR, BB = 0, 1, 2, 3, 4


@wp.func
def flat(grid: Grid, i: int, j: int, k: int) -> int:
    return (wrap(i, grid.nx) * grid.ny + j) * grid.nz + wrap(k, grid.nz)


@wp.kernel
def divergence(grid: Grid, column: Column, flow: Flow, out: wp.array(dtype=float), scale: float, x_offset: int):
    """``out`` = ``scale`` ∇·(ρ0 u) at every cell [kg/(m^3 s)] (flattened [x, y, z])."""
    t, j, k = wp.tid()
    i = t + x_offset
    rho = column.density[j]
    flux = rho * (flow.vel_x[wrap(i + 1, grid.nx), j, k] - flow.vel_x[i, j, k]) / grid.dx
    flux += rho * (flow.vel_z[i, j, wrap(k + 1, grid.nz)] - flow.vel_z[i, j, k]) / grid.dx
    flux += (column.density_face[j + 1] * flow.vel_y[i, j + 1, k]
             - column.density_face[j] * flow.vel_y[i, j, k]) / grid.dy
    out[flat(grid, i, j, k)] = scale * flux


@wp.func
def operator_row(grid: Grid, column: Column, x: wp.array(dtype=float), i: int, j: int, k: int) -> float:
    """(A x) at cell (i, j, k), A = -dx^2 ∇·(ρ0 ∇) with no flux through the floor and the lid."""
    c = flat(grid, i, j, k)
    xc = x[c]
    ratio = (grid.dx / grid.dy) * (grid.dx / grid.dy)
    ax = column.density[j] * (4.0 * xc - x[flat(grid, i + 1, j, k)] - x[flat(grid, i - 1, j, k)]
                              - x[flat(grid, i, j, k + 1)] - x[flat(grid, i, j, k - 1)])
    if j + 1 < grid.ny:
        ax += ratio * column.density_face[j + 1] * (xc - x[flat(grid, i, j + 1, k)])
    if j > 0:
        ax += ratio * column.density_face[j] * (xc - x[flat(grid, i, j - 1, k)])
    return ax


@wp.kernel
def apply_operator(grid: Grid, column: Column, x: wp.array(dtype=float), y: wp.array(dtype=float),
                   z: wp.array(dtype=float), alpha: float, beta: float, x_offset: int):
    """z = alpha A x + beta y (:func:`operator_row`)."""
    t, j, k = wp.tid()
    i = t + x_offset
    c = flat(grid, i, j, k)
    z[c] = alpha * operator_row(grid, column, x, i, j, k) + beta * y[c]


@wp.kernel
def apply_dot(grid: Grid, column: Column, p: wp.array(dtype=float), ap: wp.array(dtype=float),
              partial: wp.array2d(dtype=float), x_offset: int):
    """ap = A p and partial[i, k] = Σ_j p (A p) over column (i, k): the operator and the first sum of p·A p in one
    pass. Launched over (nx, nz)."""
    t, k = wp.tid()
    i = t + x_offset
    total = float(0.0)
    for j in range(grid.ny):
        c = flat(grid, i, j, k)
        value = operator_row(grid, column, p, i, j, k)
        ap[c] = value
        total += p[c] * value
    partial[i, k] = total


@wp.kernel
def column_solve(grid: Grid, lower: wp.array(dtype=float), inverse_pivot: wp.array(dtype=float),
                 upper: wp.array(dtype=float), x: wp.array(dtype=float), y: wp.array(dtype=float),
                 z: wp.array(dtype=float), scratch: wp.array(dtype=float), alpha: float, beta: float,
                 x_offset: int):
    """z = alpha T^-1 x + beta y, T the operator's couplings within each column (its LU factors per level,
    :func:`column_factors`). Launched over (nx, nz)."""
    t, k = wp.tid()
    i = t + x_offset
    previous = float(0.0)
    for j in range(grid.ny):
        c = flat(grid, i, j, k)
        previous = (x[c] - lower[j] * previous) * inverse_pivot[j]
        scratch[c] = previous
    following = float(0.0)
    for jj in range(grid.ny):
        j = grid.ny - 1 - jj
        c = flat(grid, i, j, k)
        following = scratch[c] - upper[j] * following
        z[c] = alpha * following + beta * y[c]


@wp.kernel
def update_precondition(grid: Grid, lower: wp.array(dtype=float), inverse_pivot: wp.array(dtype=float),
                        upper: wp.array(dtype=float), scalars: wp.array(dtype=float), p: wp.array(dtype=float),
                        ap: wp.array(dtype=float), x: wp.array(dtype=float), r: wp.array(dtype=float),
                        z: wp.array(dtype=float), scratch: wp.array(dtype=float), partial_rz: wp.array2d(dtype=float),
                        partial_rr: wp.array2d(dtype=float), x_offset: int):
    """One conjugate-gradient update of column (i, k) in one pass: x += α p and r -= α A p (α = (r·z) / (p·A p)),
    z = T^-1 r (as :func:`column_solve`), and the column's sums of r z and r r. Launched over (nx, nz)."""
    t, k = wp.tid()
    i = t + x_offset
    alpha = float(0.0)
    if scalars[PAP] != 0.0:
        alpha = scalars[RZ] / scalars[PAP]
    rr = float(0.0)
    previous = float(0.0)
    for j in range(grid.ny):
        c = flat(grid, i, j, k)
        x[c] = x[c] + alpha * p[c]
        rc = r[c] - alpha * ap[c]
        r[c] = rc
        rr += rc * rc
        previous = (rc - lower[j] * previous) * inverse_pivot[j]
        scratch[c] = previous
    rz = float(0.0)
    following = float(0.0)
    for jj in range(grid.ny):
        j = grid.ny - 1 - jj
        c = flat(grid, i, j, k)
        following = scratch[c] - upper[j] * following
        z[c] = following
        rz += r[c] * following
    partial_rz[i, k] = rz
    partial_rr[i, k] = rr


@wp.kernel
def subtract_gradient(grid: Grid, phi: wp.array(dtype=float), flow: Flow, x_offset: int):
    """u -= ∇φ on every face but the floor's and the lid's. Launched over (nx, ny + 1, nz)."""
    t, j, k = wp.tid()
    i = t + x_offset
    if j < grid.ny:
        here = phi[flat(grid, i, j, k)]
        flow.vel_x[i, j, k] -= (here - phi[flat(grid, i - 1, j, k)]) / grid.dx
        flow.vel_z[i, j, k] -= (here - phi[flat(grid, i, j, k - 1)]) / grid.dx
    if j > 0 and j < grid.ny:
        flow.vel_y[i, j, k] -= (phi[flat(grid, i, j, k)] - phi[flat(grid, i, j - 1, k)]) / grid.dy


def column_factors(density: np.ndarray, density_face: np.ndarray, ratio: float) -> tuple[np.ndarray, ...]:
    """(sub-diagonal, 1 / pivot, super-diagonal over pivot) per level of the tridiagonal column part T of the
    operator: diagonal 4 ρ_j + ratio (ρ_{j+½} + ρ_{j-½}) (walls: no term), off-diagonals -ratio ρ_{j±½}; Thomas'
    forward elimination, done once (every column shares it)."""
    levels = len(density)
    above = np.where(np.arange(levels) + 1 < levels, ratio * density_face[1:], 0.0)
    below = np.where(np.arange(levels) > 0, ratio * density_face[:-1], 0.0)
    diagonal = 4.0 * density + above + below
    lower, inverse_pivot, upper = -below, np.empty(levels), np.empty(levels)
    for j in range(levels):
        pivot = diagonal[j] - (lower[j] * upper[j - 1] if j > 0 else 0.0)
        inverse_pivot[j] = 1.0 / pivot
        upper[j] = -above[j] / pivot
    return lower, inverse_pivot, upper


@wp.kernel
def column_dot(grid: Grid, a: wp.array(dtype=float), b: wp.array(dtype=float), partial: wp.array2d(dtype=float),
               x_offset: int):
    """partial[i, k] = Σ_j a b over column (i, k) (the first of a dot product's fixed-order sums)."""
    t, k = wp.tid()
    i = t + x_offset
    total = float(0.0)
    for j in range(grid.ny):
        c = flat(grid, i, j, k)
        total += a[c] * b[c]
    partial[i, k] = total


@wp.kernel
def row_sum(partial: wp.array2d(dtype=float), rows: wp.array(dtype=float)):
    i = wp.tid()
    total = float(0.0)
    for k in range(partial.shape[1]):
        total += partial[i, k]
    rows[i] = total


@wp.kernel
def total_sum(rows: wp.array(dtype=float), scalars: wp.array(dtype=float), slot: int):
    total = float(0.0)
    for i in range(rows.shape[0]):
        total += rows[i]
    scalars[slot] = total


@wp.kernel
def residual_start(b: wp.array(dtype=float), ax: wp.array(dtype=float), r: wp.array(dtype=float)):
    c = wp.tid()
    r[c] = b[c] - ax[c]


@wp.kernel
def step_direction(scalars: wp.array(dtype=float), z: wp.array(dtype=float), p: wp.array(dtype=float)):
    """p = z + β p, β = (r·z)_new / (r·z)."""
    c = wp.tid()
    beta = float(0.0)
    if scalars[RZ] != 0.0:
        beta = scalars[RZ_NEW] / scalars[RZ]
    p[c] = z[c] + beta * p[c]


@wp.kernel
def keep_rz(scalars: wp.array(dtype=float)):
    scalars[RZ] = scalars[RZ_NEW]


class Projection:
    """The projection's buffers and solver, built once for a grid (``project`` each step).

    ``iterations`` and ``relative_residual`` (|r| / max(|b|, |b_1|), :meth:`solve`) describe the last solve.
    """

    def __init__(self, grid: Grid, column: Column, base, device, *, tolerance: float = 1.0e-4,
                 max_iterations: int = 300, check_every: int | None = None):
        self.grid, self.column, self.device = grid, column, device
        self.tolerance, self.max_iterations = tolerance, max_iterations
        # r·r comes with every iteration's sums; reading it waits for a GPU, not for the CPU
        self.check_every = check_every or (1 if is_cpu(device) else 4)
        self.cell_count = grid.nx * grid.ny * grid.nz
        n = self.cell_count
        self.rhs, self.phi, self.scratch, self.r, self.z, self.p, self.ap = (
            wp.zeros(n, dtype=float, device=device) for _ in range(7))
        self.partial, self.partial_rr = (wp.zeros((grid.nx, grid.nz), dtype=float, device=device) for _ in range(2))
        self.rows = wp.zeros(grid.nx, dtype=float, device=device)
        self.scalars = wp.zeros(5, dtype=float, device=device)
        ratio = (grid.dx / grid.dy) ** 2
        factors = column_factors(base.density, base.density_face, ratio)
        self.lower, self.inverse_pivot, self.upper = (wp.array(f.astype(np.float32), device=device) for f in factors)
        self.iterations = 0
        self.relative_residual = 0.0
        self.floor = float(grid.dx * np.mean(base.density) * np.sqrt(self.cell_count))

    def _apply(self, x, out):
        launch_slabs(apply_operator, (self.grid.nx, self.grid.ny, self.grid.nz),
                     [self.grid, self.column, x, x, out, 1.0, 0.0], self.device)

    def _precondition(self, x, out):
        launch_slabs(column_solve, (self.grid.nx, self.grid.nz),
                     [self.grid, self.lower, self.inverse_pivot, self.upper, x, x, out, self.scratch, 1.0, 0.0],
                     self.device)

    def _dot(self, a, b, slot: int) -> None:
        launch_slabs(column_dot, (self.grid.nx, self.grid.nz), [self.grid, a, b, self.partial], self.device)
        self._sum(self.partial, slot)

    def _sum(self, partial, slot: int) -> None:
        """scalars[slot] = the sum of ``partial``'s columns, rows then all (a fixed order)."""
        wp.launch(row_sum, dim=self.grid.nx, inputs=[partial, self.rows], device=self.device)
        wp.launch(total_sum, dim=1, inputs=[self.rows, self.scalars, slot], device=self.device)

    def _iterate(self) -> None:
        """One conjugate-gradient iteration: A p with p·A p, the update with the preconditioner and r·z, r·r, the
        new direction."""
        g, d, n = self.grid, self.device, self.cell_count
        launch_slabs(apply_dot, (g.nx, g.nz), [g, self.column, self.p, self.ap, self.partial], d)
        self._sum(self.partial, PAP)
        launch_slabs(update_precondition, (g.nx, g.nz),
                     [g, self.lower, self.inverse_pivot, self.upper, self.scalars, self.p, self.ap, self.phi, self.r,
                      self.z, self.scratch, self.partial, self.partial_rr], d)
        self._sum(self.partial, RZ_NEW)
        self._sum(self.partial_rr, RR)
        wp.launch(step_direction, dim=n, inputs=[self.scalars, self.z, self.p], device=d)
        wp.launch(keep_rz, dim=1, inputs=[self.scalars], device=d)

    def divergence(self, flow: Flow, out: wp.array, scale: float = 1.0) -> wp.array:
        """``scale`` ∇·(ρ0 u) of ``flow`` into ``out`` [kg/(m^3 s)]."""
        launch_slabs(divergence, (self.grid.nx, self.grid.ny, self.grid.nz),
                     [self.grid, self.column, flow, out, float(scale)], self.device)
        return out

    def solve(self) -> None:
        """Preconditioned conjugate gradients on A φ = b from the current φ, until |r| <= tolerance max(|b|, |b_1|),
        b_1 the right side of a divergence of 1 m/s per cell width in every cell (:attr:`floor`): a flow already
        divergence-free to rounding is not iterated into float32's noise."""
        n, d = self.cell_count, self.device
        self._dot(self.rhs, self.rhs, BB)
        self._apply(self.phi, self.ap)
        wp.launch(residual_start, dim=n, inputs=[self.rhs, self.ap, self.r], device=d)
        self._precondition(self.r, self.z)
        wp.copy(self.p, self.z)
        self._dot(self.r, self.z, RZ)
        self._dot(self.r, self.r, RR)
        self.iterations = 0
        while True:
            if self.iterations % self.check_every == 0 or self.iterations >= self.max_iterations:
                values = self.scalars.numpy()
                self.relative_residual = float(np.sqrt(values[RR] / max(values[BB], self.floor ** 2)))
                if self.relative_residual <= self.tolerance or self.iterations >= self.max_iterations:
                    return
            self._iterate()
            self.iterations += 1

    def project(self, flow: Flow) -> None:
        """Make ``flow`` satisfy ∇·(ρ0 u) = 0 to the solver's tolerance."""
        self.divergence(flow, self.rhs, -self.grid.dx * self.grid.dx)
        self.solve()
        launch_slabs(subtract_gradient, (self.grid.nx, self.grid.ny + 1, self.grid.nz), [self.grid, self.phi, flow],
                     self.device)
