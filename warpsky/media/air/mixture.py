"""Air of several constituents on a flat earth, on the host (float64): Riley's Rayleigh gas, aerosols (Mie
scattering and absorption, Henyey-Greenstein phase, their own scale height) and an ozone layer (absorption only, a
density rising linearly from 0 at ``ozone_altitude - ozone_width`` to 1 at ``ozone_altitude`` and back to 0 at
``ozone_altitude + ozone_width``: Bruneton 2017's profile).

On a flat earth every constituent's optical depth along a ray is closed form: an exponential one's is Riley's Eq. 11
with its own scale height, the ozone layer's is its vertical column's difference between the ray's ends over the
elevation sine. The in-scattered light is not (two scale heights and a layer in one exponent), so it is integrated
per scattering constituent c in its own s_c = 1 - T_c along the ray, where the integrand is smooth:

    int_0^K sigma_s,c T T_sun dt = omega_c int_0^{1 - T_c(K)} T_others(t(s)) T_sun(h(s)) ds,

T_others = T / T_c the other constituents' transmittance, omega_c = sigma_s,c / sigma_t,c (1 for Rayleigh) and the
point at each s in closed form (Riley's Eq. 11 inverted with that constituent's scale height). The pure Rayleigh
air keeps Riley's closed form (:func:`~warpsky.media.air.analytic.inscatter`) exactly.

The sun's transmittance at altitude h is exp(-column(h) / air_sine) with the Rayleigh gas's ``air_sine`` for every
constituent (the flat earth's air mass, continued to Chapman's grazing value for the gas below about 4°)."""

from __future__ import annotations

import math

import numpy as np

from warpsky.media.air.analytic import _depth, air_sine, inscatter
from warpsky.media.air.analytic import sun_transmittance as riley_sun_transmittance

#: Gauss-Legendre nodes per scattering constituent of the host's ray integrals.
HOST_NODES = 48


def hg(cos_theta, g: float) -> np.ndarray:
    """Henyey-Greenstein phase [1/sr]; cos_theta = 1 looks into the sun."""
    cos_theta = np.asarray(cos_theta, dtype=np.float64)
    return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def ozone_density(atm, h) -> np.ndarray:
    """The ozone layer's density relative to its peak at altitude ``h`` [m above sea level]."""
    h = np.asarray(h, dtype=np.float64)
    return np.maximum(1.0 - np.abs(h - atm.ozone_altitude) / atm.ozone_width, 0.0)


def ozone_column(atm, h) -> np.ndarray:
    """int_h^inf of :func:`ozone_density` [m]: ``ozone_width`` below the layer, 0 above it."""
    h = np.asarray(h, dtype=np.float64)
    c, w = atm.ozone_altitude, atm.ozone_width
    below = w - (np.clip(h, c - w, c) - (c - w)) ** 2 / (2.0 * w)
    above = (c + w - np.clip(h, c, c + w)) ** 2 / (2.0 * w)
    return np.where(h <= c, below, above)


def mie_extinction(atm) -> np.ndarray:
    return atm.mie_scattering + atm.mie_absorption


def column(atm, h) -> np.ndarray:
    """(..., 3) vertical optical depth of all the air above altitude ``h`` [m above sea level]."""
    h = np.asarray(h, dtype=np.float64)[..., None]
    out = atm.beta_sea_level * np.exp(-atm.gamma * h) / atm.gamma
    if atm.has_aerosols:
        out = out + mie_extinction(atm) * np.exp(-h / atm.mie_scale_height) * atm.mie_scale_height
    if atm.has_ozone:
        out = out + atm.ozone_absorption * ozone_column(atm, h)
    return out


