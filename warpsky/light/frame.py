"""The light of one frame, worked out once and handed to every technique and pass.

A frame whose air is drawn by a pass (the sky pass: Riley's analytic air around the media) lights its media, layers
and scenery through that air: the sun arrives reddened by the air above them (Riley 2004, Eq. 12). The frame does
not hand them a reddened sun. It hands the sun as it arrives at the top of the atmosphere, with the air's
transmittance towards it in :attr:`~warpsky.model.scene.Sun.transmittance` (:meth:`FrameLight.lit_at_media`,
:meth:`FrameLight.lit_at`), taken once per frame. The kernels get the product (:func:`~warpsky.light.sun.sunlight`);
whoever needs the sun before the air (a technique tracing the air, the sky's own light) takes
:func:`~warpsky.light.sun.above_air`, which drops the factor instead of dividing it back out.

One transmittance serves all the media: it is taken at their centre's altitude (:func:`media_altitude`); the
variation across a cloud a few km tall is below 1 % at sun elevations above about 5°. The stratiform layers take it
at each layer's mid altitude. The elevation is the sunlight's (:func:`~warpsky.light.sun.light_elevation_sine`),
so a setting sun stays lit down to the last sliver of its disk, which the kernels weigh by its visible fraction.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from warpsky.light.sky import sky_light
from warpsky.light.sun import light_elevation_sine
from warpsky.media.air.mixture import sunlight_transmittance


def media_altitude(scene) -> float:
    """Altitude above sea level [m] at which the media (else the ground, else the camera) receive sunlight."""
    atmosphere = scene.atmosphere
    if scene.media:
        centres = []
        for medium in scene.media:
            n = np.asarray(medium.shape, dtype=np.float64)
            centre = np.asarray(medium.world_from_index, dtype=np.float64) @ np.append(0.5 * (n - 1.0), 1.0)
            centres.append(centre[1])
        y = float(np.mean(centres))
    elif scene.ground is not None:
        y = scene.ground.height
    else:
        y = float(scene.camera.position[1])
    return y + atmosphere.altitude


@dataclass(frozen=True)
class FrameLight:
    """The light of one frame's scene (one run per light: the sun, then each extra sun).

    Attributes:
        scene: The scene as read, its sun above the air.
        through_air: A pass draws the scene's air, so what it lights sees the sun through the air.
    """

    scene: object
    through_air: bool

    def transmittance_at(self, altitude: float) -> np.ndarray:
        """RGB transmittance of the sunlight from the top of the atmosphere down to ``altitude`` [m of the stage's
        y] (ones without air drawn around the frame, or without a sun)."""
        return self._down_to(lambda atm: altitude + atm.altitude)

    @functools.cached_property
    def media_transmittance(self) -> np.ndarray:
        """RGB transmittance of the sunlight down to the media's altitude (:func:`media_altitude`)."""
        return self._down_to(lambda atm: media_altitude(self.scene))

    def _down_to(self, sea_level_altitude) -> np.ndarray:
        """RGB transmittance of the sunlight down to ``sea_level_altitude(atmosphere)`` [m above sea level]; ones
        without air drawn around the frame, or without a sun."""
        scene = self.scene
        if not self.through_air or scene.atmosphere is None or scene.sun is None:
            return np.ones(3)
        atm = scene.atmosphere
        if atm.round:
            from warpsky.media.air import round_earth as air_round_host

            return air_round_host.sunlight_transmittance(
                atm, air_round_host.scene_floor(scene), sea_level_altitude(atm), float(scene.sun.direction[1]),
                air_round_host.sun_radius(scene.sun.angular_diameter))
        return sunlight_transmittance(atm, sea_level_altitude(atm), light_elevation_sine(scene.sun))

    def lit_at_media(self, scene=None):
        """``scene`` (default the frame's) with its sun's transmittance down to the media."""
        return _with_transmittance(self.scene if scene is None else scene, self.media_transmittance)

    def lit_at(self, scene, altitude: float):
        """``scene`` with its sun's transmittance down to ``altitude`` [m of the stage's y]."""
        return _with_transmittance(scene, self.transmittance_at(altitude))

    @functools.cached_property
    def sky(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean radiance, E / pi) [RGB] of everything above the horizon lighting surfaces, fog and decks
        diffusely: the dome's upper hemisphere, plus the analytic sky's when the frame draws the air
        (:func:`~warpsky.light.sky.sky_light`, from the sun above the air)."""
        return sky_light(self.scene, analytic=self.through_air)


def _with_transmittance(scene, transmittance: np.ndarray):
    if scene.sun is None or (np.all(transmittance == 1.0) and np.all(scene.sun.transmittance == 1.0)):
        return scene
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, transmittance=transmittance))
