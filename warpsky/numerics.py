"""Device functions of plain numerics every kernel shares: exponential integrals that stay accurate from optical
depths of 1e-9 to 1e30, and luminance."""

from __future__ import annotations

import warp as wp


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
