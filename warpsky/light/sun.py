"""The sunlight a scene's media and ground receive: one host-side model of the sun setting, used by every technique
and pass (kernels get it through :func:`~warpsky.light.sun.sun_struct`).

Where a scene has a horizon (a ground plane, or air: a flat earth's air hides whatever lies below the horizon), the
sun's disk sets gradually behind it. The disk is treated as a flat circle of angular radius r (half the
DistantLight's ``inputs:angle``; exact to O(r^2), 0.1% for the real sun) centred at elevation e, and the horizon as
the chord at elevation 0. The visible part is the circular segment above the chord:

* its area fraction  f(e) = (r^2 acos(-e/r) + e sqrt(r^2 - e^2)) / (pi r^2)  for |e| < r, 0 below -r, 1 above +r
  (a sun with no disk steps from 0 to 1 at e = 0, the limit r -> 0);
* its centroid, (2/3) (r^2 - e^2)^(3/2) / (f pi r^2) above the disk's centre.

The sunlight is then a light along the centroid of the visible part with the disk's irradiance times f: every
technique lights the media and the ground with whatever is left (a point on the ground sees the visible part at
the centroid's elevation, whose sine is its cosine factor) and a sun is "up" exactly when f > 0, the same in every
kernel. Both go continuously to 0 as the disk's top sinks below the horizon.

The atmosphere's transmittance towards the sun uses :func:`air_sine`: a finite air mass at grazing elevations.
Without a horizon (no ground, no air) the sun lights from any direction, unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.media.air.analytic import air_sine
from warpsky.media.air.round_earth import air_lit, scene_floor


def visible_fraction(elevation: float, radius: float) -> float:
    """Fraction of a sun disk of angular ``radius`` [rad] centred at ``elevation`` [rad] above a flat horizon."""
    if radius <= 0.0:
        return 1.0 if elevation > 0.0 else 0.0
    if elevation >= radius:
        return 1.0
    if elevation <= -radius:
        return 0.0
    x = elevation / radius
    return min(max((math.acos(-x) + x * math.sqrt(1.0 - x * x)) / math.pi, 0.0), 1.0)


def visible_elevation(elevation: float, radius: float) -> float:
    """Elevation [rad] of the centroid of the part of the disk above the horizon (``elevation`` when all of it,
    or none, is visible)."""
    fraction = visible_fraction(elevation, radius)
    if fraction <= 0.0 or fraction >= 1.0 or radius <= 0.0:
        return elevation
    moment = (2.0 / 3.0) * (radius * radius - elevation * elevation) ** 1.5
    return elevation + moment / (fraction * math.pi * radius * radius)


@dataclass(frozen=True)
class Sunlight:
    """The light a scene's sun gives its media and ground, after the horizon has hidden part of its disk.

    Attributes:
        direction: Unit vector towards the centroid of the disk's visible part (world axes).
        irradiance: RGB irradiance of the visible part at normal incidence (the sun's times ``visible``).
        visible: Fraction of the disk's area above the horizon, in [0, 1] (1 without a horizon).
        disk_direction: Unit vector towards the disk's centre.
        disk_irradiance: RGB irradiance of the whole disk (drawn as the disk, clipped by the horizon pixel by
            pixel).
        angular_diameter: Of the disk [rad].
        air_sine: Sine of elevation for the air's optical depth towards the sun (:func:`air_sine`; the direction's
            y without air).
    """

    direction: np.ndarray
    irradiance: np.ndarray
    visible: float
    disk_direction: np.ndarray
    disk_irradiance: np.ndarray
    angular_diameter: float
    air_sine: float

    @property
    def lit(self) -> bool:
        """Whether any light arrives: part of the disk is visible and the sun shines."""
        return self.visible > 0.0 and float(np.max(self.irradiance)) > 0.0


def toward_elevation(direction: np.ndarray, elevation: float) -> np.ndarray:
    """``direction`` turned in its vertical plane to ``elevation`` [rad] (the same azimuth)."""
    horizontal = np.array([direction[0], 0.0, direction[2]], dtype=np.float64)
    norm = float(np.linalg.norm(horizontal))
    if norm <= 0.0:
        return np.asarray(direction, dtype=np.float64)
    return horizontal / norm * math.cos(elevation) + np.array([0.0, math.sin(elevation), 0.0])


def sun_sunlight(sun, *, horizon: bool, gamma: float | None = None) -> Sunlight | None:
    """The :class:`Sunlight` of a :class:`~warpsky.model.scene.Sun` (None: None) above a flat horizon when
    ``horizon``; ``gamma`` [1/m] is the air's inverse scale height (None: no air)."""
    if sun is None:
        return None
    direction = np.asarray(sun.direction, dtype=np.float64)
    irradiance = np.asarray(sun.irradiance, dtype=np.float64) * sun.transmittance
    visible, light = 1.0, direction
    if horizon:
        radius = 0.5 * float(sun.angular_diameter)
        visible = visible_fraction(sun.elevation, radius)
        if 0.0 < visible < 1.0:
            light = toward_elevation(direction, visible_elevation(sun.elevation, radius))
    sine = float(light[1]) if gamma is None else float(air_sine(light[1], gamma))
    return Sunlight(light, irradiance * visible, visible, direction, irradiance, float(sun.angular_diameter), sine)


