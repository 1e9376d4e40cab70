"""Riley's exponential atmosphere as a participating medium of the path tracer.

Air scatters with beta(h) = beta_sl e^{-gamma h} [1/m] (Riley 2004, Eq. 10), extinction = scattering (albedo 1),
Rayleigh phase. Kernels see it as :class:`Air`, in camera-relative heights.
"""

from __future__ import annotations

import warp as wp


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


@wp.func
def no_air() -> Air:
    """Air that is off: the media tracked alone."""
    out = Air()
    out.enabled = 0
    return out


@wp.func
def air_coefficient(air: Air, y: float) -> wp.vec3:
    """Air's extinction (= scattering) at camera-relative height y [1/m]."""
    return air.beta_sl * wp.exp(-air.gamma * (air.camera_altitude + y))


@wp.func
def air_scattering(air: Air, y: float) -> wp.vec3:
    """Air's scattering coefficient at camera-relative height y [1/m]; zero without air."""
    out = wp.vec3(0.0)
    if air.enabled != 0:
        out = air_coefficient(air, y)
    return out


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
        air.band = float(BAND_SCALE_HEIGHTS * atmosphere.scale_height)
    return air
