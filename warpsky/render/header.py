"""What a frame's EXR says about itself: warpsky's header values (stage, time, technique, settings and their hash,
the render's statistics, shutter, warnings), OpenEXR's standard attributes (chromaticities, pixel aspect, camera
matrices) and the preview's exposure.

The render's statistics (:func:`quality_stats`: samples, passes, the error estimate, paths stopped at the bounce
cap) also go to the batch log, and a frame whose paths were cut short too often says so
(:func:`capped_paths_warning`).
"""

from __future__ import annotations

import json

import numpy as np

from warpsky.core.image import ImageLayer
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.core.version import __version__
from warpsky.model.scene import Scene, as_imath_rows
from warpsky.output.color import colour_attributes
from warpsky.output.png import auto_exposure, shown_view
from warpsky.render.options import RenderOptions
from warpsky.render.planned import PlannedFrame

#: Figures of a Monte Carlo render that go into the EXR header (camelCase) and the batch log, where present.
QUALITY_STATS = ("spp", "passes", "stopped_by", "error_estimate", "target_error", "capped_paths", "paths",
                 "reused_spp")

#: Fraction of a frame's Monte Carlo paths stopped at ``max_bounces`` above which the render warns: their light is
#: missing from the image (a bias that more samples do not remove).
CAPPED_PATHS_WARNING = 1e-3

#: Channels every warpsky EXR holds.
EXR_CHANNELS = ("R", "G", "B", "A", "transmittance.R", "transmittance.G", "transmittance.B", "depth.Z")


def quality_stats(layer: ImageLayer) -> dict:
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


def capped_paths_warning(quality: dict, plan) -> str | None:
    """One line when more than :data:`CAPPED_PATHS_WARNING` of the frame's paths stopped at ``max_bounces``."""
    capped, paths = int(quality.get("capped_paths", 0)), int(quality.get("paths", 0))
    if paths <= 0 or capped <= CAPPED_PATHS_WARNING * paths:
        return None
    cap = getattr(plan.settings, "max_bounces", "max_bounces")
    return (f"{capped:,} of {paths:,} paths ({capped / paths:.2%}) stopped at max_bounces = {cap} scattering events; "
            "their light is missing from the frame (raise it with --set max_bounces=N)")


def png_exposure(scene: Scene, options: RenderOptions, preview: np.ndarray) -> float:
    """The preview's exposure: :func:`preview_exposure` at ``options.exposure`` stops, or without it the frame's
    own (:func:`~warpsky.output.png.auto_exposure` of the ``preview`` radiance)."""
    if options.exposure is None:
        return auto_exposure(preview)
    return preview_exposure(scene, options.exposure)


def preview_exposure(scene: Scene, stops: float = 0.0) -> float:
    """Scale that maps the radiance of a white Lambertian surface facing the sun to 1 (then ``2**stops``)."""
    if scene.sun is None or float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) <= 0.0:
        return 2.0**stops
    return np.pi / float(scene.sun.irradiance @ LUMINANCE_WEIGHTS) * 2.0**stops


def camera_attributes(camera, width: int, height: int) -> dict:
    """OpenEXR's ``worldToCamera`` (RenderMan's camera space: z > 0 in front) and ``worldToNDC`` (top left (0, 0),
    bottom right (1, 1)) of the camera conformed to the image, as Imath (row-vector) float matrices; world space is
    warpsky's Y-up metres."""
    return {"worldToCamera": as_imath_rows(camera.world_to_camera(left_handed=True)).astype(np.float32),
            "worldToNDC": as_imath_rows(camera.world_to_ndc(width, height)).astype(np.float32)}


def exr_attributes(frame: PlannedFrame) -> dict:
    """OpenEXR's standard attributes of the planned ``frame``: its colour space's chromaticities and white
    luminance, the pixel aspect and the camera matrices."""
    options, plan = frame.options, frame.plan
    attributes = {**colour_attributes(options.colorspace), "pixelAspectRatio": float(options.pixel_aspect)}
    attributes.update(camera_attributes(frame.scene.camera, plan.width, plan.height))
    return attributes


def frame_metadata(frame: PlannedFrame, layer: ImageLayer, channels, preview: np.ndarray, warnings) -> dict:
    """warpsky's header values (written as ``warpsky/<key>``) of the planned ``frame`` rendered into ``layer`` (its
    stats), written as ``channels``, with the ``preview`` radiance (its exposure, which contact sheets reuse) and the
    render's ``warnings``."""
    scene, plan, options = frame.scene, frame.plan, frame.options
    metadata = {
        "stage": str(frame.stage.resolve()),
        "camera": scene.camera.name,
        "timeCode": "earliest" if frame.time_code is None else float(frame.time_code),
        "technique": plan.technique,
        "settings": plan.settings_json(),
        "settingsHash": frame.settings_hash,
        "device": plan.device,
        "version": __version__,
        "renderSeconds": float(layer.stats.get("seconds", 0.0)),
        "lookups": int(layer.stats.get("lookups", 0)),
        "colorspace": options.colorspace,
    }
    for key, value in quality_stats(layer).items():
        metadata[_camel(key)] = value
    if options.deep_output:
        metadata["deepSamples"] = int(options.deep_samples)
    if frame.blurred:
        metadata["shutterOpen"], metadata["shutterClose"] = (float(v) for v in frame.motion)
        metadata["motionSamples"] = int(options.motion_samples)
    if scene.sun is not None:
        metadata["sun"] = scene.sun.name
    parts = layer.stats.get("parts", [layer.stats])
    for runner in plan.pass_runners:
        metadata.update(runner.header(parts))
    metadata["orderedChannels"] = ",".join(channels)
    metadata["previewExposure"] = float(png_exposure(scene, options, preview))
    metadata["previewView"] = shown_view(options.view)
    if warnings:
        metadata["warnings"] = json.dumps(warnings)
    return metadata


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(word.title() for word in rest)