def round_sunlight(sun, atm, floor: float) -> Sunlight | None:
    """The :class:`Sunlight` of ``sun`` over a round earth: the whole disk along its centre, lit while any of it
    stands above the horizon seen from the top of the air (:func:`~warpsky.media.air.round_earth.air_lit`; each point
    takes its own horizon's share in its transmittance)."""
    if sun is None:
        return None
    direction = np.asarray(sun.direction, dtype=np.float64)
    irradiance = np.asarray(sun.irradiance, dtype=np.float64) * sun.transmittance
    visible = 1.0 if air_lit(atm, floor, sun.elevation, 0.5 * float(sun.angular_diameter)) else 0.0
    return Sunlight(direction, irradiance * visible, visible, direction, irradiance, float(sun.angular_diameter),
                    float(direction[1]))


def has_horizon(scene) -> bool:
    """Whether something hides a sun below the horizon: a ground plane, or air."""
    return scene.ground is not None or scene.atmosphere is not None


def sunlight(scene) -> Sunlight | None:
    """The :class:`Sunlight` of ``scene`` (None without a sun); over a round earth the whole disk, each point of the
    air taking its own horizon's share (:func:`round_sunlight`)."""
    atmosphere = scene.atmosphere
    if atmosphere is not None and atmosphere.round:
        return round_sunlight(scene.sun, atmosphere, scene_floor(scene))
    gamma = atmosphere.gamma if atmosphere is not None else None
    return sun_sunlight(scene.sun, horizon=has_horizon(scene), gamma=gamma)


def lights_air(atmosphere, light: Sunlight | None) -> bool:
    """Whether ``light`` lights the air of ``atmosphere``: a lit sun, above the flat earth's horizon (a round
    earth's high air sees the sun after it has set: :func:`sunlight` says so there)."""
    return light is not None and light.lit and (atmosphere.round or light.air_sine > 0.0)


def light_elevation_sine(sun) -> float:
    """Sine of the elevation the sunlight of ``sun`` comes from above a horizon (the visible part's centroid):
    where the atmosphere's transmittance towards it is taken."""
    return float(sun_sunlight(sun, horizon=True).direction[1])


def visible_sun(sun):
    """A :class:`~warpsky.model.scene.Sun` without a disk giving the sunlight of ``sun`` above a horizon, for a
    scene that loses its horizon (the ground drawn by another pass); None when none of the disk is visible. Its
    transmittance through the air is ``sun``'s."""
    light = sun_sunlight(sun, horizon=True)
    if light is None or light.visible <= 0.0:
        return None
    irradiance = np.asarray(sun.irradiance, dtype=np.float64) * light.visible
    return dataclasses.replace(sun, direction=light.direction, irradiance=irradiance, angular_diameter=0.0)


def above_air(scene):
    """``scene`` with its sun as it arrives at the top of the atmosphere (transmittance ones), for a technique
    that traces the air itself or a light model that needs the sun before the air (the sky's own light)."""
    sun = scene.sun
    if sun is None or np.all(sun.transmittance == 1.0):
        return scene
    return dataclasses.replace(scene, sun=dataclasses.replace(sun, transmittance=np.ones(3)))


# ---- the sunlight as kernels see it ---------------------------------------------------------------------------


@wp.struct
class Sun:
    """The sunlight as kernels see it (:class:`~warpsky.light.sun.Sunlight`; ``lit`` 0: none arrives).

    Kernels light with ``irradiance`` along ``direction`` wherever ``lit`` is set, whatever the elevation: the
    horizon has already been folded in on the host."""

    direction: wp.vec3  # unit vector towards the light: the centroid of the disk's visible part (world axes)
    irradiance: wp.vec3  # of the visible part, at normal incidence, RGB
    air_sine: float  # the air's optical depth towards the sun is its vertical column / air_sine (finite air mass)
    disk_direction: wp.vec3  # unit vector towards the disk's centre
    disk_radiance: wp.vec3  # of the disk where it is seen, RGB [irradiance/sr] (0 for a sun without a disk)
    cos_radius: float  # cosine of the disk's angular radius (2: no disk)
    lit: int


def sun_disk(angular_diameter: float) -> tuple[float, float]:
    """(cos of the angular radius, solid angle [sr]) of a sun disk of ``angular_diameter`` [rad]; (2, 1) for none."""
    radius = 0.5 * angular_diameter
    if radius <= 0.0:
        return 2.0, 1.0
    return math.cos(radius), 2.0 * math.pi * (1.0 - math.cos(radius))


def sun_struct(light: Sunlight | None, unlit_direction: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> Sun:
    """Kernel view of a :class:`~warpsky.light.sun.Sunlight` (or None: unlit, pointing along
    ``unlit_direction``)."""
    out = Sun()
    unlit = np.asarray(unlit_direction, dtype=np.float64)
    direction = light.direction if light is not None else unlit
    irradiance = light.irradiance if light is not None else np.zeros(3)
    out.direction = wp.vec3(*np.asarray(direction, dtype=np.float64).tolist())
    out.irradiance = wp.vec3(*np.asarray(irradiance, dtype=np.float64).tolist())
    out.air_sine = float(light.air_sine) if light is not None else float(unlit[1])
    out.disk_direction = wp.vec3(*np.asarray(light.disk_direction if light is not None else unlit).tolist())
    out.cos_radius, solid_angle = sun_disk(light.angular_diameter if light is not None else 0.0)
    disk = light.disk_irradiance / solid_angle if light is not None and out.cos_radius <= 1.0 else np.zeros(3)
    out.disk_radiance = wp.vec3(*np.asarray(disk, dtype=np.float64).tolist())
    out.lit = int(light is not None and light.lit)
    return out
