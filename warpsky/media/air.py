"""The atmosphere as a participating medium of the path tracer.

Riley's gas scatters with beta(h) = beta_sl e^{-gamma h} [1/m] (Riley 2004, Eq. 10), extinction = scattering
(albedo 1), Rayleigh phase; aerosols (where the atmosphere has any) scatter and absorb with their own scale height
and a Henyey-Greenstein phase, an ozone layer absorbs (its tent profile, :mod:`~warpsky.media.air_mixture`).
Kernels see it as :class:`Air`, in camera-relative heights, and a point's scattering as :class:`AirPart`.
"""

from __future__ import annotations

import warp as wp

from warpsky.media.air_analytic import AnalyticAir
from warpsky.numerics import mean3
from warpsky.optics.phase import hg_pdf, hg_sample_cos, phase_hg, phase_rayleigh, rayleigh_pdf, rayleigh_sample_cos


@wp.struct
class Air:
    """Riley's exponential atmosphere as a medium of the path tracer (enabled = 0: no air).

    Extinction = scattering = beta_sl e^{-gamma h} [1/m] with h = camera_altitude + y (camera-relative y), Rayleigh
    phase. Its majorant over a stretch of ray is the density at the stretch's lowest point; stretches span ``band``
    metres of height. Above the height where the remaining optical depth to space falls below 1e-6 the air is
    treated as vacuum (a relative bias below 1e-6), so upward rays end.
    """

    enabled: int
    beta_sl: wp.vec3
    gamma: float
    camera_altitude: float
    band: float
    mixed: int  # 1: aerosols or ozone as well
    mie_scattering: wp.vec3  # at sea level [1/m]
    mie_extinction: wp.vec3
    mie_gamma: float
    mie_g: float
    ozone: wp.vec3  # peak absorption [1/m]
    ozone_altitude: float  # [m above sea level]
    ozone_width: float


@wp.struct
class AirPart:
    """The air's scattering at a point, per constituent [1/m], and the aerosols' asymmetry."""

    rayleigh: wp.vec3
    mie: wp.vec3
    g: float


@wp.func
def as_analytic(air: Air) -> AnalyticAir:
    """The same air as the analytic sky's struct (its closed-form depths and columns, absolute altitudes)."""
    out = AnalyticAir()
    out.beta_sea_level = air.beta_sl
    out.gamma = air.gamma
    out.camera_altitude = air.camera_altitude
    out.mixed = air.mixed
    out.mie_extinction = air.mie_extinction
    out.mie_gamma = air.mie_gamma
    out.mie_g = air.mie_g
    out.ozone = air.ozone
    out.ozone_altitude = air.ozone_altitude
    out.ozone_width = air.ozone_width
    return out


@wp.func
def no_air() -> Air:
    """Air that is off: the media tracked alone."""
    out = Air()
    out.enabled = 0
    return out


@wp.func
def ozone_profile(air: Air, h: float) -> float:
    """The ozone layer's density relative to its peak at altitude ``h`` [m above sea level]."""
    return wp.max(1.0 - wp.abs(h - air.ozone_altitude) / air.ozone_width, 0.0)


@wp.func
def air_coefficient(air: Air, y: float) -> wp.vec3:
    """Air's extinction at camera-relative height y [1/m] (the Rayleigh gas's alone: its scattering)."""
    h = air.camera_altitude + y
    out = air.beta_sl * wp.exp(-air.gamma * h)
    if air.mixed != 0:
        out += air.mie_extinction * wp.exp(-air.mie_gamma * h) + air.ozone * ozone_profile(air, h)
    return out


@wp.func
def air_bound(air: Air, lowest: float, highest: float) -> float:
    """The largest extinction [1/m] of any channel between camera-relative heights ``lowest`` and ``highest``: the
    exponential constituents' at the lowest point, plus the ozone layer's largest density over the stretch."""
    out = wp.max(air_coefficient(air, lowest))
    if air.mixed != 0:
        lo = air.camera_altitude + lowest
        hi = air.camera_altitude + highest
        peak = wp.max(ozone_profile(air, lo), ozone_profile(air, hi))
        if lo <= air.ozone_altitude and hi >= air.ozone_altitude:
            peak = 1.0
        out += wp.max(air.ozone) * peak
    return out


