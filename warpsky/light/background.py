"""The dome behind everything, per pixel: its radiance as it arrives at the top of the air and the air's
transmittance to space along each pixel's ray, worked out once per frame (:func:`dome_background`).

The dome (``UsdLuxDomeLight``) lights from beyond the air: it replaces the black space an atmosphere would
otherwise show. Like :class:`~warpsky.light.frame.FrameLight` for the sun, :class:`DomeBackground` keeps the dome
as it arrives above the air and the air's transmittance separately. With air drawn around the frame (a sky pass)
the dome is seen through all of it: the flat-earth column over the finite-air-mass sine
(:func:`~warpsky.media.air.analytic.air_sine`, not at all below the horizon: ground or sea level), or on a round
earth the transmittance to space (:func:`~warpsky.media.air.round_earth.space_transmittance`). Without air drawn
around it, the layers' own transmittance (zero on the ground, with the air where a technique traced it) is all
that hides it.

The sky pass's back layer is opaque and composited behind its front air: the dome goes into it as the light
reaching the front air's far end, its transmittance to space over the front air's (:meth:`DomeBackground.beyond`),
so that the composite, which multiplies the back layer by the front air, gives the dome through all the air.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpsky.model.scene import Projection


def pixel_directions(camera, width: int, height: int) -> np.ndarray:
    """(H, W, 3) world unit directions through the pixel centres of ``camera`` conformed to (width, height), as the
    kernels' ``primary_ray`` gives them (an orthographic camera's all run along its view axis)."""
    camera = camera.conformed(width, height)
    if camera.projection is Projection.ORTHOGRAPHIC:
        return np.broadcast_to(camera.forward, (height, width, 3)).copy()
    sx = ((np.arange(width) + 0.5) / width - 0.5) * camera.horizontal_aperture + camera.horizontal_aperture_offset
    sy = (0.5 - (np.arange(height) + 0.5) / height) * camera.vertical_aperture + camera.vertical_aperture_offset
    local = np.stack(np.broadcast_arrays(sx[None, :], sy[:, None], -camera.focal_length), axis=-1)
    d = local @ np.asarray(camera.rotation, dtype=np.float64).T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@dataclass(frozen=True)
class DomeBackground:
    """The frame's dome behind everything.

    Attributes:
        radiance: (H, W, 3) radiance of the dome along each pixel's ray, as it arrives at the top of the air.
        air: (H, W, 3) transmittance of the air from the camera to space along each pixel's ray (zeros where the
            ray ends on the ground or at sea level), or None where no pass draws the air around the frame.
    """

    radiance: np.ndarray
    air: np.ndarray | None = None

    @property
    def seen(self) -> np.ndarray:
        """(H, W, 3) float32 radiance of the dome reaching the eye through the air (all of it)."""
        return (self.radiance if self.air is None else self.radiance * self.air).astype(np.float32)

    def beyond(self, front_air: np.ndarray) -> np.ndarray:
        """(H, W, 3) float32 radiance of the dome reaching the far end of the air in front, whose transmittance is
        ``front_air``: the dome through the air to space over ``front_air`` (zero where the front air is opaque).
        The composite sees it through ``front_air`` again, and through what lies between."""
        seen = self.seen
        beyond = np.divide(seen, front_air, out=np.zeros_like(seen), where=front_air > 0.0)
        return beyond.astype(np.float32)


def dome_background(scene, width: int, height: int, *, through_air: bool) -> DomeBackground | None:
    """The scene's dome behind everything for an image of (width, height) pixels (None without a dome); with
    ``through_air`` (a pass draws the scene's air around the frame), with the air's transmittance to space."""
    if scene.dome is None:
        return None
    directions = pixel_directions(scene.camera, width, height)
    radiance = scene.dome.radiance(directions)
    atmosphere = scene.atmosphere
    if not through_air or atmosphere is None:
        return DomeBackground(radiance)
    altitude = float(scene.camera.position[1]) + atmosphere.altitude
    if atmosphere.round:
        from warpsky.media.air import round_earth as air_round_host

        through = air_round_host.space_transmittance(atmosphere, air_round_host.scene_floor(scene), altitude,
                                                     directions.reshape(-1, 3))
        return DomeBackground(radiance, through.reshape(directions.shape))
    from warpsky.media.air.analytic import air_sine
    from warpsky.media.air.mixture import column as air_column

    column = air_column(atmosphere, altitude)
    sine = air_sine(directions[..., 1], atmosphere.gamma)[..., None]
    air = np.where(directions[..., 1:2] > 0.0, np.exp(-column / sine), 0.0)
    return DomeBackground(radiance, air)