def ozone_depth(atm, h0, view_y, distance) -> np.ndarray:
    """Optical depth per unit peak absorption of the ozone layer from ``h0`` over ``distance`` (inf: upward to
    space, or along the horizontal) at elevation sine ``view_y``: the layer's mean density over the ray's altitude
    span times its length."""
    h0 = np.asarray(h0, dtype=np.float64)
    view_y = np.asarray(view_y, dtype=np.float64)
    distance = np.asarray(distance, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        finite = np.isfinite(distance)
        k = np.where(finite, distance, 0.0)
        dh = view_y * k
        h1 = h0 + dh
        steep = np.abs(dh) > 1e-3
        mean = np.where(steep, (ozone_column(atm, h0) - ozone_column(atm, h1)) / np.where(steep, dh, 1.0),
                        ozone_density(atm, h0 + 0.5 * dh))
        out = k * mean
        up = ozone_column(atm, h0) / np.where(view_y > 0.0, view_y, 1.0)
        level = np.where(ozone_density(atm, h0) > 0.0, np.inf, 0.0)
        return np.where(finite, out, np.where(view_y > 0.0, up, np.where(view_y < 0.0, np.inf, level)))


def depth_parts(atm, h0, view_y, distance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Rayleigh, aerosols, ozone) optical depths, (..., 3) each, along a ray from ``h0`` [m above sea level] of
    elevation sine ``view_y`` over ``distance`` [m] (inf: to the end of the air)."""
    h0 = np.asarray(h0, dtype=np.float64)[..., None]
    view_y = np.asarray(view_y, dtype=np.float64)[..., None]
    distance = np.asarray(distance, dtype=np.float64)[..., None]
    rayleigh = _depth(atm.beta_sea_level, atm.gamma, h0, view_y, distance)[1]
    zero = np.zeros(np.broadcast_shapes(rayleigh.shape, (3,)))
    mie = ozone = zero
    if atm.has_aerosols:
        mie = _depth(mie_extinction(atm), 1.0 / atm.mie_scale_height, h0, view_y, distance)[1]
    if atm.has_ozone:
        ozone = atm.ozone_absorption * ozone_depth(atm, h0, view_y, distance)
    return rayleigh + zero, mie + zero, ozone + zero


def optical_depth(atm, h0, view_y, distance) -> np.ndarray:
    """(..., 3) optical depth of all the air along a ray (see :func:`depth_parts`)."""
    rayleigh, mie, ozone = depth_parts(atm, h0, view_y, distance)
    return rayleigh + mie + ozone


def transmittance(atm, h0, view_y, distance) -> np.ndarray:
    return np.exp(-optical_depth(atm, h0, view_y, distance))


def sunlight_transmittance(atm, h, sun_y) -> np.ndarray:
    """(..., 3) transmittance of sunlight from elevation sine ``sun_y`` down to altitude ``h``: the column over
    :func:`~warpsky.media.air.analytic.air_sine` (Riley's Eq. 12 for air without aerosols or ozone)."""
    if not atm.mixed:
        return riley_sun_transmittance(atm.beta_sea_level, atm.gamma, h, sun_y)
    return sun_transmittance(atm, h, float(air_sine(sun_y, atm.gamma)))


def sun_transmittance(atm, h, air_sine: float) -> np.ndarray:
    """(..., 3) sunlight's transmittance down to altitude ``h`` for a sun of ``air_sine``
    (:func:`~warpsky.media.air.analytic.air_sine`)."""
    return np.exp(-column(atm, h) / air_sine)


def constituents(atm):
    """(sea-level extinction (3,), 1 / scale height, single-scattering albedo (3,)) of each scattering
    constituent: the Rayleigh gas, then the aerosols where there are any."""
    out = [(np.asarray(atm.beta_sea_level, dtype=np.float64), atm.gamma, np.ones(3))]
    if atm.has_aerosols:
        ext = mie_extinction(atm)
        albedo = np.divide(atm.mie_scattering, ext, out=np.zeros(3), where=ext > 0.0)
        out.append((ext, 1.0 / atm.mie_scale_height, albedo))
    return out


def points_along(beta, gamma: float, h0, view_y, tau) -> tuple[np.ndarray, np.ndarray]:
    """(altitude [m], distance [m]) where a constituent of sea-level extinction ``beta`` and 1 / scale height
    ``gamma`` reaches optical depth ``tau`` from ``h0`` along elevation sine ``view_y`` (Riley Eq. 11 inverted;
    arrays broadcast, channel last)."""
    h0 = np.asarray(h0, dtype=np.float64)
    view_y = np.asarray(view_y, dtype=np.float64)
    b0 = np.asarray(beta, dtype=np.float64) * np.exp(-gamma * h0)
    safe_b0 = np.where(b0 > 0.0, b0, 1.0)
    x = np.minimum(tau * gamma * view_y / safe_b0, 1.0 - 1e-15)
    small = np.abs(x) < 1e-6
    ratio = np.where(small, 1.0 + 0.5 * x, -np.log1p(-np.where(small, 0.0, x)) / np.where(small, 1.0, x))
    distance = tau / safe_b0 * ratio
    return h0 + view_y * distance, distance


def riley_nodes(own, sun_own_0, view_y, air_sine: float, w) -> tuple[np.ndarray, np.ndarray]:
    """(optical depth tau of the constituent at each node w in [0, 1], the constituent's own closed-form integral
    int_0^K sigma_t,c T_c T_c,sun dt per unit weight): Riley's integrand in tau is e^{-tau_s0} e^{-q tau},
    q = 1 - v_y / air_sine, so w = (1 - e^{-q tau}) / (1 - e^{-q tau_K}) (and its mirror for q < 0) makes it
    constant; ``own`` is the constituent's depth over the whole ray (tau_K), ``sun_own_0`` its sun depth at the
    start (tau_s0). Channel last."""
    q = 1.0 - np.asarray(view_y, dtype=np.float64)[..., None] / air_sine
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        z = np.abs(q) * own
        flat = ~(z > 1e-6)
        safe_q = np.where(flat, 1.0, np.abs(q))
        span_pos = -np.expm1(-np.where(flat, 0.0, z))  # q > 0
        span_neg = np.expm1(np.minimum(np.where(flat, 0.0, z), 700.0))  # q < 0
        w = np.asarray(w, dtype=np.float64)
        tau = np.where(flat, w * np.where(np.isfinite(own), own, 0.0),
                       np.where(q > 0.0, -np.log1p(-w * span_pos) / safe_q, np.log1p(w * span_neg) / safe_q))
        # the closed form: e^{-tau_s0} int_0^{tau_K} e^{-q tau} dtau
        integral = np.where(flat, own * (1.0 - 0.5 * z), np.where(q > 0.0, span_pos, span_neg) / safe_q)
        integral = np.exp(-sun_own_0) * integral
    return tau, integral


def scatter_parts(atm, h0, view_y, air_sine: float, distance, nodes: int = HOST_NODES) -> list[np.ndarray]:
    """[int sigma_s,c T T_sun dt for each scattering constituent c] ((..., 3) each; multiply by E P_c(theta) for
    radiance): the Rayleigh gas's, then the aerosols' where there are any, along a ray from ``h0`` of elevation
    sine ``view_y`` over ``distance`` (inf: to the end of the air) for a sun of ``air_sine`` (0 or less: none).

    Each constituent's term is Riley's closed form for that constituent alone (its own transmittance towards the
    eye and the sun) times the mean, over its integrand's cumulative fraction w, of what the other constituents
    take away (their transmittance towards the eye and the sun): ``nodes`` Gauss-Legendre nodes in w."""
    h0 = np.asarray(h0, dtype=np.float64)
    view_y = np.asarray(view_y, dtype=np.float64)
    distance = np.asarray(distance, dtype=np.float64)
    shape = np.broadcast_shapes(h0.shape, view_y.shape, distance.shape) + (3,)
    if air_sine <= 0.0:
        return [np.zeros(shape) for _ in constituents(atm)]
    if not atm.mixed:
        return [inscatter(atm.beta_sea_level, atm.gamma, h0[..., None], view_y[..., None], air_sine,
                          distance[..., None]) + np.zeros(shape)]
    parts = depth_parts(atm, h0, view_y, distance)
    x, weights = np.polynomial.legendre.leggauss(nodes)
    out = []
    for index, (beta, gamma, albedo) in enumerate(constituents(atm)):
        sun_0 = beta * np.exp(-gamma * h0[..., None]) / (gamma * air_sine)
        total = np.zeros(shape)
        for xk, wk in zip(x, weights, strict=True):
            tau, integral = riley_nodes(parts[index], sun_0, view_y, air_sine, 0.5 * (xk + 1.0))
            h, t = points_along(beta, gamma, h0[..., None], view_y[..., None], tau)
            # each channel's point t, h is broadcast over the three channels' coefficients: keep channel c's own
            at_t = depth_parts(atm, h0[..., None], view_y[..., None], t)
            others = sum(part for i, part in enumerate(at_t) if i != index)
            others = others + (column(atm, h) - beta * np.exp(-gamma * h[..., None]) / gamma) / air_sine
            total = total + 0.5 * wk * np.diagonal(np.exp(-others), axis1=-2, axis2=-1)
        out.append(albedo * integral * total)
    return out