@wp.func
def air_part(air: Air, y: float) -> AirPart:
    """Air's scattering at camera-relative height y per constituent; zero without air."""
    out = AirPart()
    out.rayleigh = wp.vec3(0.0)
    out.mie = wp.vec3(0.0)
    out.g = air.mie_g
    if air.enabled != 0:
        h = air.camera_altitude + y
        out.rayleigh = air.beta_sl * wp.exp(-air.gamma * h)
        if air.mixed != 0:
            out.mie = air.mie_scattering * wp.exp(-air.mie_gamma * h)
    return out


@wp.func
def scaled_part(part: AirPart, weight: float) -> AirPart:
    out = part
    out.rayleigh = part.rayleigh * weight
    out.mie = part.mie * weight
    return out


@wp.func
def part_total(part: AirPart) -> wp.vec3:
    """The air's summed scattering [1/m]."""
    return part.rayleigh + part.mie


@wp.func
def part_phase(part: AirPart, cos_theta: float) -> wp.vec3:
    """sum_c sigma_s,c P_c(cos_theta) [1/(m sr)] of the air's constituents."""
    return part.rayleigh * phase_rayleigh(cos_theta) + part.mie * phase_hg(cos_theta, part.g)


@wp.func
def part_pdf(part: AirPart, cos_theta: float) -> float:
    """The air's share of a mixture's sampling density: each constituent's mean scattering times its phase's."""
    return mean3(part.rayleigh) * rayleigh_pdf(cos_theta) + mean3(part.mie) * hg_pdf(cos_theta, part.g)


@wp.func
def part_sample_cos(part: AirPart, target: float, u: float) -> float:
    """cos theta of a sample of the air's phase, the constituent picked by ``target`` in [0, mean scattering)
    (the Rayleigh gas first), then ``u``."""
    if target < mean3(part.rayleigh):
        return rayleigh_sample_cos(u)
    return hg_sample_cos(part.g, u)


@wp.func
def air_scattering(air: Air, y: float) -> wp.vec3:
    """Air's scattering coefficient at camera-relative height y [1/m]; zero without air."""
    return part_total(air_part(air, y))


@wp.func
def sea_level_distance(air: Air, origin: wp.vec3, direction: wp.vec3) -> float:
    """Distance [m] from ``origin`` along a downward ``direction`` to sea level, where the air ends."""
    return wp.max(air.camera_altitude + origin[1], 0.0) / (-direction[1])


#: Air stretches span this fraction of the scale height (its majorant is taken at each stretch's lowest point).
BAND_SCALE_HEIGHTS = 0.1


def air_struct(atmosphere, camera_position) -> Air:
    """Kernel view of a :class:`~warpsky.scene.model.Atmosphere` seen from ``camera_position`` (None: no air)."""
    air = Air()
    air.enabled = int(atmosphere is not None)
    if atmosphere is not None:
        air.beta_sl = wp.vec3(*atmosphere.beta_sea_level.tolist())
        air.gamma = float(atmosphere.gamma)
        air.camera_altitude = float(camera_position[1] + atmosphere.altitude)
        air.band = float(BAND_SCALE_HEIGHTS * min(atmosphere.scale_height, atmosphere.mie_scale_height
                                                  if atmosphere.has_aerosols else atmosphere.scale_height))
        air.mixed = int(atmosphere.mixed)
        extinction = atmosphere.mie_scattering + atmosphere.mie_absorption
        air.mie_scattering = wp.vec3(*atmosphere.mie_scattering.tolist())
        air.mie_extinction = wp.vec3(*extinction.tolist())
        air.mie_gamma = float(1.0 / atmosphere.mie_scale_height)
        air.mie_g = float(atmosphere.mie_g)
        air.ozone = wp.vec3(*atmosphere.ozone_absorption.tolist())
        air.ozone_altitude = float(atmosphere.ozone_altitude)
        air.ozone_width = float(atmosphere.ozone_width)
    return air
