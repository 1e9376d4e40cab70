"""Multiple-scattering tables in half-angle slicing on the device (Riley 2004 §4.2): every medium's Ams_n (n = 0..N)
and forward fractions F_n, looked up at fractional order, mixed over the media at a point by scattering weight
(Riley Eq. 6 applied per order), and oriented ice's first order."""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import linear_cell
from warpsky.media.phase_mixture import oriented_slice
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia
from warpsky.optics.kernels import GRID_SIZE, grid_node
from warpsky.optics.oriented_phase import OrientedPhases, oriented_value


@wp.struct
class AmsTables:
    """Ams_n per table (T tables, N+1 orders, 3 channels, GRID_SIZE angles), F_n (T, N+1, 3), and per medium its
    table and Riley's back-scatter term xi."""

    ams: wp.array(dtype=float)
    forward: wp.array(dtype=float)
    orders: int  # N + 1
    table_of: wp.array(dtype=int)  # table index of each medium
    xi_of: wp.array(dtype=float)  # xi of each medium [1/sr], added to its phase in the eye gather


@wp.func
def ams_value(tables: AmsTables, table: int, order: int, channel: int, theta: float) -> float:
    """Ams of order ``order`` [1/sr] of table ``table`` in one channel at scattering angle ``theta`` [rad]."""
    node = grid_node(theta)
    i = int(node[0])
    base = ((table * tables.orders + order) * 3 + channel) * GRID_SIZE + i
    return tables.ams[base] + (tables.ams[base + 1] - tables.ams[base]) * node[1]


@wp.func
def ams_at(tables: AmsTables, table: int, n: float, channel: int, theta: float) -> float:
    """Ams of fractional order n (linear between neighbouring orders; clamped to the last)."""
    lo, hi, f = linear_cell(n, tables.orders)
    return ams_value(tables, table, lo, channel, theta) * (1.0 - f) + ams_value(tables, table, hi, channel, theta) * f


@wp.func
def forward_at(tables: AmsTables, table: int, n: float, channel: int) -> float:
    """F of fractional order n in one channel of table ``table`` (linear between neighbouring orders; clamped to
    the last)."""
    lo, hi, f = linear_cell(n, tables.orders)
    a = tables.forward[(table * tables.orders + lo) * 3 + channel]
    b = tables.forward[(table * tables.orders + hi) * 3 + channel]
    return a * (1.0 - f) + b * f


@wp.func
def mixed_forward(point: MediaPoint, media: VoxelMedia, tables: AmsTables, order: float, channel: int) -> float:
    """alpha F_order of the media mixed at the point: sum of scattering_i F_i over the total extinction."""
    if point.extinction[channel] <= 0.0:
        return 0.0
    num = float(0.0)
    for m in range(media.count):
        value = point.density[m]
        if value > 0.0:
            num += media.grids[m].scattering[channel] * value * forward_at(tables, tables.table_of[m], order, channel)
    return num / point.extinction[channel]


@wp.func
def mixed_ams_scattering(point: MediaPoint, media: VoxelMedia, tables: AmsTables, order: wp.vec3,
                         theta: float) -> wp.vec3:
    """Sum over the media at the point of scattering_i (Ams_i of order ``order[c]`` at theta + xi_i) per channel c
    (Riley Eq. 6 applied per order, before dividing by the summed scattering)."""
    phase = wp.vec3(0.0)
    for m in range(media.count):
        value = point.density[m]
        if value > 0.0:
            s = media.grids[m].scattering * value
            for c in range(3):
                phase[c] = phase[c] + s[c] * (ams_at(tables, tables.table_of[m], order[c], c, theta)
                                              + tables.xi_of[m])
    return phase


@wp.func
def order_one_weight(tables: AmsTables, n: float) -> float:
    """The weight :func:`ams_at` gives Ams_1 at fractional order n."""
    x = wp.clamp(n, 0.0, float(tables.orders - 1))
    if x <= 1.0:
        return x
    return wp.max(2.0 - x, 0.0)


@wp.func
def oriented_ams_correction(point: MediaPoint, media: VoxelMedia, tables: AmsTables, phases: OrientedPhases,
                            order: wp.vec3, look: wp.vec3, theta: float) -> wp.vec3:
    """What oriented ice adds to :func:`mixed_ams_scattering`: light that has not scattered yet (order 1) meets
    the crystals with the sun's direction, so their share of Ams_1 becomes the frame's oriented slice seen along
    ``look``; higher orders keep the random-orientation Ams (the light has lost the sun's direction)."""
    out = wp.vec3(0.0)
    if phases.count == 0:
        return out
    for m in range(media.count):
        index = oriented_slice(point, phases, m)
        if index >= 0:
            s = media.grids[m].scattering * point.density[m]
            oriented = oriented_value(phases, index, look)
            for c in range(3):
                weight = order_one_weight(tables, order[c])
                out[c] = out[c] + s[c] * weight * (oriented[c] - ams_value(tables, tables.table_of[m], 1, c, theta))
    return out
