"""Phase tables on the device: lookup, inverse-CDF sampling and its density, and a medium's phase whatever its model.

Tables share the grid of :mod:`warpsky.optics.grid` (M nodes) and are stored flat, row ``(table * 3 + channel)``
of M values. Lookups interpolate linearly in theta, like the host-side integrals, so a normalised table integrates
to 1 in a kernel too. The scattering angle is taken with atan2 from the two directions: acos(dot) in float32 cannot
resolve angles below ~0.02 deg, where the rain diffraction peak lives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.numerics import cdf_search
from warpsky.optics.grid import angle_grid, cumulative, segment_table
from warpsky.optics.phase import phase_eval

_SEG = segment_table()
GRID_SIZE = wp.constant(len(angle_grid()))
SEG1_START = wp.constant(float(_SEG[1, 0]))
SEG2_START = wp.constant(float(_SEG[2, 0]))
SEG3_START = wp.constant(float(_SEG[3, 0]))
SEG0_STEP = wp.constant(float(_SEG[0, 1]))
SEG1_STEP = wp.constant(float(_SEG[1, 1]))
SEG2_STEP = wp.constant(float(_SEG[2, 1]))
SEG3_STEP = wp.constant(float(_SEG[3, 1]))
SEG1_INDEX = wp.constant(int(_SEG[1, 2]))
SEG2_INDEX = wp.constant(int(_SEG[2, 2]))
SEG3_INDEX = wp.constant(int(_SEG[3, 2]))
#: Phase-kind codes at or above this select a table: table index = kind - TABLE_KIND.
TABLE_KIND = wp.constant(3)


@wp.func
def scattering_angle(a: wp.vec3, b: wp.vec3) -> float:
    """Angle [rad] between unit vectors a and b, accurate near 0 and pi."""
    return wp.atan2(wp.length(wp.cross(a, b)), wp.dot(a, b))


@wp.func
def grid_node(theta: float) -> wp.vec2:
    """(index i of the grid interval holding theta, fraction within it) for theta in [0, pi]."""
    start = float(0.0)
    step = SEG0_STEP
    first = int(0)
    if theta >= SEG3_START:
        start = SEG3_START
        step = SEG3_STEP
        first = SEG3_INDEX
    elif theta >= SEG2_START:
        start = SEG2_START
        step = SEG2_STEP
        first = SEG2_INDEX
    elif theta >= SEG1_START:
        start = SEG1_START
        step = SEG1_STEP
        first = SEG1_INDEX
    u = wp.max((theta - start) / step, 0.0)
    i = wp.min(first + int(u), GRID_SIZE - 2)
    frac = wp.clamp(theta - (start + float(i - first) * step), 0.0, step) / step
    return wp.vec2(float(i), frac)


@wp.func
def grid_angle(i: int) -> float:
    """Angle [rad] of grid node i."""
    if i >= SEG3_INDEX:
        return SEG3_START + float(i - SEG3_INDEX) * SEG3_STEP
    if i >= SEG2_INDEX:
        return SEG2_START + float(i - SEG2_INDEX) * SEG2_STEP
    if i >= SEG1_INDEX:
        return SEG1_START + float(i - SEG1_INDEX) * SEG1_STEP
    return float(i) * SEG0_STEP


@wp.func
def table_value(values: wp.array(dtype=float), row: int, theta: float) -> float:
    """Table row ``row`` interpolated at theta [rad]."""
    node = grid_node(theta)
    i = int(node[0])
    base = row * GRID_SIZE + i
    return values[base] + (values[base + 1] - values[base]) * node[1]


@wp.func
def table_phase(values: wp.array(dtype=float), table: int, theta: float) -> wp.vec3:
    """RGB phase function [1/sr] of table ``table`` at scattering angle theta."""
    node = grid_node(theta)
    i = int(node[0])
    f = node[1]
    out = wp.vec3(0.0)
    for c in range(3):
        base = (table * 3 + c) * GRID_SIZE + i
        out[c] = values[base] + (values[base + 1] - values[base]) * f
    return out


@wp.func
def medium_phase(values: wp.array(dtype=float), kind: int, g: float, theta: float) -> wp.vec3:
    """RGB phase of a medium: analytic models (kind < TABLE_KIND) or table ``kind - TABLE_KIND``."""
    if kind >= TABLE_KIND:
        return table_phase(values, kind - TABLE_KIND, theta)
    return wp.vec3(phase_eval(kind, g, wp.cos(theta)))


@wp.func
def interval_density(mass: float, total: float, width: float, theta: float) -> float:
    """Density per steradian at ``theta`` [rad] of samples spread uniformly in theta over a grid interval ``width``
    [rad] wide that holds ``mass`` of the table's ``total``."""
    return mass / total / width / (2.0 * wp.pi * wp.max(wp.sin(theta), 1.0e-12))


