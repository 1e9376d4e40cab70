"""The air of several constituents (:mod:`~warpsky.media.air.mixture`) on the device, float32: each constituent's
optical depth along a ray in closed form, the sun's transmittance, and the single-scattering integrals of the
Rayleigh gas and the aerosols, each as its own Riley closed form times the mean, over :data:`SCATTER_NODES`
Gauss-Legendre nodes in that closed form's cumulative fraction, of what the other constituents take away. Air
without aerosols or ozone (``AnalyticAir.mixed`` 0) keeps Riley's closed forms exactly."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core.numerics import exp3, one_minus_exp, one_minus_exp_over_x
from warpsky.media.air.analytic import X_CUT_WP, AirRay, AnalyticAir, air_depth, air_inscatter

#: Gauss-Legendre nodes per scattering constituent of a ray's single-scattering integral.
SCATTER_NODES = 12
_X, _W = np.polynomial.legendre.leggauss(SCATTER_NODES)
_vec = wp.types.vector(length=SCATTER_NODES, dtype=float)
SCATTER_S = wp.constant(_vec(*(0.5 * (_X + 1.0)).tolist()))
SCATTER_W = wp.constant(_vec(*(0.5 * _W).tolist()))


@wp.struct
class AirDepths:
    """Optical depths along one ray, per constituent, RGB."""

    rayleigh: wp.vec3
    mie: wp.vec3
    ozone: wp.vec3


@wp.struct
class AirScatter:
    """int sigma_s,c T T_sun dt per scattering constituent along one ray (multiply by E P_c), RGB."""

    rayleigh: wp.vec3
    mie: wp.vec3


@wp.func
def ozone_column(air: AnalyticAir, h: float) -> float:
    """The ozone layer's column [m] above altitude ``h`` per unit peak density (its tent profile)."""
    c = air.ozone_altitude
    w = air.ozone_width
    if h <= c:
        x = wp.clamp(h, c - w, c) - (c - w)
        return w - x * x / (2.0 * w)
    y = c + w - wp.clamp(h, c, c + w)
    return y * y / (2.0 * w)


@wp.func
def ozone_density(air: AnalyticAir, h: float) -> float:
    return wp.max(1.0 - wp.abs(h - air.ozone_altitude) / air.ozone_width, 0.0)


@wp.func
def ozone_depth(air: AnalyticAir, h0: float, view_y: float, distance: float) -> float:
    """The ozone layer's optical depth per unit peak absorption from ``h0`` over ``distance`` (1e30: infinity)."""
    if view_y > 0.0 and distance >= 1.0e29:
        return ozone_column(air, h0) / view_y
    k = wp.min(distance, 1.0e30)
    dh = view_y * k
    if wp.abs(dh) > 1.0e-3:
        return (ozone_column(air, h0) - ozone_column(air, h0 + dh)) / view_y
    return k * ozone_density(air, h0 + 0.5 * dh)


@wp.func
def air_depths(air: AnalyticAir, h0: float, view_y: float, distance: float) -> AirDepths:
    out = AirDepths()
    out.rayleigh = air_depth(air.beta_sea_level, air.gamma, h0, view_y, distance)
    out.mie = air_depth(air.mie_extinction, air.mie_gamma, h0, view_y, distance)
    out.ozone = air.ozone * ozone_depth(air, h0, view_y, distance)
    return out


@wp.func
def air_optical_depth(air: AnalyticAir, h0: float, view_y: float, distance: float) -> wp.vec3:
    """Optical depth of all the air from altitude ``h0`` over ``distance`` [m] (1e30: infinity) at elevation sine
    ``view_y``; Riley's Eq. 11 alone for air without aerosols or ozone."""
    if air.mixed == 0:
        return air_depth(air.beta_sea_level, air.gamma, h0, view_y, distance)
    d = air_depths(air, h0, view_y, distance)
    return d.rayleigh + d.mie + d.ozone


@wp.func
def air_column(air: AnalyticAir, h: float) -> wp.vec3:
    """Vertical optical depth of all the air above altitude ``h``."""
    out = air.beta_sea_level * (wp.exp(-air.gamma * h) / air.gamma)
    if air.mixed != 0:
        out += air.mie_extinction * (wp.exp(-air.mie_gamma * h) / air.mie_gamma)
        out += air.ozone * ozone_column(air, h)
    return out


@wp.func
def scalar_depth(beta: float, gamma: float, h0: float, view_y: float, distance: float) -> float:
    """One channel of :func:`~warpsky.media.air.analytic.air_depth`."""
    b = beta * wp.exp(-gamma * h0)
    k = distance
    if view_y < 0.0:
        k = wp.min(k, X_CUT_WP / (gamma * (-view_y)))
    if view_y > 0.0 and distance >= 1.0e29:
        return b / (gamma * view_y)
    return b * (k * one_minus_exp_over_x(gamma * view_y * k))


