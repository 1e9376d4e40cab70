"""Render one frame end to end: stage -> scene -> plan -> technique -> composite -> EXR (+ PNG preview)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import warpsky
from warpsky.composite import composite, merge_by_depth
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


def settings_hash(plan: RenderPlan, options: RenderOptions, scene: Scene | None = None) -> str:
    """Short hash of what changes a frame's pixels: the resolved settings, resolution, camera and format, and (with
    ``scene``) the identity of its input files — the stage and every medium's field file by size and modification
    time — so a batch re-renders frames whose data were rewritten (used to resume batches)."""
    inputs = []
    if scene is not None:
        import os

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


def render_layers(technique, scene, plan):
    """(the technique's layer, all layers front to back): with an atmosphere, the media see sunlight reddened by
    the air above them, and the sky pass adds air in front of and behind them plus the sun's disk. Stratiform
    layers are rendered by :func:`render_with_layers`."""
    if scene.layers:
        return render_with_layers(technique, scene, plan)
    if scene.atmosphere is None or getattr(technique, "traces_air", False):
        layer = technique.render(scene, plan.width, plan.height)  # the path tracer carries the air itself
        return layer, [layer]
    from warpsky.techniques.sky.technique import SkyPass, attenuated_sun

    layer = technique.render(attenuated_sun(scene), plan.width, plan.height)
    front, back = SkyPass(device=plan.device).render(scene, plan.width, plan.height, media_depth=layer.depth)
    return layer, [front, layer, back]


def _sun_at_altitude(scene: Scene, altitude: float) -> Scene:
    """``scene`` with its sun reddened by the air above ``altitude`` [m of the stage's y] (Eq. 12)."""
    if scene.atmosphere is None or scene.sun is None:
        return scene
    from warpsky.techniques.sky.analytic import sun_transmittance

    atm = scene.atmosphere
    t = sun_transmittance(atm.beta_sea_level, atm.gamma, altitude + atm.altitude, scene.sun.direction[1])
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, irradiance=scene.sun.irradiance * t))


def render_with_layers(technique, scene, plan):
    """(merged layer, all layers front to back) for a scene with stratiform layers.

    The voxel ``technique`` runs only when there are voxel media, without the ground; each stratiform layer is its
    own Layer (Bouthors slab + radiosity when a ground lies below), lit by the sun reddened down to its mid
    altitude; the lowest layer draws the ground (textured, in the layer's shadow, lit by the radiosity). The media
    and the layers are merged per pixel by depth (:func:`~warpsky.composite.merge_by_depth`), then the sky pass
    splits the air at the merged depth. Not modelled: shadows between voxel media and layers, and of voxel media on
    the ground.
    """
    from warpsky.techniques.stratiform.technique import Stratiform

    width, height = plan.width, plan.height
    parts = []
    if scene.media:
        media_scene = dataclasses.replace(scene, ground=None, layers=())
        if scene.ground is not None and scene.sun is not None and scene.sun.direction[1] <= 0.0:
            media_scene = dataclasses.replace(media_scene, sun=None)  # the ground hides a sun below the horizon
        if scene.atmosphere is not None:
            from warpsky.techniques.sky.technique import attenuated_sun

            media_scene = attenuated_sun(media_scene)
        parts.append(technique.render(media_scene, width, height))
    stratiform = Stratiform(getattr(plan, "layer_settings", None), device=plan.device)
    lowest = min(range(len(scene.layers)), key=lambda i: scene.layers[i].base_altitude)
    for index, layer in enumerate(scene.layers):
        lit = _sun_at_altitude(scene, layer.base_altitude + 0.5 * float(layer.thickness.max()))
        part = stratiform.render(lit, width, height, layer=layer, draw_ground=index == lowest)
        part.stats["layer"] = layer.name
        parts.append(part)
    merged = merge_by_depth(parts, far=scene.camera.far)
    if scene.atmosphere is None:
        return merged, [merged]
    from warpsky.techniques.sky.technique import SkyPass

    front, back = SkyPass(device=plan.device).render(scene, width, height, media_depth=merged.depth)
    return merged, [front, merged, back]


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
        "settingsHash": settings_hash(plan, options, scene),
        "device": plan.device,
        "version": warpsky.__version__,
        "renderSeconds": float(layer.stats.get("seconds", 0.0)),
        "lookups": int(layer.stats.get("lookups", 0)),
    }
    if scene.sun is not None:
        metadata["sun"] = scene.sun.name
    metadata["previewExposure"] = float(preview_exposure(scene, options.exposure))  # contact sheets reuse it
    if scene.layers:
        keys = ("layer", "radiosity", "radiosity_iterations", "radiosity_residual", "radiosity_converged", "seconds")
        metadata["stratiform"] = json.dumps([{k: part[k] for k in keys if k in part}
                                             for part in layer.stats["parts"] if "layer" in part])
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
