"""The passes a frame is made of besides the voxel technique, and the scene each one sees.

A frame is planned (:func:`warpsky.plan.make_plan` decides which passes run), each pass renders Layers, and the
Layers are composited front to back (:mod:`warpsky.composite`):

- ``media``: the voxel technique (:class:`~warpsky.techniques.base.Technique`), on :func:`media_scene`;
- ``stratiform``: :class:`StratiformPass`, one Layer per stratiform layer, merged with the media by depth;
- ``sky``: :class:`~warpsky.techniques.sky.technique.SkyPass`, the air in front of the merged layer and behind
  it (with the sun's disk).
"""

from __future__ import annotations

import dataclasses

from warpsky.scene.model import Scene
from warpsky.techniques.base import Layer
from warpsky.techniques.sky.analytic import sun_transmittance
from warpsky.techniques.sky.technique import attenuated_sun
from warpsky.techniques.stratiform.technique import Stratiform, StratiformSettings
from warpsky.techniques.sunlight import light_elevation_sine, visible_sun


def media_scene(scene: Scene, passes: tuple[str, ...]) -> Scene:
    """The scene the voxel technique renders.

    With a sky pass, the media see sunlight reddened by the air above them. Next to stratiform layers, the media
    are rendered without the ground and the layers (the lowest stratiform layer draws the ground); where the ground
    was the only horizon, the sun becomes the light of its disk's visible part
    (:func:`~warpsky.techniques.sunlight.visible_sun`), so the ground still hides what has set. Not modelled:
    shadows between voxel media and layers, and of voxel media on the ground.
    """
    if "stratiform" in passes:
        media_only = dataclasses.replace(scene, ground=None, layers=())
        if scene.ground is not None and scene.atmosphere is None:
            media_only = dataclasses.replace(media_only, sun=visible_sun(scene.sun))
        scene = media_only
    return attenuated_sun(scene) if "sky" in passes else scene


def sun_at_altitude(scene: Scene, altitude: float) -> Scene:
    """``scene`` with its sun reddened by the air above ``altitude`` [m of the stage's y] (Riley Eq. 12)."""
    if scene.atmosphere is None or scene.sun is None:
        return scene
    atm = scene.atmosphere
    t = sun_transmittance(atm.beta_sea_level, atm.gamma, altitude + atm.altitude, light_elevation_sine(scene.sun))
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, irradiance=scene.sun.irradiance * t))


class StratiformPass:
    """Every stratiform layer of the scene as its own Layer (Bouthors slab, plus the ground <-> cloud-base
    radiosity when a ground lies below), each lit by the sun reddened down to its mid altitude; the lowest layer
    draws the ground (textured, in the layer's shadow, lit by the radiosity)."""

    def __init__(self, settings: StratiformSettings | None = None, *, device: str = "cpu"):
        self.stratiform = Stratiform(settings, device=device)

    def render(self, scene: Scene, width: int, height: int) -> list[Layer]:
        """One Layer per stratiform layer of ``scene``, in the scene's order; ``stats["layer"]`` names it."""
        parts = []
        lowest = min(range(len(scene.layers)), key=lambda i: scene.layers[i].base_altitude)
        for index, layer in enumerate(scene.layers):
            lit = sun_at_altitude(scene, layer.base_altitude + 0.5 * float(layer.thickness.max()))
            part = self.stratiform.render(lit, width, height, layer=layer, draw_ground=index == lowest)
            part.stats["layer"] = layer.name
            parts.append(part)
        return parts
