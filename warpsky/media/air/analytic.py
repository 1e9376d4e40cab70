"""Riley 2004 §4.1's single-scattering sky on a flat earth, rewritten so that no direction or sun ever breaks it.

Air scatters with β(h) = β_sl e^{-γh} (Eq. 10), extinction = scattering (albedo 1), Rayleigh phase (Eq. 1). For an
observer at altitude h0 looking along v (elevation sine v_y), with the sun along l (elevation sine l_y > 0):

* optical depth to distance K (Eq. 11):  τ(K) = B K E(x),  B = β_sl e^{-γh0},  x = γ v_y K,
  E(x) = (1 - e^{-x}) / x  (E(0) = 1: a horizontal ray sees constant density);
* sun transmittance at altitude h (Eq. 12):  exp(-β_sl e^{-γh} / (γ l_y)), with l_y replaced near the horizon by
  :func:`~warpsky.media.air.analytic.air_sine` (a finite air mass: Riley's 1 / l_y diverges there);
* in-scattered radiance over [0, K] (Eq. 8 with Eqs. 10-12), integrated exactly:

      L = I P(θ) B K E(x) exp(-min(τ_s0, τ_s0 + Δ)) F(|Δ|),
      τ_s0 = B / (γ l_y),   Δ = B K E(x) (1 - v_y / l_y),   F(z) = (1 - e^{-z}) / z  (F(0) = 1).

  This is Riley's Eq. 15 with its removable singularities taken out: the factor l_y / (p_y - l_y) and the
  difference of nearly equal exponentials become F (expm1-based, no cancellation at v_y -> l_y), the 1 / p_y of
  his exponents becomes E (no division by zero at horizontal views), and the exponent min(τ_s0, τ_s0 + Δ) >= 0
  never overflows. (Riley's printed Eq. 15 also omits the constant factor exp(-β_eye / (γ p_y)), the eye's
  transmittance to the top of the atmosphere; we keep the exact integral, which the tests check by quadrature.)

Rays looking down are cut where x < -X_CUT (the optical depth there exceeds 1e9 for any air: nothing beyond is
visible), so nothing overflows in float32.

Sunset: the part of the sun's disk below the horizon lights nothing (:mod:`warpsky.light.sun`: the
irradiance is the visible part's, and the in-scatter formula takes l_y = air_sine, which is exact for a sun whose
optical depth at every altitude is the vertical column times one air mass). The sky is black once the whole disk
has set (no twilight glow, which would need a round earth's air lit from below the horizon).
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.core.numerics import one_minus_exp_over_x
from warpsky.model.camera_rays import PinholeCamera, PrimaryRay
from warpsky.surfaces.plane import Ground

#: Riley 2004 Table 3: sea-level scattering coefficients [1/m] at 680, 550, 440 nm (our R, G, B).
RILEY_BETA_SEA_LEVEL = (5.8e-6, 1.35e-5, 3.31e-5)
#: Riley's scale height 1/γ [m].
RILEY_SCALE_HEIGHT = 8000.0
#: Downward rays stop where the dimensionless height change γ v_y K falls below -X_CUT.
X_CUT = 40.0
SERIES = 1.0e-4


#: Earth's mean radius [m], for the air mass at the horizon.
EARTH_RADIUS = 6.371e6


def horizon_air_mass(gamma: float) -> float:
    """Air mass at the horizon of an exponential atmosphere of scale height 1/``gamma`` [m] on a round earth:
    sqrt(pi R gamma / 2), Chapman's grazing-incidence limit (35.4 for 8 km; Kasten and Young's standard
    atmosphere gives 38)."""
    return math.sqrt(0.5 * math.pi * EARTH_RADIUS * gamma)


def air_sine(sun_y, gamma: float) -> np.ndarray:
    """The sine of the sun's elevation the air's optical depth is divided by: the air mass towards the sun is
    1 / air_sine, finite at every elevation.

    Riley's flat earth gives air mass 1 / sin(e), which diverges at the horizon. Above the elevation whose sine is
    mu_c = e_euler / M0 (M0 = :func:`horizon_air_mass`; 4.4 deg for an 8 km scale height) the flat-earth value is
    kept exactly; below it the sine is continued as mu_c exp(sin(e) / mu_c - 1), which meets it with the same
    slope at mu_c, gives air mass M0 at the horizon and falls smoothly towards 0 below it (a finite, continuous
    transmittance: the disk's visible fraction takes the light to 0).
    """
    sun_y = np.asarray(sun_y, dtype=np.float64)
    knee = math.e / horizon_air_mass(gamma)
    return np.where(sun_y >= knee, sun_y, knee * np.exp(np.minimum(sun_y, knee) / knee - 1.0))


def e_factor(x: np.ndarray) -> np.ndarray:
    """(1 - e^{-x}) / x with the limit 1 at x = 0 (float64)."""
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < SERIES
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x + x * x / 6.0, -np.expm1(-safe) / safe)


def _depth(beta_sl, gamma, h0, view_y, distance):
    """Optical depth of air from altitude h0 over ``distance`` (may be inf) at elevation sine view_y (Eq. 11)."""
    b = np.asarray(beta_sl, dtype=np.float64) * np.exp(-gamma * np.asarray(h0, dtype=np.float64))
    view_y = np.asarray(view_y, dtype=np.float64)
    distance = np.asarray(distance, dtype=np.float64)
    down = view_y < 0.0
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        cut = np.where(down, X_CUT / (gamma * np.where(down, -view_y, 1.0)), np.inf)
        k = np.minimum(distance, cut)
        up_to_infinity = (view_y > 0.0) & np.isinf(k)
        x = gamma * view_y * np.where(np.isinf(k), 1.0, k)
        finite = b * np.where(np.isinf(k), 1.0, k) * e_factor(x)
        depth = np.where(up_to_infinity, b / (gamma * np.where(view_y > 0.0, view_y, 1.0)),
                         np.where(np.isinf(k), np.inf, finite))
    return b, depth


def _depth_times_f(depth, q):
    """depth * F(depth |q|), F(z) = (1 - e^{-z}) / z, without 0 * inf: -> 1 / |q| for large depth."""
    z = depth * np.abs(q)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        large = np.where(np.isnan(z), False, z > 1.0)
        small = np.where(large, 1.0, np.where(np.isnan(z), 0.0, z))
        near = depth * np.where(small < SERIES, 1.0 - 0.5 * small, -np.expm1(-small) / np.maximum(small, 1e-300))
        far = -np.expm1(-np.where(large, z, 1.0)) / np.where(large, np.abs(q), 1.0)
    return np.where(large, far, near)


def inscatter(beta_sl, gamma, h0, view_y, sun_y, distance) -> np.ndarray:
    """∫_0^K β(h) T_eye T_sun dt per channel (multiply by I_s P(θ) for radiance); float64, broadcasting.
    ``sun_y`` is Riley's sun elevation sine, or a sunlight's ``air_sine`` (0 for ``sun_y <= 0``)."""
    sun_y = np.asarray(sun_y, dtype=np.float64)
    view_y = np.asarray(view_y, dtype=np.float64)
    b, depth = _depth(beta_sl, gamma, h0, view_y, distance)
    lit = sun_y > 0.0
    ly = np.where(lit, sun_y, 1.0)
    q = 1.0 - view_y / ly
    tau_s0 = b / (gamma * ly)
    # q < 0 (looking above the sun): the exponent tau_s0 + delta is the sun's depth at the far end plus the eye's,
    # a sum of positives (written as the difference it would cancel catastrophically in float32)
    distance = np.asarray(distance, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        far = np.where(np.isinf(distance), np.where(view_y > 0.0, 0.0, 1.0), np.exp(-gamma * view_y * distance))
        exponent = np.where(q >= 0.0, tau_s0, tau_s0 * far + depth)
    out = np.exp(-exponent) * _depth_times_f(depth, q)
    return np.where(lit, out, 0.0)


def transmittance(beta_sl, gamma, h0, view_y, distance) -> np.ndarray:
    """Transmittance of air from altitude h0 over ``distance`` along a ray of elevation sine view_y (Eq. 11)."""
    return np.exp(-_depth(beta_sl, gamma, h0, view_y, distance)[1])


def sun_transmittance(beta_sl, gamma, h, sun_y) -> np.ndarray:
    """Transmittance of sunlight from outside the atmosphere down to altitude h (Eq. 12) for sunlight from
    elevation sine ``sun_y``: the vertical column over :func:`~warpsky.media.air.analytic.air_sine`, finite and
    positive at every elevation and continuous through the horizon (the disk's visible fraction, not this, makes
    the night black)."""
    b = np.asarray(beta_sl, dtype=np.float64) * np.exp(-gamma * np.asarray(h, dtype=np.float64))
    return np.exp(-b / (gamma * air_sine(sun_y, gamma)))


def rayleigh(cos_theta) -> np.ndarray:
    return 3.0 / (16.0 * math.pi) * (1.0 + np.asarray(cos_theta, dtype=np.float64) ** 2)


# ---- the same on the device (float32) -------------------------------------------------------------------------

X_CUT_WP = wp.constant(X_CUT)
#: The distance [m] kernels take for infinity (a ray that never leaves the air).
INFINITE = wp.constant(1.0e30)


@wp.struct
class AnalyticAir:
    """The air of Riley's sky as kernels see it."""

    beta_sea_level: wp.vec3  # the Rayleigh gas's scattering (= extinction) coefficient at sea level [1/m], RGB
    gamma: float  # 1 / scale height [1/m]
    camera_altitude: float  # the eye's altitude above sea level [m]
    mixed: int  # 1: aerosols or ozone too (:mod:`~warpsky.media.air.mixture`), 0: Riley's closed form alone
    mie_extinction: wp.vec3  # the aerosols' at sea level [1/m]
    mie_albedo: wp.vec3  # their single-scattering albedo
    mie_gamma: float  # 1 / their scale height [1/m]
    mie_g: float  # their Henyey-Greenstein g
    ozone: wp.vec3  # the ozone layer's peak absorption [1/m]
    ozone_altitude: float  # [m above sea level]
    ozone_width: float  # [m]


def analytic_air(atmosphere, camera_position) -> AnalyticAir:
    """Kernel view of a :class:`~warpsky.model.scene.Atmosphere` seen from ``camera_position`` (world, metres)."""
    out = AnalyticAir()
    out.beta_sea_level = wp.vec3(*np.asarray(atmosphere.beta_sea_level, dtype=np.float64).tolist())
    out.gamma = float(atmosphere.gamma)
    out.camera_altitude = float(camera_position[1] + atmosphere.altitude)
    out.mixed = int(atmosphere.mixed)
    extinction = atmosphere.mie_scattering + atmosphere.mie_absorption
    out.mie_extinction = wp.vec3(*extinction.tolist())
    out.mie_albedo = wp.vec3(*np.divide(atmosphere.mie_scattering, extinction, out=np.zeros(3),
                                        where=extinction > 0.0).tolist())
    out.mie_gamma = float(1.0 / atmosphere.mie_scale_height)
    out.mie_g = float(atmosphere.mie_g)
    out.ozone = wp.vec3(*atmosphere.ozone_absorption.tolist())
    out.ozone_altitude = float(atmosphere.ozone_altitude)
    out.ozone_width = float(atmosphere.ozone_width)
    return out


@wp.func
def air_depth(beta_sl: wp.vec3, gamma: float, h0: float, view_y: float, distance: float) -> wp.vec3:
    """Optical depth of air from altitude h0 over ``distance`` [m] (1e30 = infinity) at elevation sine view_y."""
    b = beta_sl * wp.exp(-gamma * h0)
    k = distance
    if view_y < 0.0:
        k = wp.min(k, X_CUT_WP / (gamma * (-view_y)))
    if view_y > 0.0 and distance >= 1.0e29:
        return b / (gamma * view_y)
    return b * (k * one_minus_exp_over_x(gamma * view_y * k))


@wp.func
def air_inscatter(beta_sl: wp.vec3, gamma: float, h0: float, view_y: float, sun_y: float, distance: float) -> wp.vec3:
    """In-scatter integral over [0, distance] per channel (see the module docstring) for a sun of air sine
    ``sun_y`` (the sunlight's ``air_sine``); 0 for ``sun_y <= 0``."""
    out = wp.vec3(0.0)
    if sun_y <= 0.0:
        return out
    b = beta_sl * wp.exp(-gamma * h0)
    depth = air_depth(beta_sl, gamma, h0, view_y, distance)
    q = 1.0 - view_y / sun_y
    far = float(1.0)  # e^{-gamma v_y K}: density at the far end relative to the eye
    if view_y > 0.0:
        far = wp.exp(-gamma * view_y * wp.min(distance, 1.0e29))
    for c in range(3):
        tau_s0 = b[c] / (gamma * sun_y)
        exponent = tau_s0
        if q < 0.0:
            # looking above the sun: the sun's depth at the far end plus the eye's (no cancellation)
            exponent = tau_s0 * far + depth[c]
        z = depth[c] * wp.abs(q)
        g = float(0.0)
        if z > 1.0:
            g = (1.0 - wp.exp(-z)) / wp.abs(q)
        else:
            g = depth[c] * one_minus_exp_over_x(z)
        out[c] = wp.exp(-exponent) * g
    return out


@wp.struct
class AirRay:
    """One eye ray's stretch of air: where it starts and how far the air reaches along it."""

    altitude: float  # of the ray's start above sea level [m]
    t_end: float  # [m] to where the air ends: sea level or the ground plane below, else INFINITE
    split: float  # [m] to the media's representative depth (Riley §4, Fig. 7), at most t_end


@wp.func
def air_ray(air: AnalyticAir, cam: PinholeCamera, ray: PrimaryRay, has_ground: int, ground: Ground,
            media_depth: float) -> AirRay:
    """The air along ``ray`` (from its start, :func:`~warpsky.model.camera_rays.primary_ray`), split at the media's
    depth ``media_depth`` along the view axis [m] (the far plane or beyond: no media, the split is the air's end)."""
    out = AirRay()
    height = ray.origin[1]  # of the ray's start above the eye (orthographic)
    out.altitude = air.camera_altitude + height
    # where the air ends: the ground plane, else infinity
    out.t_end = INFINITE
    if ray.direction[1] < 0.0:
        # the air ends at sea level: below it lies a black surface unless a ground plane comes first
        out.t_end = wp.max(out.altitude, 0.0) / (-ray.direction[1])
    if has_ground != 0:
        if ray.direction[1] < 0.0 and ground.offset < height:
            out.t_end = wp.min(out.t_end, (ground.offset - height) / ray.direction[1])
    # the media's representative depth splits the air into a front and a back part (Riley §4, Fig. 7)
    out.split = out.t_end
    if media_depth < cam.far:
        out.split = wp.min(media_depth / ray.cos_axis, out.t_end)
    return out
