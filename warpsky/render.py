"""Render one frame end to end: stage -> scene -> plan -> passes -> composite -> EXR (+ PNG preview)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import warpsky
from warpsky.composite import add_light, composite, dome_background, merge_by_depth, with_background
from warpsky.output.exr import write_exr
from warpsky.output.png import write_png
from warpsky.passes import StratiformPass, media_scene
from warpsky.plan import RenderPlan, make_plan
from warpsky.resources import check_resources
from warpsky.scene.model import LUMINANCE_WEIGHTS, Scene
from warpsky.techniques.base import DEFAULT_TECHNIQUE, Layer, Technique
from warpsky.techniques.sky.technique import SkyPass

#: Figures of a Monte Carlo render that go into the EXR header (camelCase) and the batch log, where present.
QUALITY_STATS = ("spp", "passes", "stopped_by", "error_estimate", "target_error", "capped_paths", "paths")

#: Fraction of a frame's Monte Carlo paths stopped at ``max_bounces`` above which the render warns: their light is
#: missing from the image (a bias that more samples do not remove).
CAPPED_PATHS_WARNING = 1e-3

#: Channels every warpsky EXR holds.
EXR_CHANNELS = ("R", "G", "B", "A", "transmittance.R", "transmittance.G", "transmittance.B", "depth.Z")


@dataclass
class RenderOptions:
    """How to render, as given on the command line (or by a batch driver).

    Attributes:
        technique: Registered technique name.
        settings: Technique settings as ``{name: text}``; unknown names are an error.
        resolution: (width, height or None) or None for the stage's render settings / default.
        device: Warp device name, already resolved (``cpu``, ``cuda:0``).
        camera: Camera prim path, or None for the default camera.
        half: Write RGBA as half floats (False: 32-bit float).
        png: Also write a tone-mapped PNG preview next to the EXR.
        exposure: Preview exposure in stops, on top of the automatic sun-based normalisation.
        max_memory: Most bytes a frame may allocate on the host and on the device each (None: what is free).
        work_limit: Refuse frames whose worst-case work exceeds :mod:`warpsky.resources`' bounds.
    """

    technique: str = DEFAULT_TECHNIQUE
    settings: dict[str, str] = field(default_factory=dict)
    resolution: tuple[int, int | None] | None = None
    device: str = "cpu"
    camera: str | None = None
    half: bool = True
    png: bool = False
    exposure: float = 0.0
    max_memory: int | None = None
    work_limit: bool = True


@dataclass
class FrameResult:
    """What rendering one frame produced.

    Attributes:
        timings: Seconds per step of the frame: ``plan`` (stage read, plan, settings hash), ``passes`` (every
            pass's render), ``composite``, ``write`` (EXR and PNG).
    """

    exr: Path
    png: Path | None
    seconds: float
    render_seconds: float
    time_code: float | None
    plan: RenderPlan
    timings: dict[str, float] = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def capped_paths_warning(quality: dict, plan: RenderPlan) -> str | None:
    """One line when more than :data:`CAPPED_PATHS_WARNING` of the frame's paths stopped at ``max_bounces``."""
    capped, paths = int(quality.get("capped_paths", 0)), int(quality.get("paths", 0))
    if paths <= 0 or capped <= CAPPED_PATHS_WARNING * paths:
        return None
    cap = getattr(plan.settings, "max_bounces", "max_bounces")
    return (f"{capped:,} of {paths:,} paths ({capped / paths:.2%}) stopped at max_bounces = {cap} scattering events; "
            "their light is missing from the frame (raise it with --set max_bounces=N)")


def preview_exposure(scene: Scene, stops: float = 0.0) -> float:
    """Scale that maps the radiance of a white Lambertian surface facing the sun to 1 (then ``2**stops``)."""
    if scene.sun is None or float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) <= 0.0:
        return 2.0**stops
    return np.pi / float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) * 2.0**stops


def plan_frame(reader, time_code, options: RenderOptions, *, check: bool = True) -> tuple[Scene, RenderPlan]:
    """Read the stage at ``time_code`` once and plan the frame: technique built, settings resolved, passes chosen,
    settings hash computed (``plan.settings_hash``); with ``check``, a frame over the memory or work limits is
    refused here (:class:`~warpsky.resources.ResourceError`), before anything is allocated."""
    scene = reader.scene_at(time_code, camera_path=options.camera)
    plan = make_plan(
        scene,
        technique=options.technique,
        settings=options.settings,
        resolution=options.resolution,
        device=options.device,
    )
    plan.settings_hash = settings_hash(plan, options, scene)
    if check:
        check_resources(plan, max_memory=options.max_memory, work_limit=options.work_limit)
    return scene, plan


