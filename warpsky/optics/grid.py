"""The one angular grid every phase table lives on, and exact integrals over the sphere on it.

Scattering angle theta in [0, pi] (0 = forward). The grid is piecewise uniform, refined where phase functions of
cloud and rain change fastest:

=============== ========= ===================================================================
theta range     step      resolves
=============== ========= ===================================================================
0 - 0.5 deg     0.0025°   the diffraction peak of 1 mm rain drops (first zero ~0.02° at 550 nm)
0.5 - 5 deg     0.02°     the peak's wings and cloud droplets' forward peak (~2° wide)
5 - 170 deg     0.1°      halos, rainbows, fogbows (Riley used 0.18° everywhere)
170 - 180 deg   0.02°     the glory rings of cloud droplets
=============== ========= ===================================================================

Tables are piecewise linear in theta between nodes; :func:`sphere_weights` integrates exactly that
interpolant against sin(theta), so a table normalised with them integrates to 1 in the kernels too.
"""

from __future__ import annotations

import functools

import numpy as np

#: (start, stop, step) in degrees of the grid's uniform segments.
SEGMENTS_DEG = ((0.0, 0.5, 0.0025), (0.5, 5.0, 0.02), (5.0, 170.0, 0.1), (170.0, 180.0, 0.02))


@functools.cache
def _grid() -> np.ndarray:
    parts = []
    for start, stop, step in SEGMENTS_DEG:
        count = int(round((stop - start) / step))
        parts.append(np.linspace(start, stop, count + 1)[:-1])
    parts.append(np.array([180.0]))
    grid = np.radians(np.concatenate(parts))
    grid.flags.writeable = False
    return grid


def angle_grid() -> np.ndarray:
    """Scattering angles [rad] of the shared grid, ascending from 0 to pi (read-only float64)."""
    return _grid()


def segment_table() -> np.ndarray:
    """Per segment: (first angle [rad], step [rad], index of its first node); used by the kernels' lookup."""
    rows, index = [], 0
    for start, stop, step in SEGMENTS_DEG:
        rows.append((np.radians(start), np.radians(step), index))
        index += int(round((stop - start) / step))
    return np.array(rows)


def _linear_moment(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(integral of sin over [a, b], integral of (theta - a) sin over [a, b]), free of cancellation."""
    h = b - a
    m = 0.5 * (a + b)
    s0 = 2.0 * np.sin(m) * np.sin(0.5 * h)
    # integral of (theta - a) sin(theta) = cos(m) (2 sin(h/2) - h cos(h/2)) + h sin(m) sin(h/2)
    small = h < 1e-2
    core = np.where(small, h**3 / 12.0 - h**5 / 480.0, 2.0 * np.sin(0.5 * h) - h * np.cos(0.5 * h))
    s1 = np.cos(m) * core + h * np.sin(m) * np.sin(0.5 * h)
    return s0, s1


@functools.cache
def _weights(key: bytes) -> np.ndarray:
    theta = np.frombuffer(key, dtype=np.float64)
    a, b = theta[:-1], theta[1:]
    h = b - a
    s0, s1 = _linear_moment(a, b)
    # p(theta) = p_a (1 - u) + p_b u with u = (theta - a) / h
    w = np.zeros_like(theta)
    w[:-1] += s0 - s1 / h
    w[1:] += s1 / h
    out = 2.0 * np.pi * w
    out.flags.writeable = False
    return out


def sphere_weights(theta: np.ndarray | None = None) -> np.ndarray:
    """Weights w with sum(w * p) = integral of p over the sphere [sr], p piecewise linear in theta."""
    theta = angle_grid() if theta is None else np.ascontiguousarray(theta, dtype=np.float64)
    return _weights(theta.tobytes())


def sphere_integral(values: np.ndarray, theta: np.ndarray | None = None, *, upto: float | None = None) -> np.ndarray:
    """Integral over the sphere of tabulated ``values`` (last axis on the grid); ``upto`` limits theta [rad]."""
    theta = angle_grid() if theta is None else theta
    values = np.asarray(values, dtype=np.float64)
    if upto is None:
        return values @ sphere_weights(theta)
    cut = np.searchsorted(theta, upto, side="right")
    if cut < len(theta) and theta[cut - 1] < upto:
        # split the interval containing ``upto`` by interpolating the table there
        inner = np.append(theta[:cut], upto)
        frac = (upto - theta[cut - 1]) / (theta[cut] - theta[cut - 1])
        edge = values[..., cut - 1] + frac * (values[..., cut] - values[..., cut - 1])
        return np.concatenate([values[..., :cut], edge[..., None]], axis=-1) @ sphere_weights(inner)
    return values[..., :cut] @ sphere_weights(theta[:cut])


def normalise(values: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """``values`` scaled so that each row integrates to 1 over the sphere."""
    values = np.asarray(values, dtype=np.float64)
    return values / sphere_integral(values, theta)[..., None]


def delta_table(theta: np.ndarray | None = None) -> np.ndarray:
    """The grid's discrete Dirac delta at theta = 0: all mass in the first node, integral 1."""
    theta = angle_grid() if theta is None else theta
    values = np.zeros(len(theta))
    values[0] = 1.0
    return normalise(values, theta)


def cumulative(values: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """Integral over the cap theta' < theta_i of tabulated ``values`` at every node (last axis); starts at 0."""
    theta = angle_grid() if theta is None else theta
    values = np.asarray(values, dtype=np.float64)
    a, b = theta[:-1], theta[1:]
    s0, s1 = _linear_moment(a, b)
    h = b - a
    pieces = 2.0 * np.pi * (values[..., :-1] * (s0 - s1 / h) + values[..., 1:] * (s1 / h))
    out = np.zeros_like(values)
    out[..., 1:] = np.cumsum(pieces, axis=-1)
    return out
