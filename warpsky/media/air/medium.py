"""The atmosphere as a participating medium of the path tracer.

Riley's gas scatters with beta(h) = beta_sl e^{-gamma h} [1/m] (Riley 2004, Eq. 10), extinction = scattering
(albedo 1), Rayleigh phase; aerosols (where the atmosphere has any) scatter and absorb with their own scale height
and a Henyey-Greenstein phase, an ozone layer absorbs (its tent profile, :mod:`~warpsky.media.air.mixture`).
Kernels see it as :class:`Air`, at camera-relative points, and a point's scattering as :class:`AirPart`.

The earth is Riley's flat one (``round`` 0: altitude = camera altitude + y) or a sphere of sea level
(``round`` 1, :class:`~warpsky.media.air.round_earth_kernels.RoundAir`): its centre lies at (0, -(R + camera altitude),
0) from the camera, a point's local vertical points away from it, and its altitude is a + s^2 / (sqrt((R + a)^2 + s^2) +
R + a), a its height above the camera's sea level and s its horizontal distance from the camera, without the
cancellation of |p - centre| - R in float32. The round air ends below at its floor's sphere and above at its top.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.numerics import mean3
from warpsky.media.air.analytic import AnalyticAir
from warpsky.media.air.round_earth_kernels import RoundAir, round_struct, sphere_below, top_distance
from warpsky.optics.phase import hg_pdf, hg_sample_cos, phase_hg, phase_rayleigh, rayleigh_pdf, rayleigh_sample_cos


@wp.struct
class Air:
    """Riley's exponential atmosphere as a medium of the path tracer (enabled = 0: no air).

    Extinction = scattering = beta_sl e^{-gamma h} [1/m] with h the altitude of a camera-relative point
    (:func:`altitude`), Rayleigh phase. Its majorant over a stretch of ray is the density at the stretch's lowest
    point; stretches span about ``band`` metres of height. On a flat earth the air above the height where the
    remaining optical depth to space falls below 1e-6 is treated as vacuum (a relative bias below 1e-6), on a round
    one the air above ``planet.top``, so upward rays end.
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
    round: int  # 1: a round earth (``planet``), 0: Riley's flat earth
    planet: RoundAir  # the round earth's shell and its optical depths to the top (a placeholder on a flat earth)
    floor_ground: int  # 1: the round earth's floor is the scene's ground plane (its albedo), 0: a black sea level


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
    out.round = 0
    return out


@wp.func
def ozone_profile(air: Air, h: float) -> float:
    """The ozone layer's density relative to its peak at altitude ``h`` [m above sea level]."""
    return wp.max(1.0 - wp.abs(h - air.ozone_altitude) / air.ozone_width, 0.0)


@wp.func
def altitude(air: Air, p: wp.vec3) -> float:
    """Altitude [m above sea level] of the camera-relative point ``p``."""
    a = air.camera_altitude + p[1]
    if air.round == 0:
        return a
    s2 = p[0] * p[0] + p[2] * p[2]
    r = air.planet.radius + a
    return a + s2 / (wp.sqrt(r * r + s2) + r)


@wp.func
def vertical(air: Air, p: wp.vec3) -> wp.vec3:
    """The unit local vertical at the camera-relative point ``p`` (+y on a flat earth)."""
    if air.round == 0:
        return wp.vec3(0.0, 1.0, 0.0)
    return wp.normalize(wp.vec3(p[0], p[1] + (air.planet.radius + air.camera_altitude), p[2]))


@wp.func
def coefficient_at(air: Air, h: float) -> wp.vec3:
    """Air's extinction at altitude ``h`` [m above sea level] [1/m]."""
    out = air.beta_sl * wp.exp(-air.gamma * h)
    if air.mixed != 0:
        out += air.mie_extinction * wp.exp(-air.mie_gamma * h) + air.ozone * ozone_profile(air, h)
    return out


@wp.func
def air_coefficient(air: Air, p: wp.vec3) -> wp.vec3:
    """Air's extinction at the camera-relative point ``p`` [1/m] (the Rayleigh gas's alone: its scattering)."""
    return coefficient_at(air, altitude(air, p))


@wp.func
def air_bound(air: Air, lowest: float, highest: float) -> float:
    """The largest extinction [1/m] of any channel between altitudes ``lowest`` and ``highest`` [m above sea
    level]: the exponential constituents' at the lowest point, plus the ozone layer's largest density over the
    stretch."""
    out = wp.max(coefficient_at(air, lowest))
    if air.mixed != 0:
        peak = wp.max(ozone_profile(air, lowest), ozone_profile(air, highest))
        if lowest <= air.ozone_altitude and highest >= air.ozone_altitude:
            peak = 1.0
        out += wp.max(air.ozone) * peak
    return out


