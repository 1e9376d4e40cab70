"""The analytic sky as a light: its radiance over the upper hemisphere, for the passes that light surfaces and media
with a uniform-equivalent sky (the surfaces, fog and deck passes).

The sky's radiance along a direction above the horizon is the air to infinity as the sky pass draws it
(:func:`~warpsky.media.air.multiple_kernels.air_radiance`: Riley's single scattering E_sun P_R(theta) inscatter(v) plus
the multiple-scattering table's light), with the unreddened sun E_sun. Averaged on an equal-area grid of the upper
hemisphere it gives the mean radiance and E / pi, the uniform radiance that gives a horizontal surface the sky's
irradiance.
"""

from __future__ import annotations

import numpy as np

from warpsky.light.dome import hemisphere_directions, upper_hemisphere
from warpsky.light.sun import lights_air, sunlight
from warpsky.media.air.multiple_kernels import air_radiance


def sky_hemisphere(scene, samples: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """(mean radiance, E / pi) [RGB] of the analytic sky's upper hemisphere seen at the camera's altitude; zeros
    without an atmosphere or with the sun set (the night sky is black, as the sky pass draws it)."""
    light = sunlight(scene)
    atmosphere = scene.atmosphere
    if atmosphere is None or not lights_air(atmosphere, light):
        return np.zeros(3), np.zeros(3)
    directions = hemisphere_directions(samples, upper=True).reshape(-1, 3)
    altitude = float(scene.camera.position[1]) + atmosphere.altitude
    radiance = air_radiance(scene, light, altitude, directions)
    return radiance.mean(axis=0), 2.0 * (radiance * directions[:, 1:2]).mean(axis=0)


def sky_light(scene, *, analytic: bool) -> tuple[np.ndarray, np.ndarray]:
    """(mean radiance, E / pi) [RGB] of everything above the horizon that lights the scene diffusely: the dome's
    upper hemisphere, plus the analytic sky's with ``analytic`` (a frame with a sky pass)."""
    mean, cosine = np.zeros(3), np.zeros(3)
    if scene.dome is not None:
        mean, cosine = upper_hemisphere(scene.dome)
    if analytic:
        sky_mean, sky_cosine = sky_hemisphere(scene)
        mean, cosine = mean + sky_mean, cosine + sky_cosine
    return mean, cosine
