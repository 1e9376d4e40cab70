"""Render one frame end to end: stage -> scene -> plan -> technique -> composite -> EXR (+ PNG preview)."""

from __future__ import annotations

import hashlib
import json
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import warpsky
from warpsky.composite import composite
from warpsky.plan import RenderPlan, make_plan
from warpsky.scene.model import LUMINANCE_WEIGHTS, Scene
from warpsky.techniques.base import DEFAULT_TECHNIQUE, technique_class

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
    """

    technique: str = DEFAULT_TECHNIQUE
    settings: dict[str, str] = field(default_factory=dict)
    resolution: tuple[int, int | None] | None = None
    device: str = "cpu"
    camera: str | None = None
    half: bool = True
    png: bool = False
    exposure: float = 0.0


@dataclass
class FrameResult:
    exr: Path
    png: Path | None
    seconds: float
    render_seconds: float
    time_code: float | None
    plan: RenderPlan


def preview_exposure(scene: Scene, stops: float = 0.0) -> float:
    """Scale that maps the radiance of a white Lambertian surface facing the sun to 1 (then ``2**stops``)."""
    if scene.sun is None or float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) <= 0.0:
        return 2.0**stops
    return np.pi / float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) * 2.0**stops


def plan_frame(reader, time_code, options: RenderOptions) -> tuple[Scene, RenderPlan]:
    scene = reader.scene_at(time_code, camera_path=options.camera)
    plan = make_plan(
        scene,
        technique=options.technique,
        settings=options.settings,
        resolution=options.resolution,
        device=options.device,
    )
    return scene, plan


def settings_hash(plan: RenderPlan, options: RenderOptions) -> str:
    """Short hash of everything that changes pixels except the stage's content (used to resume batches)."""
    key = json.dumps(
        {"plan": json.loads(plan.settings_json()), "res": [plan.width, plan.height], "camera": options.camera,
         "half": options.half},
        sort_keys=True,
    )
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def render_layers(technique, scene, plan):
    """(the technique's layer, all layers front to back): with an atmosphere, the media see sunlight reddened by
    the air above them, and the sky pass adds air in front of and behind them plus the sun's disk."""
    if scene.atmosphere is None or getattr(technique, "traces_air", False):
        layer = technique.render(scene, plan.width, plan.height)  # the path tracer carries the air itself
        return layer, [layer]
    from warpsky.techniques.sky.technique import SkyPass, attenuated_sun

    layer = technique.render(attenuated_sun(scene), plan.width, plan.height)
    front, back = SkyPass(device=plan.device).render(scene, plan.width, plan.height, media_depth=layer.depth)
    return layer, [front, layer, back]


def render_frame(reader, time_code, out_path: Path, options: RenderOptions) -> FrameResult:
    """Render the stage at ``time_code`` (None: earliest) and write ``out_path`` atomically."""
    from warpsky.output.exr import write_exr

    started = _time.perf_counter()
    scene, plan = plan_frame(reader, time_code, options)
    technique = technique_class(plan.technique)(plan.settings, device=plan.device)
    layer, layers = render_layers(technique, scene, plan)
    frame = composite(layers, far=scene.camera.far)
    metadata = {
        "stage": str(Path(reader.path).resolve()),
        "camera": scene.camera.name,
        "timeCode": "earliest" if time_code is None else float(time_code),
        "technique": plan.technique,
        "settings": plan.settings_json(),
        "settingsHash": settings_hash(plan, options),
        "device": plan.device,
        "version": warpsky.__version__,
        "renderSeconds": float(layer.stats.get("seconds", 0.0)),
        "lookups": int(layer.stats.get("lookups", 0)),
    }
    if scene.sun is not None:
        metadata["sun"] = scene.sun.name
    exr = write_exr(
        out_path, frame.rgba, transmittance=frame.transmittance, depth=frame.depth, aovs=frame.aovs,
        metadata=metadata,
        half=options.half,
    )
    png = None
    if options.png:
        from warpsky.output.png import write_png

        png = write_png(Path(out_path).with_suffix(".png"), frame.rgba[..., :3],
                        exposure=preview_exposure(scene, options.exposure))
    return FrameResult(
        Path(exr), png, _time.perf_counter() - started, float(layer.stats.get("seconds", 0.0)), time_code, plan
    )