@wp.func
def distance_at_depth(beta: float, gamma: float, h0: float, view_y: float, tau: float) -> float:
    """Distance [m] at which a constituent of sea-level extinction ``beta`` reaches optical depth ``tau`` from
    ``h0`` along elevation sine ``view_y`` (Riley's Eq. 11 inverted)."""
    b0 = wp.max(beta * wp.exp(-gamma * h0), 1.0e-30)
    x = wp.min(tau * gamma * view_y / b0, 1.0 - 1.0e-7)
    ratio = 1.0 + 0.5 * x
    if wp.abs(x) >= 1.0e-4:
        ratio = -wp.log(1.0 - x) / x
    return tau / b0 * ratio


@wp.func
def channel_scatter(air: AnalyticAir, which: int, c: int, h0: float, view_y: float, sun_y: float,
                    d: AirDepths) -> float:
    """Channel ``c`` of constituent ``which``'s (0 Rayleigh, 1 aerosols) int sigma_t,c T T_sun dt (times its
    albedo outside): its own closed form, int_0^tau_K e^{-tau_s0 - q tau} dtau with q = 1 - v_y / sun_y, times the
    mean over w = its cumulative fraction of the others' transmittance towards the eye and the sun."""
    beta = air.beta_sea_level[c]
    gamma = air.gamma
    own = d.rayleigh[c]
    if which == 1:
        beta = air.mie_extinction[c]
        gamma = air.mie_gamma
        own = d.mie[c]
    if beta <= 0.0:
        return 0.0
    sun_0 = beta * wp.exp(-gamma * h0) / (gamma * sun_y)
    q = 1.0 - view_y / sun_y
    z = wp.abs(q) * own
    # e^{-tau_s0} times the closed form; for q < 0, z - tau_s0 = -(tau_K + the sun's depth at the far end) <= 0
    integral = float(0.0)
    if z < 1.0e-4:
        integral = wp.exp(-sun_0) * own * (1.0 - 0.5 * z)
    elif q > 0.0:
        integral = wp.exp(-sun_0) * one_minus_exp(z) / q
    else:
        integral = (wp.exp(z - sun_0) - wp.exp(-sun_0)) / (-q)
    total = float(0.0)
    for k in range(SCATTER_NODES):
        w = SCATTER_S[k]
        tau = float(0.0)
        if z < 1.0e-4:
            tau = w * own
        elif q > 0.0:
            tau = -wp.log(1.0 - w * one_minus_exp(z)) / q
        else:
            tau = own + wp.log(w + (1.0 - w) * wp.exp(-z)) / (-q)
        t = distance_at_depth(beta, gamma, h0, view_y, tau)
        h = h0 + view_y * t
        others = air.ozone[c] * (ozone_depth(air, h0, view_y, t) + ozone_column(air, h) / sun_y)
        if which == 0:
            others += scalar_depth(air.mie_extinction[c], air.mie_gamma, h0, view_y, t)
            others += air.mie_extinction[c] * wp.exp(-air.mie_gamma * h) / (air.mie_gamma * sun_y)
        else:
            others += scalar_depth(air.beta_sea_level[c], air.gamma, h0, view_y, t)
            others += air.beta_sea_level[c] * wp.exp(-air.gamma * h) / (air.gamma * sun_y)
        total += SCATTER_W[k] * wp.exp(-others)
    return integral * total


@wp.func
def air_scatter(air: AnalyticAir, h0: float, view_y: float, sun_y: float, distance: float) -> AirScatter:
    """The single-scattering integrals of the Rayleigh gas and the aerosols from ``h0`` over ``distance`` for a
    sun of air sine ``sun_y`` (0 or less: none); the Rayleigh gas alone in Riley's closed form when the air holds
    nothing else."""
    out = AirScatter()
    out.rayleigh = wp.vec3(0.0)
    out.mie = wp.vec3(0.0)
    if sun_y <= 0.0:
        return out
    if air.mixed == 0:
        out.rayleigh = air_inscatter(air.beta_sea_level, air.gamma, h0, view_y, sun_y, distance)
        return out
    d = air_depths(air, h0, view_y, distance)
    for c in range(3):
        out.rayleigh[c] = channel_scatter(air, 0, c, h0, view_y, sun_y, d)
        out.mie[c] = air.mie_albedo[c] * channel_scatter(air, 1, c, h0, view_y, sun_y, d)
    return out


@wp.func
def split_transmittance(air: AnalyticAir, along: AirRay, view_y: float) -> wp.vec3:
    """Transmittance of the air from the ray's start to its split (the front air), RGB, along a ray of elevation
    sine ``view_y``."""
    return exp3(air_optical_depth(air, along.altitude, view_y, along.split))
