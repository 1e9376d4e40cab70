"""Decide what a frame needs before anything runs: technique, settings, passes, device, resolution, features.

This is where "leave out what a scene does not need" lives, and what ``warpsky info`` prints. The plan asks the
registered technique and passes (:mod:`warpsky.render.registry`) what they are: which passes run (``Pass.runs``),
whether the technique can render next to them (``Pass.refusal``), what each costs and what each says about the scene; it
names none of them itself.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.core.resources import (
    COMPOSITE_BYTES,
    WORKING_MEMORY,
    MemoryEstimate,
    WorkEstimate,
)
from warpsky.core.settings import parse_settings, settings_dict, settings_line, split_by_prefix
from warpsky.light.dome import mean_radiance
from warpsky.model.scene import Scene
from warpsky.optics.tables import is_cached
from warpsky.passes.frame import ground_pass
from warpsky.render.memory import held_memory, with_stage_read
from warpsky.render.registry import DEFAULT_TECHNIQUE, pass_classes, technique_class, technique_classes
from warpsky.render.setting_owners import check_owners

DEFAULT_WIDTH = 512


@dataclass
class RenderPlan:
    """What will run for one frame, fully resolved.

    Attributes:
        technique: Registered name of the technique.
        settings: Its settings with every ``auto`` value resolved for the frame's scene.
        device: Warp device name.
        width, height: Image size [pixels].
        renderer: The technique, built once for the frame with ``settings``.
        passes: Names of the passes that run, in order (the technique runs in ``media``).
        pass_runners: Those passes, built once for the frame with their settings.
        pass_settings: Settings of every registered pass that has settings, by pass name (running or not).
        features: One line per feature of the scene, what ``warpsky info`` prints.
        unused: ``--set`` names given to passes that do not run in this frame.
        settings_hash: Hash of what changes the frame's pixels, set by :func:`warpsky.render.planned.plan_frame` (the
            batch's resume check and the EXR metadata share it); empty until then.
        memory: Bytes the frame's process will hold at its peak, by part (:func:`frame_memory`).
        work: Worst-case kernel iterations of the frame (:func:`frame_work`).
    """

    technique: str
    settings: object
    device: str
    width: int
    height: int
    renderer: object
    passes: tuple[str, ...] = ()
    pass_runners: tuple = ()
    pass_settings: dict = field(default_factory=dict)
    features: dict[str, str] = field(default_factory=dict)
    unused: tuple[str, ...] = ()
    settings_hash: str = ""
    memory: MemoryEstimate = field(default_factory=MemoryEstimate)
    work: WorkEstimate = field(default_factory=WorkEstimate)

    def settings_dict(self) -> dict:
        return settings_dict(self.settings)

    def running_settings(self) -> list:
        """The settings of every running pass that has settings, in pass order."""
        return [runner.settings for runner in self.pass_runners if runner.settings is not None]

    def settings_record(self) -> dict:
        """The technique's settings and every running pass's, by pass name: what the settings hash covers."""
        passes = {runner.name: settings_dict(runner.settings) for runner in self.pass_runners
                  if runner.settings is not None}
        return {"technique": self.technique, **self.settings_dict(), **passes}

    def settings_json(self) -> str:
        """:meth:`settings_record` as the JSON the EXR header holds."""
        return json.dumps(self.settings_record(), sort_keys=True)

    def describe(self) -> str:
        media = any(runner.runs_technique for runner in self.pass_runners)
        lines = [
            f"technique   {self.technique}",
            f"device      {self.device}",
            f"resolution  {self.width} x {self.height}",
            "settings    " + (settings_line(self.settings) if media
                              else f"none: {self.technique} does not run (no voxel media)"),
        ]
        lines += ["            " + settings_line(settings) for settings in self.running_settings()]
        lines.append(f"passes      {' -> '.join(self.passes)} -> composite")
        lines += [f"{name:<11} {state}" for name, state in self.features.items()]
        return "\n".join(lines)


def resolve_resolution(scene: Scene, resolution: tuple[int, int | None] | None) -> tuple[int, int]:
    """Image size: ``--res``, else the stage's render settings, else 512 wide at the camera's aspect ratio."""
    camera = scene.camera
    aspect = camera.horizontal_aperture / camera.vertical_aperture / camera.pixel_aspect  # in pixels
    if resolution is None:
        resolution = scene.resolution or (DEFAULT_WIDTH, None)
    width, height = resolution
    if height is None:
        height = max(1, round(width / aspect))
    if width <= 0 or height <= 0:
        raise UsageError(f"resolution must be positive, got {width}x{height}")
    return int(width), int(height)


def make_plan(
    scene: Scene,
    *,
    technique: str = DEFAULT_TECHNIQUE,
    settings: dict | None = None,
    resolution: tuple[int, int | None] | None = None,
    device: str = "cpu",
) -> RenderPlan:
    """Plan a frame of ``scene``: parse the settings (``PREFIX.NAME`` ones go to the pass of that prefix, the rest
    to the technique), build the technique once with its settings resolved for the scene, decide the passes and
    build them, describe the features and estimate the frame's memory and work (nothing is allocated)."""
    cls = technique_class(technique)
    classes = pass_classes()
    prefixes = {p.Settings.prefix: p for p in classes if p.Settings is not None}
    own, by_prefix = split_by_prefix(settings or {}, prefixes)
    check_owners(technique, own, by_prefix, prefixes)
    pass_settings = {p.name: parse_settings(p.Settings, by_prefix[p.Settings.prefix]) for p in prefixes.values()}
    renderer = cls(parse_settings(cls.Settings, own), device=device).resolve(scene)
    width, height = resolve_resolution(scene, resolution)
    check_refusals(scene, cls, classes)
    running = [p for p in classes if p.runs(scene, renderer)]  # the technique's settings may decide (media)
    runners = tuple(p(pass_settings.get(p.name), device=device, technique=renderer) for p in running)
    unused = tuple(prefix + name for prefix, values in by_prefix.items() if prefixes[prefix] not in running
                   for name in values)
    plan = RenderPlan(technique, renderer.settings, device, width, height, renderer,
                      tuple(p.name for p in running), runners, pass_settings, unused=unused)
    plan.features = renderer.features(scene, width, height, describe_features(scene, plan))
    plan.memory, plan.work = frame_memory(scene, plan), frame_work(scene, plan)
    return plan