def settings_hash(plan: RenderPlan, options: RenderOptions, scene: Scene | None = None) -> str:
    """Short hash of what changes a frame's pixels: the resolved settings, resolution, camera and format, and (with
    ``scene``) the identity of its input files — the stage and every medium's field file by size and modification
    time — so a batch re-renders frames whose data were rewritten (used to resume batches)."""
    inputs = []
    if scene is not None:
        for path in [scene.source, *(m.source for m in scene.media)]:
            try:
                info = os.stat(path)
                inputs.append([str(path), info.st_size, info.st_mtime_ns])
            except (OSError, TypeError, ValueError):
                inputs.append([str(path), None, None])
    key = json.dumps(
        {"plan": json.loads(plan.settings_json()), "res": [plan.width, plan.height], "camera": options.camera,
         "half": options.half, "inputs": inputs},
        sort_keys=True,
    )
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def render_layers(technique: Technique, scene: Scene, plan: RenderPlan) -> tuple[Layer, list[Layer]]:
    """Run the plan's passes: (the media's layer, merged by depth with the stratiform layers when the scene has
    any; all layers front to back for :func:`~warpsky.composite.composite`). ``technique`` is the plan's
    ``renderer`` or another technique with the same capabilities.

    Light transport is linear in the lights: each of the scene's ``extra_suns`` runs every pass again with that
    light as the sun (one more run of every pass per light) and the radiance adds up; transmittance and depth are
    the first run's. The dome lights the first run only, and shows behind everything
    (:func:`~warpsky.composite.dome_background`)."""
    width, height = plan.width, plan.height

    def lit_by(lit: Scene, run: Technique) -> tuple[Layer, list[Layer]]:
        parts = []
        if "media" in plan.passes:
            parts.append(run.render(media_scene(lit, plan.passes), width, height))
        if "stratiform" in plan.passes:
            parts += StratiformPass(plan.layer_settings, device=plan.device).render(lit, width, height)
            main = merge_by_depth(parts, far=lit.camera.far)
        else:
            main = parts[0]
        if "sky" not in plan.passes:
            return main, [main]
        front, back = SkyPass(device=plan.device).render(lit, width, height, media_depth=main.depth)
        return main, [front, main, back]

    main, layers = lit_by(scene, technique)
    if scene.extra_suns:
        settings = getattr(technique, "settings", None)
        if getattr(settings, "environment", 0.0):  # the uniform environment lights the first run only
            technique = type(technique)(dataclasses.replace(settings, environment=0.0), device=plan.device)
        for sun in scene.extra_suns:
            extra_main, extra_layers = lit_by(dataclasses.replace(scene, sun=sun, extra_suns=(), dome=None), technique)
            main = add_light([main], [extra_main])[0]
            layers = add_light(layers, extra_layers)
    if scene.dome is not None:
        sky = "sky" in plan.passes
        background = dome_background(scene, width, height, through_air=sky)
        layers = with_background(layers, background, scene.camera.far,
                                 front_air=layers[0].transmittance if sky else None)
    return main, layers


def render_frame(reader, time_code, out_path: Path, options: RenderOptions) -> FrameResult:
    """Render the stage at ``time_code`` (None: earliest) and write ``out_path`` atomically."""
    started = _time.perf_counter()
    scene, plan = plan_frame(reader, time_code, options)
    timings = {"plan": _time.perf_counter() - started}
    return write_frame(scene, plan, out_path, options, stage=reader.path, time_code=time_code, timings=timings)


def write_frame(scene: Scene, plan: RenderPlan, out_path: Path, options: RenderOptions, *, stage, time_code,
                timings: dict[str, float] | None = None) -> FrameResult:
    """Render a planned frame (``plan_frame``'s scene and plan, of the stage at ``stage`` and ``time_code``) and
    write ``out_path`` atomically, plus the PNG preview when asked."""
    timings = dict(timings or {})
    started = _time.perf_counter()
    layer, layers = render_layers(plan.renderer, scene, plan)
    timings["passes"] = _time.perf_counter() - started
    frame = composite(layers, far=scene.camera.far)
    timings["composite"] = _time.perf_counter() - started - timings["passes"]
    exr = write_exr(
        out_path, frame.rgba, transmittance=frame.transmittance, depth=frame.depth, aovs=frame.aovs,
        metadata=_metadata(scene, plan, options, layer, stage=stage, time_code=time_code),
        half=options.half,
    )
    png = None
    if options.png:
        png = write_png(Path(out_path).with_suffix(".png"), frame.rgba[..., :3],
                        exposure=preview_exposure(scene, options.exposure))
    timings["write"] = _time.perf_counter() - started - timings["passes"] - timings["composite"]
    quality = quality_stats(layer)
    warnings = [w for w in [capped_paths_warning(quality, plan)] if w]
    return FrameResult(Path(exr), png, timings.get("plan", 0.0) + _time.perf_counter() - started,
                       float(layer.stats.get("seconds", 0.0)), time_code, plan, timings, quality, warnings)


def quality_stats(layer: Layer) -> dict:
    """The layer's :data:`QUALITY_STATS` (from the technique's layer, or the media's part of a merged one)."""
    sources = [layer.stats, *[part for part in layer.stats.get("parts", []) if isinstance(part, dict)]]
    out = {}
    for stats in sources:
        for key in QUALITY_STATS:
            if key in stats and key not in out:
                value = stats[key]
                if isinstance(value, float) and not np.isfinite(value):
                    continue  # no estimate yet (a single pass): left out rather than written as inf
                out[key] = value
    return out


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(word.title() for word in rest)


def _metadata(scene: Scene, plan: RenderPlan, options: RenderOptions, layer: Layer, *, stage, time_code) -> dict:
    """The EXR header of a frame."""
    metadata = {
        "stage": str(Path(stage).resolve()),
        "camera": scene.camera.name,
        "timeCode": "earliest" if time_code is None else float(time_code),
        "technique": plan.technique,
        "settings": plan.settings_json(),
        "settingsHash": plan.settings_hash or settings_hash(plan, options, scene),
        "device": plan.device,
        "version": warpsky.__version__,
        "renderSeconds": float(layer.stats.get("seconds", 0.0)),
        "lookups": int(layer.stats.get("lookups", 0)),
    }
    for key, value in quality_stats(layer).items():
        metadata[_camel(key)] = value
    if scene.sun is not None:
        metadata["sun"] = scene.sun.name
    metadata["previewExposure"] = float(preview_exposure(scene, options.exposure))  # contact sheets reuse it
    if scene.layers:
        keys = ("layer", "radiosity", "radiosity_iterations", "radiosity_residual", "radiosity_converged", "seconds")
        metadata["stratiform"] = json.dumps([{k: part[k] for k in keys if k in part}
                                             for part in layer.stats["parts"] if "layer" in part])
    return metadata
