"""The passes a frame is made of besides the voxel technique, and the scene each one sees.

A frame is planned (:func:`warpsky.plan.make_plan` decides which passes run), each pass renders Layers, and the
Layers are composited front to back (:mod:`warpsky.composite`):

- ``media``: the voxel technique (:class:`~warpsky.techniques.base.Technique`), on :func:`media_scene`;
- ``stratiform``: :class:`StratiformPass`, one Layer per stratiform layer, merged with the media by depth;
- ``surfaces``: :class:`~warpsky.passes.surfaces.surfaces.SurfacesPass`, the meshes (terrain) and, in a scene
  without voxel media and stratiform layers, the ground plane; its depth stops the two passes below;
- ``heightfield``: :class:`~warpsky.passes.heightfield.heightfield.HeightFieldPass`, Max's clouds and haze;
- ``fog``: :class:`~warpsky.passes.fog.fog.FogPass`, Biri's analytic fog;
- ``sky``: :class:`~warpsky.passes.sky.sky.SkyPass`, the air in front of the merged layer and behind
  it (with the sun's disk).

All but the sky are merged by depth (:func:`~warpsky.composite.merge_by_depth`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from warpsky.layer import Layer
from warpsky.light.sun import light_elevation_sine, visible_sun
from warpsky.media.air_analytic import sun_transmittance
from warpsky.passes.sky.sky import attenuated_sun
from warpsky.passes.stratiform.stratiform import Stratiform, StratiformSettings
from warpsky.scene.model import Scene

#: The passes :func:`scenery_layers` runs.
SCENERY_PASSES = frozenset({"surfaces", "heightfield", "fog"})
#: ``--set PASS.NAME=VALUE`` settings of the height-field and fog passes: their keyword arguments and types
#: (documented on :class:`~warpsky.passes.heightfield.heightfield.HeightFieldPass` and
#: :class:`~warpsky.passes.fog.fog.FogPass`).
SCENERY_SETTINGS = {
    "heightfield": {"mode": str, "step_length": float, "haze_step_length": float, "max_steps": int,
                    "min_transmittance": float},
    "fog": {"nodes": int, "min_pieces": int, "max_pieces": int, "cut_depth": float},
}


def parse_scenery_settings(values: dict[str, str]) -> dict[str, dict]:
    """``{"heightfield.mode": "max", ...}`` as ``{"heightfield": {"mode": "max"}, ...}``, typed and checked by
    building the passes (a bad name or value is a one-line UsageError naming the setting)."""
    from warpsky.errors import UsageError

    out: dict[str, dict] = {}
    for key, text in values.items():
        prefix, _, name = key.partition(".")
        kinds = SCENERY_SETTINGS[prefix]
        if name not in kinds:
            raise UsageError(f"unknown setting {key}; {prefix} settings: "
                             f"{', '.join(prefix + '.' + n for n in kinds)}")
        try:
            out.setdefault(prefix, {})[name] = kinds[name](text)
        except ValueError:
            raise UsageError(f"setting {key} must be {'a whole number' if kinds[name] is int else 'a number'}, "
                             f"got {text!r}") from None
    if "heightfield" in out:
        from warpsky.passes.heightfield.heightfield import HeightFieldPass

        HeightFieldPass(**out["heightfield"])
    if "fog" in out:
        from warpsky.passes.fog.fog import FogPass

        FogPass(**out["fog"])
    return out


def media_scene(scene: Scene, passes: tuple[str, ...]) -> Scene:
    """The scene the voxel technique renders.

    With a sky pass, the media see sunlight reddened by the air above them. Next to stratiform layers, the media
    are rendered without the ground and the layers (the lowest stratiform layer draws the ground); where the ground
    was the only horizon, the sun becomes the light of its disk's visible part
    (:func:`~warpsky.light.sun.visible_sun`), so the ground still hides what has set. Not modelled:
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


_SURFACE_PASSES: dict = {}


def _surfaces_pass(device: str):
    """One surfaces pass per device for the process: it keeps its BVH, which the next frame refits when only the
    points or the camera moved (an animated batch, a turntable)."""
    from warpsky.passes.surfaces.surfaces import SurfacesPass

    if device not in _SURFACE_PASSES:
        _SURFACE_PASSES[device] = SurfacesPass(device=device)
    return _SURFACE_PASSES[device]


def scenery_sun_transmittance(scene: Scene, device: str):
    """``points (N, 3) world -> (N, 3)``: the sunlight's transmittance through the scene's height-field clouds,
    fog and stratiform layers (the voxel media's shadows the surfaces pass traces itself); None when the scene has
    none of them."""
    parts = []
    if scene.heightfield_clouds:
        from warpsky.passes.heightfield.heightfield import heightfield_sun_transmittance

        # the exact sun-ray optical depth: Max's thickness rule fails for decks thicker than their features
        parts.append(lambda s, points, d: heightfield_sun_transmittance(s, points, d, exact=True))
    if scene.fogs:
        from warpsky.passes.fog.fog import fog_sun_transmittance

        parts.append(fog_sun_transmittance)
    if scene.layers and scene.sun is not None:
        from warpsky.media.stratiform import layer_sun_transmittance

        for layer in scene.layers:
            parts.append(lambda s, points, d, layer=layer: layer_sun_transmittance(layer, points, s.sun.direction, d))
    if not parts:
        return None

    def transmittance(points):
        out = 1.0
        for part in parts:
            out = out * part(scene, points, device)
        return out

    return transmittance


def scenery_layers(scene: Scene, passes: tuple[str, ...], width: int, height: int, *, device: str,
                   before: list[Layer] | None = None, settings: dict | None = None, sky=None
                   ) -> tuple[list[Layer], np.ndarray | None]:
    """The surfaces, height-field and fog passes' Layers for ``scene`` (already lit as the media see it), with the
    ``before`` layers (the media's, the stratiform layers') between the surfaces and the rest; and the surfaces'
    depth (the camera's far distance where no surface is hit; None without a surfaces pass). That depth
    stops the height-field clouds, the haze and the fog (Max: "bounded by the distance to the nearest opaque
    surface"; Biri: the fog integral runs to the depth buffer). ``settings``: :func:`parse_scenery_settings`'s.
    ``sky``: (mean radiance, E / pi) of the upper hemisphere lighting them (:func:`~warpsky.light.sky.
    sky_light`); None: the dome's alone."""
    from warpsky.light.dome import isotropic_ambient
    from warpsky.light.sky import sky_light
    from warpsky.plan import surfaces_draw_ground

    sky = sky_light(scene, analytic=False) if sky is None else sky
    ambient = isotropic_ambient(scene, sky)
    parts, limit = [], None
    if "surfaces" in passes:
        surfaces = _surfaces_pass(device).render(
            scene, width, height, draw_ground=surfaces_draw_ground(scene),
            sun_transmittance=scenery_sun_transmittance(scene, device), sky=sky[1])
        parts.append(surfaces)
        limit = surfaces.depth
    parts += before or []
    if "heightfield" in passes:
        from warpsky.passes.heightfield.heightfield import HeightFieldPass

        options = (settings or {}).get("heightfield", {})
        parts.append(HeightFieldPass(device=device, **options).render(scene, width, height, limit=limit,
                                                                      ambient=ambient))
    if "fog" in passes:
        from warpsky.passes.fog.fog import FogPass

        options = (settings or {}).get("fog", {})
        occluders = _surfaces_pass(device).occluders if scene.meshes and "surfaces" in passes else None
        parts.append(FogPass(device=device, **options).render(scene, width, height, limit=limit, ambient=ambient,
                                                               occluders=occluders))
    return parts, limit
