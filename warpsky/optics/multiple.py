"""Multiple-scattering angular distributions Ams_n (Riley 2004 Eqs. 20, 23) and Bouthors' modified Mie (2006 §4.1).

Axisymmetric phase functions convolve on the sphere by multiplying their Legendre coefficients
(the Funk–Hecke theorem): with p(θ) = Σ_l (2l + 1) / (4π) χ_l P_l(cos θ) and χ_0 = 1,

    Ams_n(θ) = Σ_l (2l + 1) / (4π) χ_l^n P_l(cos θ).

This is exact for the table as the kernels see it (piecewise linear in θ on the shared grid), up to the number of
terms kept. Rain's forward diffraction peak (first zero ~0.01°) needs l up to ~7e4, so the coefficients are
computed in two passes:

* l ≤ :data:`FULL_DEGREE`: Gauss–Legendre quadrature over every grid interval of [0, π], with enough points per
  interval to follow P_l (rule: 0.6 × phase span + 6), applied to the linear interpolant;
* FULL_DEGREE < l ≤ L: the same quadrature restricted to θ < 5°, the only part of any warpsky table with structure
  finer than 0.1°; the rest contributes there only through the kinks of the interpolant, below 1e-6 of χ_0.

Either pass stops at the first chunk of 512 coefficients that all lie below :data:`COEFFICIENT_TOLERANCE`.

The series stops where every |χ_l| stays below :data:`COEFFICIENT_TOLERANCE`, which keeps the forward peak (no
delta-M style truncation) and leaves no ringing: the dropped terms are smaller than the tolerance squared in Ams_2.
Upward three-term recurrence for P_l is stable on [-1, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpsky.optics.grid import angle_grid, delta_table, normalise, sphere_integral

#: Highest degree integrated over the whole sphere.
FULL_DEGREE = 12000
#: Highest degree ever used (the Nyquist degree of the grid's 0.0025° forward segment is ~72,000).
MAX_DEGREE = 80000
#: Terms with |χ_l| below this (for all channels, from some l on) end the series.
COEFFICIENT_TOLERANCE = 1e-5
#: The forward segment where coefficients beyond FULL_DEGREE are integrated [rad].
FORWARD_LIMIT = np.radians(5.0)
_CHUNK = 512


def _legendre_chunks(mu: np.ndarray, degree: int):
    """Yield (first l, rows P_l(mu) for l = first .. first + count - 1) in chunks, for l = 0 .. ``degree``."""
    prev, cur = np.zeros_like(mu), np.ones_like(mu)  # P_{-1} := 0, P_0
    for first in range(0, degree + 1, _CHUNK):
        count = min(_CHUNK, degree + 1 - first)
        rows = np.empty((count, mu.size))
        for k in range(count):
            l = first + k
            if l > 0:  # P_l from P_{l-1} (cur) and P_{l-2} (prev)
                prev, cur = cur, ((2 * l - 1) * mu * cur - (l - 1) * prev) / l
            rows[k] = cur
        yield first, rows


def _quadrature(theta: np.ndarray, values: np.ndarray, degree: int, upto: float | None):
    """(cos of nodes, weights (C, K) of 2π ∫ f(θ) sin θ dθ of the interpolant) on the intervals below ``upto``."""
    a, b = theta[:-1], theta[1:]
    keep = np.ones(len(a), dtype=bool) if upto is None else b <= upto + 1e-15
    a, b = a[keep], b[keep]
    fa, fb = values[:, :-1][:, keep], values[:, 1:][:, keep]
    span = (b - a) * degree
    points = np.clip(np.ceil(0.6 * span).astype(int) + 6, 6, 256)
    mus, weights = [], []
    for q in np.unique(points):
        sel = points == q
        x, w = np.polynomial.legendre.leggauss(int(q))
        half = 0.5 * (b[sel] - a[sel])
        t = (0.5 * (x[None, :] + 1.0)) * (b[sel] - a[sel])[:, None] + a[sel][:, None]  # (I, q)
        u = (t - a[sel][:, None]) / (b[sel] - a[sel])[:, None]
        f = fa[:, sel][:, :, None] * (1.0 - u) + fb[:, sel][:, :, None] * u  # (C, I, q)
        wt = 2.0 * np.pi * half[:, None] * w[None, :] * np.sin(t)
        mus.append(np.cos(t).ravel())
        weights.append((f * wt[None]).reshape(values.shape[0], -1))
    return np.concatenate(mus), np.concatenate(weights, axis=1)


def legendre_coefficients(
    table: np.ndarray, theta: np.ndarray | None = None, *, max_degree: int | None = None
) -> np.ndarray:
    """χ_l = 2π ∫ p(θ) P_l(cos θ) sin θ dθ of the piecewise-linear ``table`` (C, M), for l = 0 .. L (C, L + 1).

    ``max_degree`` caps L (default: until the series ends, at most :data:`MAX_DEGREE`).
    """
    theta = angle_grid() if theta is None else np.asarray(theta, dtype=np.float64)
    table = np.atleast_2d(np.asarray(table, dtype=np.float64))
    full = FULL_DEGREE if max_degree is None else min(max_degree, FULL_DEGREE)
    mu, weight = _quadrature(theta, table, full, None)
    blocks = []
    for _, rows in _legendre_chunks(mu, full):
        blocks.append(weight @ rows.T)
        if np.max(np.abs(blocks[-1])) < COEFFICIENT_TOLERANCE:
            break  # a whole chunk below tolerance: the series has ended
    chi = np.concatenate(blocks, axis=1)
    unresolved = np.max(np.abs(chi[:, -_CHUNK:])) > COEFFICIENT_TOLERANCE
    if max_degree is None and chi.shape[1] == FULL_DEGREE + 1 and unresolved:
        # the forward peak is not resolved yet: go on over the forward segment alone
        mu, weight = _quadrature(theta, table, MAX_DEGREE, FORWARD_LIMIT)
        more = []
        for first, rows in _legendre_chunks(mu, MAX_DEGREE):
            if first + len(rows) <= FULL_DEGREE + 1:
                continue  # only advancing the recurrence
            block = (weight @ rows.T)[:, max(0, FULL_DEGREE + 1 - first) :]
            more.append(block)
            if np.max(np.abs(block)) < COEFFICIENT_TOLERANCE:
                break
        chi = np.concatenate([chi, *more], axis=1)
    # end the series after the last coefficient above tolerance
    above = np.nonzero(np.max(np.abs(chi), axis=0) >= COEFFICIENT_TOLERANCE)[0]
    return chi[:, : above[-1] + 1 if len(above) else 1]


def synthesize(coefficients: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """Σ_l (2l + 1)/(4π) c_l P_l(cos θ) at the grid nodes, for coefficient rows (..., L + 1) -> (..., M)."""
    theta = angle_grid() if theta is None else np.asarray(theta, dtype=np.float64)
    coefficients = np.asarray(coefficients, dtype=np.float64)
    lead = coefficients.shape[:-1]
    flat = coefficients.reshape(-1, coefficients.shape[-1])
    mu = np.cos(theta)
    out = np.zeros((flat.shape[0], len(theta)))
    scale_all = (2.0 * np.arange(flat.shape[1]) + 1.0) / (4.0 * np.pi)
    for first, rows in _legendre_chunks(mu, flat.shape[1] - 1):
        block = flat[:, first : first + len(rows)]
        live = np.max(np.abs(block), axis=1) > 0.0
        if np.any(live):
            out[live] += (block[live] * scale_all[first : first + len(rows)]) @ rows
    return out.reshape(*lead, len(theta))


@dataclass
class AmsDiagnostics:
    """How exact a set of Ams tables is.

    Attributes:
        degree: Legendre terms used.
        raw_integral: (N+1, C) integral of each synthesised table before renormalisation (1 when exact).
        clipped: (N+1, C) largest negative value clipped, relative to the table's maximum.
    """

    degree: int
    raw_integral: np.ndarray
    clipped: np.ndarray


def ams_tables(phase: np.ndarray, orders: int, *, diagnostics: bool = False):
    """Ams_n for n = 0 .. ``orders`` of the phase tables ``phase`` (C, M) -> (orders + 1, C, M) (Riley Eq. 20).

    Ams_0 is the grid's delta at θ = 0 and Ams_1 the phase table itself; higher orders come from Legendre powers,
    clipped at 0 (the clipped amount is in the diagnostics) and renormalised.
    """
    phase = np.atleast_2d(np.asarray(phase, dtype=np.float64))
    channels, size = phase.shape
    ams = np.empty((orders + 1, channels, size))
    ams[0] = delta_table()[None, :]
    if orders >= 1:
        ams[1] = phase
    raw = np.ones((orders + 1, channels))
    clipped = np.zeros((orders + 1, channels))
    degree = 1
    if orders >= 2:
        chi = legendre_coefficients(phase)
        chi[:, 0] = 1.0
        degree = chi.shape[1]
        powers = np.stack([chi**n for n in range(2, orders + 1)])  # (orders - 1, C, L + 1)
        with np.errstate(under="ignore"):
            powers[np.abs(powers) < 1e-300] = 0.0
        tables = synthesize(powers)
        raw[2:] = sphere_integral(tables)
        peak = np.max(tables, axis=-1, keepdims=True)
        clipped[2:] = np.max(np.clip(-tables, 0.0, None) / peak, axis=-1)
        ams[2:] = normalise(np.clip(tables, 0.0, None))
    if diagnostics:
        return ams, AmsDiagnostics(degree, raw, clipped)
    return ams


def forward_fractions(ams: np.ndarray) -> np.ndarray:
    """F_n: the share of Ams_n in the forward hemisphere θ < 90° (Riley Eq. 23), shape ams.shape[:-1]."""
    return sphere_integral(ams, upto=0.5 * np.pi)


def isotropic_order(ams: np.ndarray, tolerance: float = 1e-2) -> np.ndarray:
    """Per channel, the first order n with max |4π Ams_n - 1| < ``tolerance`` (-1 if none)."""
    deviation = np.max(np.abs(4.0 * np.pi * ams - 1.0), axis=-1)  # (N+1, C)
    below = deviation < tolerance
    return np.where(below.any(axis=0), np.argmax(below, axis=0), -1)


def convolve(a: np.ndarray, b: np.ndarray, *, max_degree: int | None = None) -> np.ndarray:
    """Spherical convolution a * b of two axisymmetric tables (C, M) (both normalised), clipped and renormalised.

    With ``max_degree`` the product series is cut there with a Hann taper over its upper half (no Gibbs
    ringing; the result is blurred by ~2π / max_degree rad), for tables with cuts such as Bouthors' P_S.
    """
    ca = legendre_coefficients(a, max_degree=max_degree)
    cb = legendre_coefficients(b, max_degree=max_degree)
    degree = min(ca.shape[1], cb.shape[1])
    product = ca[:, :degree] * cb[:, :degree]
    if max_degree is not None and degree > 1:
        l = np.arange(degree)
        half = 0.5 * (degree - 1)
        product = product * np.where(l <= half, 1.0, 0.5 * (1.0 + np.cos(np.pi * (l - half) / half)))
    table = synthesize(product)
    return normalise(np.clip(table, 0.0, None))


@dataclass
class ModifiedMie:
    """Bouthors 2006 §4.1 split of a phase function at the forward cut θ_f.

    Attributes:
        forward_weight: P_f per channel: the share of scattering below θ_f.
        p_s: P_S = P / (1 - P_f) for θ ≥ θ_f, else 0 (normalised) [1/sr].
        p_f: P_F = P / P_f for θ < θ_f, else 0 (normalised) [1/sr].
        p2: P_S * P_S, the modified double-scattering distribution [1/sr] (series to l = 3600, Hann taper).
        theta_f: The cut [rad].
    """

    forward_weight: np.ndarray
    p_s: np.ndarray
    p_f: np.ndarray
    p2: np.ndarray
    theta_f: float


def modified_mie(phase: np.ndarray, theta_f: float) -> ModifiedMie:
    """Split ``phase`` (C, M) at ``theta_f`` [rad] into the forward peak and the rest (Bouthors 2006 §4.1)."""
    phase = np.atleast_2d(np.asarray(phase, dtype=np.float64))
    theta = angle_grid()
    if not 0.0 < theta_f < np.pi:
        raise ValueError(f"theta_f must lie in (0, pi), got {theta_f}")
    forward_weight = sphere_integral(phase, upto=theta_f)
    # the cut falls on a node of the grid for the usual 5°; elsewhere the node below takes the step
    inside = theta < theta_f - 1e-12
    p_f = normalise(np.where(inside, phase, 0.0))
    p_s = normalise(np.where(inside, 0.0, phase))
    return ModifiedMie(forward_weight, p_s, p_f, convolve(p_s, p_s, max_degree=3600), float(theta_f))


def forward_cut(phase: np.ndarray, theta_f: float) -> tuple[np.ndarray, np.ndarray]:
    """(truncated phase (C, M), peak fraction f (C,)): ``phase`` (C, M, normalised) with its forward peak above
    its value at ``theta_f`` [rad] cut off, ``p = f delta + (1 - f) p_cut`` (the delta-M idea, Wiscombe 1977, with
    the peak flattened to a plateau rather than Bouthors' split, so the truncated phase keeps light going forward).
    A medium whose scattering coefficient is reduced to sigma_s (1 - f), its extinction by f sigma_s, and which
    scatters by ``p_cut`` treats light deflected by less than ``theta_f`` as not scattered."""
    phase = np.atleast_2d(np.asarray(phase, dtype=np.float64))
    if not 0.0 < theta_f < np.pi:
        raise ValueError(f"theta_f must lie in (0, pi), got {theta_f}")
    theta = angle_grid()
    plateau = np.array([np.interp(theta_f, theta, row) for row in phase])
    inside = theta < theta_f
    flattened = np.where(inside, np.minimum(phase, plateau[:, None]), phase)
    fraction = np.clip(sphere_integral(phase) - sphere_integral(flattened), 0.0, 1.0)
    return normalise(flattened), fraction
