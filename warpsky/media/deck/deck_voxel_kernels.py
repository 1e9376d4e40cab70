"""The deck's partial-volume voxel densities (:func:`~warpsky.media.deck.deck_voxels.cloud_fractions`) as a Warp
kernel: one thread per voxel column, in float64 (the pattern's waves are evaluated about the grid's centre, where the
host's float64 formulas are the reference to 1e-12).

Each of the column's s x s sub-columns holds the cloud between its base h and top g (none where f <= 0); the
column's voxel k gets clamp(min(g, e_k+1) - max(h, e_k), 0, Δy) / Δy averaged over the sub-columns, e_k the row
edges above the mean plane.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class DeckColumns:
    """The pattern about the grid's centre and where the grid's columns and rows lie (float64)."""

    poly: wp.array(dtype=wp.float64)  # c0, cx, cz, cxx, cxz, czz about the centre
    waves: wp.array(dtype=wp.float64)  # per wave: kx, kz [rad/m], amplitude [m], phase at the centre and time [rad]
    wave_count: int
    cap: wp.float64  # f is clamped to at most this [m]
    rounding: wp.float64  # c [m]
    bottom_depth: wp.float64  # D [m]
    x0: wp.float64  # first sub-column's x relative to the centre [m]
    z0: wp.float64
    sub_step: wp.float64  # distance between sub-columns [m] (a column's width over s)
    supersample: int  # s
    floor: wp.float64  # the grid's floor above the mean plane [m]
    row: wp.float64  # Δy [m]
    rows: int


@wp.func
def column_pattern(c: DeckColumns, x: wp.float64, z: wp.float64) -> wp.float64:
    """f [m] at (x, z) relative to the centre, clamped to the cap."""
    f = c.poly[0] + c.poly[1] * x + c.poly[2] * z + c.poly[3] * x * x + c.poly[4] * x * z + c.poly[5] * z * z
    for i in range(c.wave_count):
        f += c.waves[4 * i + 2] * wp.sin(c.waves[4 * i] * x + c.waves[4 * i + 1] * z + c.waves[4 * i + 3])
    return wp.min(f, c.cap)


@wp.kernel
def deck_fractions_kernel(c: DeckColumns, out: wp.array3d(dtype=float), row_offset: int):
    r, iz = wp.tid()
    ix = r + row_offset
    s = c.supersample
    weight = wp.float64(1.0) / (wp.float64(s * s) * c.row)
    two = wp.float64(2.0)
    for a in range(s):
        for b in range(s):
            x = c.x0 + wp.float64(ix * s + a) * c.sub_step
            z = c.z0 + wp.float64(iz * s + b) * c.sub_step
            f = column_pattern(c, x, z)
            if f > wp.float64(0.0):
                g = wp.sqrt(f) * wp.sqrt(f + two * c.rounding)
                h = -c.bottom_depth * g / wp.sqrt((f + c.rounding) * (f + c.rounding) + c.rounding * c.rounding)
                first = wp.max(int(wp.floor((h - c.floor) / c.row)), 0)
                last = wp.min(int(wp.floor((g - c.floor) / c.row)), c.rows - 1)
                for k in range(first, last + 1):
                    lo = c.floor + wp.float64(k) * c.row
                    cover = wp.min(g, lo + c.row) - wp.max(h, lo)
                    if cover > wp.float64(0.0):
                        out[ix, k, iz] = out[ix, k, iz] + float(wp.min(cover, c.row) * weight)


def deck_columns(clouds, grid, time_s: float, supersample: int, device) -> DeckColumns:
    """The kernel's view of ``clouds`` at ``time_s`` [s] over ``grid`` (a
    :class:`~warpsky.media.stratiform.stratiform_voxels.ColumnGrid`), the pattern re-expanded about its centre."""
    from warpsky.media.deck.deck_geometry import eye_polynomial, wave_table

    nx, ny, nz = grid.shape
    s = int(supersample)
    centre = np.array([grid.origin[0] + 0.5 * nx * grid.width[0], grid.origin[1] + 0.5 * nz * grid.width[1]])
    c = DeckColumns()
    c.poly = wp.array(eye_polynomial(clouds, centre).astype(np.float64), dtype=wp.float64, device=device)
    c.waves = wp.array(wave_table(clouds, centre, time_s).reshape(-1), dtype=wp.float64, device=device)
    c.wave_count = int(len(clouds.wave_vectors))
    c.cap = wp.float64(min(clouds.pattern_cap, 1.0e300))
    c.rounding = wp.float64(clouds.rounding)
    c.bottom_depth = wp.float64(clouds.bottom_depth)
    c.sub_step = wp.float64(grid.width[0] / s)
    c.x0 = wp.float64(-0.5 * nx * grid.width[0] + 0.5 * grid.width[0] / s)
    c.z0 = wp.float64(-0.5 * nz * grid.width[1] + 0.5 * grid.width[1] / s)
    c.supersample = s
    c.floor = wp.float64(grid.floor - clouds.mean_altitude)
    c.row = wp.float64(grid.height)
    c.rows = int(ny)
    return c