def check_refusals(scene: Scene, cls, classes) -> None:
    """A one-line UsageError when the technique class ``cls`` cannot render next to a pass the scene needs, naming
    what and the prims, and the techniques that can."""
    refused = [r for p in classes for r in [p.refusal(scene, cls)] if r is not None]
    if not refused:
        return
    named = "; ".join(f"{what} ({', '.join(names)})" for what, names in refused)
    able = [t.name for t in technique_classes() if all(p.refusal(scene, t) is None for p in classes)]
    advice = f"; use {', '.join(able[:-1])} or {able[-1]}" if len(able) > 1 else (f"; use {able[0]}" if able else "")
    raise UsageError(f"technique {cls.name} does not render {named}{advice}")


def frame_memory(scene: Scene, plan: RenderPlan) -> MemoryEstimate:
    """Peak memory of the frame's process: what it holds before the frame (:func:`~warpsky.render.memory.
    held_memory`), every running pass's buffers (the technique's through the media pass), the composite's and the
    EXR's, and the working memory; at least the stage read's peak (:func:`~warpsky.render.memory.with_stage_read`)."""
    estimate = held_memory(scene)
    for runner in plan.pass_runners:
        estimate.merge(runner.memory_estimate(scene, plan.width, plan.height))
    estimate.add("composite and EXR", host=plan.width * plan.height * COMPOSITE_BYTES)
    estimate.add("working memory", host=WORKING_MEMORY)
    return with_stage_read(estimate, scene, plan.device)


def frame_work(scene: Scene, plan: RenderPlan) -> WorkEstimate:
    """Worst-case kernel work of every running pass."""
    return WorkEstimate([item for runner in plan.pass_runners
                         for item in runner.work_estimate(scene, plan.width, plan.height)])


def describe_features(scene: Scene, plan: RenderPlan) -> dict[str, str]:
    """What ``warpsky info`` prints about the scene, one line per feature: the lights, what every registered pass
    draws (or why it does not run), the optics tables and the ground."""
    cls = type(plan.renderer)
    features = light_features(scene, cls)
    for p in pass_classes():
        features.update(p.describe(scene, cls, plan.pass_settings.get(p.name)))
    if plan.unused:
        features["unused"] = f"{', '.join(plan.unused)}: the pass(es) they set do not run in this frame"
    species = scene.species
    if species:
        states = [f"{name} ({'cached' if is_cached(name) else 'to build'})" for name in species]
        features["optics"] = "phase tables for " + ", ".join(states)
    else:
        features["optics"] = "analytic phase only: no species fields, no tables built"
    features["ground"] = _ground_feature(scene, plan)
    return features


def light_features(scene: Scene, cls) -> dict[str, str]:
    """The ``sun``, ``extra suns`` and ``dome`` lines."""
    features = {}
    if scene.sun is None:
        features["sun"] = "none (no visible DistantLight): media render black, transmittance only"
    else:
        sun = scene.sun
        features["sun"] = (f"{sun.name}: elevation {np.degrees(sun.elevation):.2f} deg, "
                           f"irradiance {np.round(sun.irradiance, 4).tolist()}")
    if scene.extra_suns:
        features["extra suns"] = (", ".join(f"{s.name} (elevation {np.degrees(s.elevation):.2f} deg)"
                                            for s in scene.extra_suns)
                                  + f": every pass runs {1 + len(scene.extra_suns)} times, once per light")
    if scene.dome is not None:
        dome = scene.dome
        kind = f"lat-long texture {dome.source}" if dome.texture is not None else "uniform"
        how = ("path traced exactly" if cls.traces_dome
               else "ambient: its mean radiance, occluded towards the zenith")
        features["dome"] = (f"{dome.name}: {kind}, mean radiance {np.round(mean_radiance(dome), 4).tolist()}; "
                            f"{how}; shown behind everything")
    return features


def _ground_feature(scene: Scene, plan: RenderPlan) -> str:
    ground = scene.ground
    if ground is None:
        return "off (no Plane prim): the kernels skip the ground (Ground.enabled = 0)"
    line = f"{ground.name} at y = {ground.height:g} m, albedo {np.round(ground.albedo, 3).tolist()}"
    if ground.albedo_map is not None:
        tex = ground.albedo_map
        line += (f"; albedo map {tex.albedo.shape[0]}x{tex.albedo.shape[1]} over {tex.size[0]:g} x "
                 f"{tex.size[1]:g} m (stratiform pass only)")
    drawer = ground_pass(plan.pass_runners, scene)
    note = next((runner.ground_note for runner in plan.pass_runners if runner.name == drawer), "")
    return line + (f"; {note}" if note else "")