@wp.func
def sample_table(cdf: wp.array(dtype=float), row: int, u: float) -> wp.vec2:
    """Sample a scattering angle from row ``row``'s cumulative table: (theta [rad], pdf per steradian).

    Within a grid interval the angle is linear in u, so the sampling density is the interval's mass spread
    uniformly in theta; the returned pdf is exactly that density (use it, not the table value, as the pdf).
    """
    base = row * GRID_SIZE
    total = cdf[base + GRID_SIZE - 1]
    target = u * total
    lo = cdf_search(cdf, base, GRID_SIZE - 1, target)
    c0 = cdf[base + lo]
    c1 = cdf[base + lo + 1]
    t0 = grid_angle(lo)
    t1 = grid_angle(lo + 1)
    mass = c1 - c0
    frac = float(0.5)
    if mass > 0.0:
        frac = wp.clamp((target - c0) / mass, 0.0, 1.0)
    theta = t0 + frac * (t1 - t0)
    return wp.vec2(theta, interval_density(mass, total, t1 - t0, theta))


@wp.func
def table_pdf(cdf: wp.array(dtype=float), row: int, theta: float) -> float:
    """Density per steradian with which :func:`sample_table` returns ``theta`` from row ``row``."""
    node = grid_node(theta)
    i = int(node[0])
    base = row * GRID_SIZE
    total = cdf[base + GRID_SIZE - 1]
    mass = cdf[base + i + 1] - cdf[base + i]
    return interval_density(mass, total, grid_angle(i + 1) - grid_angle(i), theta)


@dataclass
class DevicePhaseTables:
    """Flat phase and cumulative tables on one device (a one-value dummy when the scene has no species)."""

    values: wp.array
    cdf: wp.array
    count: int

    @classmethod
    def upload(cls, phase: np.ndarray | None, device) -> DevicePhaseTables:
        """``phase``: (S, 3, M) tables, or None."""
        if phase is None or len(phase) == 0:
            dummy = wp.zeros(1, dtype=float, device=device)
            return cls(dummy, dummy, 0)
        phase = np.asarray(phase, dtype=np.float64)
        return cls(
            wp.array(phase.reshape(-1).astype(np.float32), dtype=float, device=device),
            wp.array(cumulative(phase).reshape(-1).astype(np.float32), dtype=float, device=device),
            phase.shape[0],
        )


@wp.kernel
def lookup_kernel(values: wp.array(dtype=float), table: int, angles: wp.array(dtype=float),
                  out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = table_phase(values, table, angles[i])


@wp.kernel
def sample_kernel(cdf: wp.array(dtype=float), row: int, seed: int, out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    out[i] = sample_table(cdf, row, wp.randf(state))


def lookup(tables: DevicePhaseTables, table: int, angles: np.ndarray, device) -> np.ndarray:
    """Evaluate table ``table`` at ``angles`` [rad] on ``device`` (for tests and benchmarks)."""
    angles_wp = wp.array(np.asarray(angles, dtype=np.float32), dtype=float, device=device)
    out = wp.zeros(len(angles), dtype=wp.vec3, device=device)
    wp.launch(lookup_kernel, dim=len(angles), inputs=[tables.values, table, angles_wp, out], device=device)
    return out.numpy()


def sample(tables: DevicePhaseTables, row: int, count: int, seed: int, device) -> np.ndarray:
    """``count`` (theta, pdf) samples of table row ``row`` (= table * 3 + channel)."""
    out = wp.zeros(count, dtype=wp.vec2, device=device)
    wp.launch(sample_kernel, dim=count, inputs=[tables.cdf, row, seed, out], device=device)
    return out.numpy()


__all__ = ["DevicePhaseTables", "GRID_SIZE", "TABLE_KIND", "lookup", "medium_phase", "sample",
           "sample_table", "scattering_angle", "table_pdf", "table_phase", "table_value"]
