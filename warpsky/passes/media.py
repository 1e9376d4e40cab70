"""The media pass: the frame's technique in its place among the passes.

It hands the technique the scene as the media see it. With a pass that draws the air (the sky pass), their sun
comes through the air above them (:meth:`~warpsky.light.frame.FrameLight.lit_at_media`). Where another pass draws
the ground plane (the lowest stratiform layer), the technique renders the media without the ground and without what
that pass draws from the scene (the layers), and where the ground was the only horizon, the sun becomes the light
of its disk's visible part (:func:`~warpsky.light.sun.visible_sun`), so the ground still hides what has set. Not
modelled there: shadows between voxel media and layers, and of voxel media on the ground. A technique that
``scatters_scenery`` runs here in a stage of fog or meshes even without voxel media, for their multiple scattering;
the surfaces pass then draws the ground plane (in the fog's shadow), on which the technique's paths bounce.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from warpsky.light.sun import visible_sun
from warpsky.passes.render_pass import Pass


def has_scenery(scene) -> bool:
    """Whether ``scene`` holds meshes, height-field clouds or analytic fog (each drawn by its own pass)."""
    return bool(scene.meshes or scene.decks or scene.fogs)


def scenery_traceable(scene) -> bool:
    """Whether a ``scatters_scenery`` technique path traces ``scene``'s fog, height-field deck and meshes beyond
    their single scattering: there are some, and stratiform layers only above the fog (every slab's top, moved by
    its wind, below the lowest cloud base), without voxel media, a deck or a ground albedo map (the paths then trace
    the layers too, beyond a camera ray's first event; the stratiform pass draws them, and the surfaces pass, which
    reads no albedo map, the ground)."""
    scenery = bool(scene.fogs or scene.meshes or scene.decks)
    if not scene.stratiform_layers:
        return scenery
    textured = scene.ground is not None and scene.ground.albedo_map is not None
    base = min(layer.base_altitude for layer in scene.stratiform_layers)
    below = all(fog.top + float(fog.wind[1]) * scene.time_s < base for fog in scene.fogs)
    return scenery and below and not (scene.media or scene.decks or textured)


@dataclass(frozen=True)
class SceneryFrame:
    """What the frame's other passes draw around a technique whose paths trace the scenery
    (:meth:`~warpsky.techniques.technique.Technique.scenery_paths`)."""

    ground: object | None = None  # the ground plane another pass draws: the paths bounce on it
    stratiform_layers: tuple = ()  # what the stratiform pass draws: traced beyond a camera ray's first event
    drawn: np.ndarray | None = None  # (H, W, 3) radiance of the passes before (the surfaces), in the frame's level
    occluders: object | None = None  # the frame's meshes on the device, whose shadows lie on the fog's sunlight
    fog: object | None = None  # the fog pass's layer of this frame (ImageLayer), drawn early and kept for its turn
    deck: object | None = None  # the deck pass's, likewise


def scenery_paths(scene, technique) -> bool:
    """Whether ``technique`` path traces ``scene``'s scenery (a technique class: whether it can; a built technique:
    its settings decide, :meth:`~warpsky.techniques.technique.Technique.scenery_paths`)."""
    if not (technique.scatters_scenery and scenery_traceable(scene)):
        return False
    return isinstance(technique, type) or technique.scenery_paths(scene)


class MediaPass(Pass):
    """The technique's voxel media (and whatever the technique traces itself: voxelised layers, a deck)."""

    name = "media"
    ground_rank = 1
    runs_technique = True

    @classmethod
    def runs(cls, scene, technique) -> bool:
        """With voxel media, with layers, a deck, fog or meshes the technique traces itself, or in a scene with
        nothing else to draw (the technique draws the ground, the sky or nothing)."""
        return cls.renders_own(scene, technique) or scenery_paths(scene, technique)

    @classmethod
    def renders_own(cls, scene, technique) -> bool:
        """Whether it runs for what the technique draws itself (not only for the scenery's multiple scattering,
        :meth:`~warpsky.techniques.technique.Technique.scenery_paths`)."""
        traced = ((scene.stratiform_layers and technique.traces_layers) or (scene.decks and technique.traces_decks)
                  or (scene.fogs and technique.traces_fog) or (scene.meshes and technique.traces_meshes))
        return bool(scene.media) or bool(traced) or not (scene.stratiform_layers or has_scenery(scene))

    def draws_ground(self, scene) -> bool:
        """Not where it runs only for the scenery's multiple scattering: the surfaces pass draws the ground there,
        in the fog's shadow (the technique's paths still bounce on it)."""
        return self.renders_own(scene, type(self.technique))

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if scene.media:
            voxels = sum(int(np.prod(m.shape)) for m in scene.media)
            return {"media": f"{len(scene.media)} voxel grid(s), {voxels:,} voxels, {voxels * 4 / 2**20:.1f} MiB"}
        if cls.runs(scene, technique) and not cls.renders_own(scene, technique):
            kinds = [kind for kind, present in (("the fog", scene.fogs), ("the height-field deck",
                     scene.decks), ("the meshes", scene.meshes)) if present]
            named = ", ".join(kinds[:-1]) + " and " + kinds[-1] if len(kinds) > 1 else kinds[0]
            layers = (", and the stratiform layers' light on them (the layers voxelised beyond the camera rays' "
                      "first event, which the stratiform pass draws)") if scene.stratiform_layers else ""
            return {"media": f"none: {technique.name} path traces the multiple scattering of {named} (their "
                             f"passes draw the single scattering){layers}"}
        if scene.stratiform_layers:
            return {"media": f"none: {technique.name} does not run, the layers are rendered by the stratiform pass"}
        return {"media": "none"}

    def memory_estimate(self, scene, width: int, height: int):
        return self.technique.memory_estimate(scene, width, height)

    def work_estimate(self, scene, width: int, height: int):
        return list(self.technique.work_estimate(scene, width, height))

    def tables(self, scene) -> list:
        return self.technique.tables(scene)

    def render(self, frame) -> list:
        """The technique's layer; for deep output with the voxel media's depth profile on the technique's rays
        (:func:`~warpsky.passes.depth_profile.media_profile`)."""
        scene = media_scene(frame)
        if frame.technique.scenery_paths(scene):
            # other passes draw the ground plane and the layers; the paths bounce on the one and trace the other
            kept = {runner.name: runner.own_layer(frame) for runner in frame.runners
                    if runner.name in ("fog", "deck")}
            around = SceneryFrame(ground=frame.scene.ground if scene.ground is None else None,
                                  stratiform_layers=() if scene.stratiform_layers
                                  else tuple(frame.scene.stratiform_layers),
                                  drawn=sum(layer.radiance for layer in frame.layers) if frame.layers else None,
                                  occluders=frame.occluders, fog=kept.get("fog"), deck=kept.get("deck"))
            layer = frame.technique.render(scene, frame.width, frame.height, around=around)
        else:
            layer = frame.technique.render(scene, frame.width, frame.height)
        if frame.deep_samples > 0 and scene.media:
            from warpsky.passes.depth_profile import media_profile

            layer = dataclasses.replace(layer, profile=media_profile(scene, frame.width, frame.height,
                                                                     frame.deep_samples, frame.device))
        return [layer]


def media_scene(frame):
    """The scene the technique renders in ``frame`` (see the module docstring)."""
    scene = frame.scene
    drawn = {name: () for runner in frame.runners for name in runner.draws}
    if frame.ground not in (None, MediaPass.name):
        drawn["ground"] = None
        if scene.atmosphere is None:
            drawn["sun"] = visible_sun(scene.sun)
    if frame.limit is not None:  # an opaque surface drawn in front of the media: camera rays end there
        from warpsky.core import device_buffers

        # kept by contents, so a batch's frames with the same view keep its address (and slicing its CUDA graph)
        opaque = device_buffers.upload("media:opaque", np.asarray(frame.limit, dtype=np.float32), float, frame.device)
        drawn["camera"] = dataclasses.replace(scene.camera, opaque_depth=opaque)
    if drawn:
        scene = dataclasses.replace(scene, **drawn)
    return frame.light.lit_at_media(scene) if frame.light.through_air else scene
