"""Device functions of plain numerics every kernel shares: exponential integrals that stay accurate from optical
depths of 1e-9 to 1e30, luminance and channel means, the cells of clamped bilinear and trilinear lookups, and the
bisection of cumulative tables."""

from __future__ import annotations

import numpy as np
import warp as wp

#: Rec. 709 luminance weights, on the host, for alpha and for one-number summaries of RGB quantities (the device
#: has :func:`luminance`).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


@wp.func
def one_minus_exp_over_x(x: float) -> float:
    """(1 - exp(-x)) / x, limit 1 at 0, by its Taylor series for |x| < 0.01 (truncation error < x^4/120, where the
    quotient would lose up to 1e-4 of its value to cancellation in float32). Negative x is fine: the air's optical
    depth along a descending ray grows as e^{-x} with x < 0."""
    if wp.abs(x) < 1.0e-2:
        return 1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0)))
    return (1.0 - wp.exp(-x)) / x

@wp.func
def one_minus_exp(tau: float) -> float:
    """1 - e^{-tau} for tau >= 0 without cancellation for tiny tau (float32 would lose it below ~1e-6)."""
    return tau * one_minus_exp_over_x(tau)

@wp.func
def exp_lerp_mean(tau_a: float, tau_b: float) -> float:
    """Mean of exp(-tau) over a step along which tau goes linearly from tau_a to tau_b (both >= 0).

    Equals (exp(-tau_a) - exp(-tau_b)) / (tau_b - tau_a), taken as exp(-min) * (1 - exp(-d)) / d with
    d = |tau_b - tau_a| so it never divides 0 by 0 and never overflows, from optical depths of 1e-9 to 1e30.
    """
    lo = wp.min(tau_a, tau_b)
    return wp.exp(-lo) * one_minus_exp_over_x(wp.abs(tau_b - tau_a))

@wp.func
def exp_lerp_mean3(tau_a: wp.vec3, tau_b: wp.vec3) -> wp.vec3:
    """:func:`exp_lerp_mean` per RGB channel."""
    return wp.vec3(
        exp_lerp_mean(tau_a[0], tau_b[0]), exp_lerp_mean(tau_a[1], tau_b[1]), exp_lerp_mean(tau_a[2], tau_b[2])
    )

@wp.func
def exp3(tau: wp.vec3) -> wp.vec3:
    """exp(-tau) per channel."""
    return wp.vec3(wp.exp(-tau[0]), wp.exp(-tau[1]), wp.exp(-tau[2]))

@wp.func
def luminance(c: wp.vec3) -> float:
    """Rec. 709 luminance."""
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


@wp.func
def mean3(v: wp.vec3) -> float:
    """Mean of the three channels."""
    return (v[0] + v[1] + v[2]) / 3.0


@wp.func
def linear_cell(x: float, n: int):
    """(lower node, upper node, fraction) of the cell of position ``x`` on an axis of ``n`` nodes at the integers,
    ``x`` clamped to [0, n - 1] (the upper node is the lower one at the last node)."""
    c = wp.clamp(x, 0.0, float(n - 1))
    lo = wp.min(int(c), n - 1)
    return lo, wp.min(lo + 1, n - 1), c - float(lo)


@wp.struct
class BilinearCell:
    """The texel cell around a point in texel coordinates: its lower and upper texel and the point's fractions."""

    lo: wp.vec2i
    hi: wp.vec2i
    frac: wp.vec2


@wp.func
def bilinear_cell(p: wp.vec2, n: wp.vec2i) -> BilinearCell:
    """The cell of continuous texel position ``p`` (texel centres at integers) in a map of ``n`` texels per axis,
    ``p`` clamped to [0, n - 1] (clamp-to-edge addressing)."""
    i0, i1, fx = linear_cell(p[0], n[0])
    j0, j1, fy = linear_cell(p[1], n[1])
    out = BilinearCell()
    out.lo = wp.vec2i(i0, j0)
    out.hi = wp.vec2i(i1, j1)
    out.frac = wp.vec2(fx, fy)
    return out


@wp.func
def bilinear_mix(c00: wp.vec3, c10: wp.vec3, c01: wp.vec3, c11: wp.vec3, frac: wp.vec2) -> wp.vec3:
    """Bilinear blend of a cell's corner values ``c<ij>`` (i along the first axis, j along the second) at the
    fractions ``frac``: first along the first axis, then along the second."""
    low = c00 * (1.0 - frac[0]) + c10 * frac[0]
    high = c01 * (1.0 - frac[0]) + c11 * frac[0]
    return low * (1.0 - frac[1]) + high * frac[1]


@wp.struct
class TrilinearCell:
    """The grid cell around a point in index coordinates: its lower and upper node and the point's fractions."""

    lo: wp.vec3i
    hi: wp.vec3i
    frac: wp.vec3


@wp.func
def trilinear_cell(p: wp.vec3, n: wp.vec3i) -> TrilinearCell:
    """The cell of index position ``p`` in a grid of ``n`` nodes per axis, ``p`` clamped to [0, n - 1]."""
    i0, i1, fx = linear_cell(p[0], n[0])
    j0, j1, fy = linear_cell(p[1], n[1])
    k0, k1, fz = linear_cell(p[2], n[2])
    out = TrilinearCell()
    out.lo = wp.vec3i(i0, j0, k0)
    out.hi = wp.vec3i(i1, j1, k1)
    out.frac = wp.vec3(fx, fy, fz)
    return out


@wp.func
def cdf_search(cdf: wp.array(dtype=float), base: int, count: int, u: float) -> int:
    """The bin i in 0..count-1 with cdf[base + i] <= u < cdf[base + i + 1] of the non-decreasing cumulative table
    cdf[base], ..., cdf[base + count] (bisection; u below cdf[base + 1] gives 0, u at or above cdf[base + count - 1]
    gives count - 1)."""
    lo = int(0)
    hi = count
    while hi - lo > 1:
        mid = (lo + hi) / 2
        if cdf[base + mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo
