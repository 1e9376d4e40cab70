"""One frame as a loop over its passes: the technique (in the ``media`` pass) and the registered passes that run,
once per light, merged by depth, wrapped in the air, composited by :func:`warpsky.passes.composite.composite`.

The plan (:func:`warpsky.render.plan.make_plan`) decides which passes run and builds them with their settings; this
module runs them. Every pass gets the same :class:`FrameState`: the scene with its sun above the air, the frame's
light worked out once (:class:`~warpsky.light.frame.FrameLight`: the sun's transmittance through the air, the
sky's light), which pass draws the ground plane, and what the passes before it drew (their layers, the depth of
the nearest opaque surface, the meshes on the device for shadow rays).

Light transport is linear in the lights: each of the scene's ``extra_suns`` runs every pass again with that light
as the sun (the technique's :meth:`~warpsky.techniques.technique.Technique.for_extra_light`) and the radiance adds up;
transmittance and depth are the first run's. The dome lights the first run only, and shows behind everything
(:func:`~warpsky.light.background.dome_background`, worked out in the light layer, composited here).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from warpsky.core.image import ImageLayer
from warpsky.light.background import dome_background
from warpsky.light.frame import FrameLight
from warpsky.passes.composite import add_light, merge_by_depth, with_background


@dataclass
class FrameState:
    """What every pass of one frame sees, for one light.

    Attributes:
        scene: The scene lit by this light, its sun above the air (``FrameLight.lit_at_media`` gives the sun
            through the air).
        technique: The technique the media pass runs.
        runners: Every pass that runs, in order.
        width, height: Image size [pixels].
        device: Warp device name.
        light: The light of this run (:class:`~warpsky.light.frame.FrameLight`).
        ground: Name of the pass that draws the ground plane (None: none does, or the scene has none).
        layers: What the depth-merged passes drew so far, in order.
        limit: (H, W) camera-space depth [m] of the nearest opaque surface, once a pass has drawn one (the
            camera's far distance where none is hit); the marches after it stop there.
        occluders: The frame's meshes on the device, relative to the camera, for shadow rays (None: no meshes).
        merged: The depth-merged layer, for a wrapping pass.
        kept: Layers a pass drew for this frame before its turn, by pass name (:meth:`~warpsky.passes.render_pass.Pass.
            own_layer`: the media pass hands the fog's and the deck's to the technique's scenery paths).
        deep_samples: Volume samples per pixel a volume pass profiles its layer into for deep output
            (:class:`~warpsky.output.deep_bins.DepthProfile`); 0: none, the frame writes no deep image.
    """

    scene: object
    technique: object
    runners: tuple
    width: int
    height: int
    device: str
    light: FrameLight
    ground: str | None = None
    layers: list[ImageLayer] = field(default_factory=list)
    limit: np.ndarray | None = None
    occluders: object | None = None
    merged: ImageLayer | None = None
    deep_samples: int = 0
    kept: dict = field(default_factory=dict)

    def runs(self, name: str) -> bool:
        """Whether the pass called ``name`` runs in this frame."""
        return any(runner.name == name for runner in self.runners)


def ground_pass(runners, scene) -> str | None:
    """Name of the running pass that draws the scene's ground plane: the one of lowest ``ground_rank``."""
    if scene.ground is None:
        return None
    ranked = [r for r in runners if r.ground_rank is not None and r.draws_ground(scene)]
    return min(ranked, key=lambda r: r.ground_rank).name if ranked else None


def render_layers(plan, scene, technique=None, *, deep_samples: int = 0) -> tuple[ImageLayer, list[ImageLayer]]:
    """Run ``plan``'s passes (``plan.pass_runners``) on ``scene``: (the depth-merged layer of the technique and
    the other passes; every layer front to back for :func:`~warpsky.passes.composite.composite`). ``technique`` is the
    plan's ``renderer`` (the default) or another with the same capabilities. With ``deep_samples``, the volume
    passes profile their layers for deep output in that many bins (not with extra suns, whose merged layer is one
    sample)."""
    technique = plan.renderer if technique is None else technique
    main, layers = _lit_by(plan, scene, technique, 0 if scene.extra_suns else deep_samples)
    if scene.extra_suns:
        again = technique.for_extra_light()
        for sun in scene.extra_suns:
            extra_main, extra_layers = _lit_by(plan, replace(scene, sun=sun, extra_suns=(), dome=None), again)
            main = add_light([main], [extra_main])[0]
            layers = add_light(layers, extra_layers)
    air = any(runner.wraps for runner in plan.pass_runners)
    dome = dome_background(scene, plan.width, plan.height, through_air=air)
    if dome is not None:  # behind the air a wrapping pass drew, whose front part (the first layer) it lies beyond
        background = dome.beyond(layers[0].transmittance) if air else dome.seen
        layers = with_background(layers, background, scene.camera.far, behind_air=air)
    return main, layers


def frame_state(plan, scene, technique=None, deep_samples: int = 0) -> FrameState:
    """The :class:`FrameState` of ``plan``'s passes on ``scene`` (lit by one light), before any pass ran."""
    runners = plan.pass_runners
    return FrameState(scene, plan.renderer if technique is None else technique, runners, plan.width, plan.height,
                      plan.device, FrameLight(scene, through_air=any(runner.wraps for runner in runners)),
                      ground=ground_pass(runners, scene), deep_samples=deep_samples)


def render_pass(plan, scene, name: str) -> list[ImageLayer]:
    """The layers of ``plan``'s pass ``name`` alone on ``scene`` (benchmarks time one pass so)."""
    runner = next(runner for runner in plan.pass_runners if runner.name == name)
    return runner.render(frame_state(plan, scene))


def depth_layers(plan, scene, technique=None) -> list[ImageLayer]:
    """The layers of ``plan``'s depth-merged passes on ``scene`` (lit by one light), in pass order, unmerged."""
    return _depth_passes_run(frame_state(plan, scene, technique)).layers


def _depth_passes_run(frame: FrameState) -> FrameState:
    """``frame`` after its depth-merged passes (those that do not wrap the others) ran in order."""
    for runner in frame.runners:
        if not runner.wraps:
            frame.layers += runner.render(frame)
    return frame


def _lit_by(plan, scene, technique, deep_samples: int = 0) -> tuple[ImageLayer, list[ImageLayer]]:
    """Every pass run once on ``scene`` (lit by one light): (merged layer, layers front to back)."""
    wrapping = [runner for runner in plan.pass_runners if runner.wraps]
    frame = _depth_passes_run(frame_state(plan, scene, technique, deep_samples))
    ahead = None
    if wrapping:  # light already attenuated to the eye (through the air too) goes in front of the front air
        ahead = front_light(frame.layers)
        frame.layers = [replace(layer, front=None) for layer in frame.layers]
    main = merge_by_depth(frame.layers, far=scene.camera.far) if len(frame.layers) > 1 else frame.layers[0]
    frame.merged = main
    if not wrapping:
        return main, [main]
    front, back = wrapping[0].render(frame)
    return main, [replace(front, front=ahead), main, back]


def front_light(layers: list[ImageLayer]) -> ImageLayer | None:
    """The sum of ``layers``' ``front`` light (:class:`~warpsky.core.image.ImageLayer`), or None when none has any."""
    fronts = [layer.front for layer in layers if layer.front is not None]
    if not fronts:
        return None
    out = fronts[0]
    for more in fronts[1:]:
        out = add_light([out], [more])[0]
    return out