@wp.func
def air_part(air: Air, p: wp.vec3) -> AirPart:
    """Air's scattering at the camera-relative point ``p`` per constituent; zero without air."""
    out = AirPart()
    out.rayleigh = wp.vec3(0.0)
    out.mie = wp.vec3(0.0)
    out.g = air.mie_g
    if air.enabled != 0:
        h = altitude(air, p)
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
def air_scattering(air: Air, p: wp.vec3) -> wp.vec3:
    """Air's scattering coefficient at the camera-relative point ``p`` [1/m]; zero without air."""
    return part_total(air_part(air, p))


@wp.func
def sea_level_distance(air: Air, origin: wp.vec3, direction: wp.vec3) -> float:
    """Distance [m] from ``origin`` along a downward ``direction`` to sea level, where the air ends."""
    return wp.max(air.camera_altitude + origin[1], 0.0) / (-direction[1])


#: Air stretches span this fraction of the scale height (its majorant is taken at each stretch's lowest point).
BAND_SCALE_HEIGHTS = 0.1


def air_floor(scene) -> tuple[float, bool]:
    """(altitude [m above sea level], whether it is the ground plane) of what ends ``scene``'s air below: the ground
    plane where it lies at or above sea level, else sea level."""
    ground, atmosphere = scene.ground, scene.atmosphere
    if ground is not None and ground.height + atmosphere.altitude >= 0.0:
        return float(ground.height + atmosphere.altitude), True
    return 0.0, False


def no_planet(device) -> RoundAir:
    """A placeholder :class:`RoundAir` for a flat earth (a one-entry table kept on ``device``)."""
    out = RoundAir()
    out.depth = device_buffers.upload("air:no_planet", np.zeros((1, 1, 3), np.float32), wp.vec3, device)
    return out


def air_struct(scene, camera_position, device, *, air: bool = True) -> Air:
    """Kernel view of ``scene``'s :class:`~warpsky.model.scene.Atmosphere` seen from ``camera_position`` on
    ``device`` (no air without one, or when ``air`` is False); a round earth's shell and optical depth table are
    built there once per air and floor (:func:`~warpsky.media.air.round_earth_kernels.round_struct`)."""
    atmosphere = scene.atmosphere if air else None
    out = Air()
    out.enabled = int(atmosphere is not None)
    out.round = 0
    out.floor_ground = 0
    out.planet = no_planet(device)
    if atmosphere is not None:
        out.beta_sl = wp.vec3(*atmosphere.beta_sea_level.tolist())
        out.gamma = float(atmosphere.gamma)
        out.camera_altitude = float(camera_position[1] + atmosphere.altitude)
        out.band = float(BAND_SCALE_HEIGHTS * min(atmosphere.scale_height, atmosphere.mie_scale_height
                                                  if atmosphere.has_aerosols else atmosphere.scale_height))
        out.mixed = int(atmosphere.mixed)
        extinction = atmosphere.mie_scattering + atmosphere.mie_absorption
        out.mie_scattering = wp.vec3(*atmosphere.mie_scattering.tolist())
        out.mie_extinction = wp.vec3(*extinction.tolist())
        out.mie_gamma = float(1.0 / atmosphere.mie_scale_height)
        out.mie_g = float(atmosphere.mie_g)
        out.ozone = wp.vec3(*atmosphere.ozone_absorption.tolist())
        out.ozone_altitude = float(atmosphere.ozone_altitude)
        out.ozone_width = float(atmosphere.ozone_width)
        if atmosphere.round:
            floor, is_ground = air_floor(scene)
            out.round = 1
            out.floor_ground = int(is_ground)
            out.planet = round_struct(atmosphere, floor, device)
    return out


@wp.func
def top_entry(ra: RoundAir, h0: float, mu0: float) -> float:
    """Distance [m] along a ray from altitude ``h0`` of elevation sine ``mu0`` to where it enters the top of a round
    earth's air: 0 from inside it, -1 when it never does."""
    if h0 <= ra.top:
        return 0.0
    return sphere_below(ra.radius, h0, ra.top, mu0)


@wp.func
def top_exit(ra: RoundAir, h0: float, mu0: float) -> float:
    """Distance [m] along a ray from altitude ``h0`` of elevation sine ``mu0`` to where it leaves a round earth's
    air through its top for good (0 when it never is inside)."""
    if h0 <= ra.top:
        return top_distance(ra, h0, mu0)
    entry = top_entry(ra, h0, mu0)
    if entry < 0.0:
        return 0.0
    r0 = ra.radius + h0
    c = (h0 - ra.top) * (2.0 * ra.radius + h0 + ra.top)
    return -r0 * mu0 + wp.sqrt(wp.max(r0 * r0 * mu0 * mu0 - c, 0.0))
