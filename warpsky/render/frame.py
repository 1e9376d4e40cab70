"""Render one frame end to end: stage -> scene -> plan -> passes -> composite -> channels -> EXR (+ PNG preview).

:func:`render_image` stops before the file: it returns the frame's pixels, channels and header in memory (the Python
API's :func:`warpsky.render_stage`); :func:`write_frame` writes them (the command line and batches).
"""

from __future__ import annotations

import hashlib
import json
import os
import time as _time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.core.image import ImageLayer, gathered_warnings
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.core.resources import check_resources
from warpsky.core.version import __version__
from warpsky.model.scene import Scene, as_imath_rows
from warpsky.output.color import DEFAULT_COLORSPACE, colour_attributes, convert_frame
from warpsky.output.deep import average_deep
from warpsky.output.deep_bins import DEEP_SAMPLES
from warpsky.output.exr import write_channels
from warpsky.output.png import DEFAULT_VIEW, auto_exposure, shown_view, write_png
from warpsky.output.products import (
    FULL_WINDOW,
    OutputVar,
    default_outputs,
    frame_channels,
    render_bounds,
    required_channels,
    window_pixels,
)
from warpsky.passes.composite import Frame, composite
from warpsky.passes.frame import render_layers
from warpsky.render.motion import (
    DEFAULT_SAMPLES,
    add_stats,
    average_frames,
    blurs,
    shutter_interval,
    sub_frame_options,
    sub_frame_times,
)
from warpsky.render.plan import RenderPlan, make_plan
from warpsky.render.registry import DEFAULT_TECHNIQUE, aov_producers
from warpsky.usd.render_settings import SOURCES

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
        settings: Settings as ``{name: text or value}`` (``PREFIX.NAME`` for a pass's); unknown names are an
            error.
        resolution: (width, height or None) or None for the stage's render settings / default.
        device: Warp device name, already resolved (``cpu``, ``cuda:0``).
        camera: Camera prim path, or None for the default camera.
        half: Write RGBA as half floats (False: 32-bit float).
        png: Also write a tone-mapped PNG preview next to the EXR.
        deep: Also write a deep scanline EXR next to it (:mod:`warpsky.output.deep`).
        deep_product: The output is itself a deep scanline EXR (a ``deepRaster`` RenderProduct): no flat frame.
        deep_samples: Volume samples per pixel of each volume layer (voxel media, analytic fog) in a deep image,
            1..64 (:mod:`warpsky.output.deep_bins`).
        shutter: (open, close) [frames] overriding the camera's shutter (:mod:`warpsky.render.motion`); None: the
        camera's. motion_samples: Sub-frames of a frame whose shutter is open (:mod:`warpsky.render.motion`).
        exposure: Preview exposure in stops on top of the sun-based normalisation (a white surface facing the sun ->
            1); None: automatic, from the frame's luminance (:func:`~warpsky.output.png.auto_exposure`).
        view: The preview's display view (:mod:`warpsky.output.png`).
        max_memory: Most bytes a frame may allocate on the host and on the device each (None: what is free).
        work_limit: Refuse frames whose worst-case work exceeds :mod:`warpsky.core.resources`' bounds.
        outputs: The channels to write (a RenderProduct's vars), or None for warpsky's default channels.
        pixel_aspect: Width / height of a pixel as displayed (RenderSettings ``pixelAspectRatio``).
        data_window: The part of the image written, (xmin, ymin, xmax, ymax) in NDC (``dataWindowNDC``).
        colorspace: The primaries the EXR's colours are written in (:mod:`warpsky.output.color`).
        stage: How the stage is composed (:class:`~warpsky.usd.composition.StageOptions`; None: defaults).
    """

    technique: str = DEFAULT_TECHNIQUE
    settings: dict = field(default_factory=dict)
    resolution: tuple[int, int | None] | None = None
    device: str = "cpu"
    camera: str | None = None
    half: bool = True
    png: bool = False
    deep: bool = False
    deep_product: bool = False
    deep_samples: int = DEEP_SAMPLES
    shutter: tuple[float, float] | None = None
    motion_samples: int = DEFAULT_SAMPLES
    exposure: float | None = None
    view: str = DEFAULT_VIEW
    max_memory: int | None = None
    work_limit: bool = True
    outputs: tuple[OutputVar, ...] | None = None
    pixel_aspect: float = 1.0
    data_window: tuple[float, float, float, float] = FULL_WINDOW
    colorspace: str = DEFAULT_COLORSPACE
    stage: object = None

    @property
    def required_channels(self) -> tuple[str, ...]:
        """Channels every frame written with these options holds (AOVs left out of the default set)."""
        return required_channels(self.outputs or default_outputs())


@dataclass
class RenderedImage:
    """One frame in memory, before (or instead of) its file.

    Attributes:
        frame: The composited frame in the output colour space: ``rgba``, ``transmittance``, ``depth``, ``aovs``.
        channels: The output's channels by EXR name, cropped to the data window, in the precision written.
        metadata: warpsky's header values (written as ``warpsky/<key>``).
        attributes: OpenEXR's standard attributes (chromaticities, whiteLuminance, camera matrices, ...).
        window: Pixel bounds (x0, y0, x1, y1) of the data window in the full image, or None for all of it.
        preview: (H, W, 3) linear Rec.709 radiance of the whole frame, for the sRGB PNG preview.
        warnings: One line each from every pass and the technique (a target error not reached, a camera under
            the terrain, paths stopped at the bounce cap): printed by the command line, kept in the batch log and
            written into the EXR header.
    """

    frame: Frame
    channels: dict
    metadata: dict
    attributes: dict
    window: tuple[int, int, int, int] | None
    preview: np.ndarray
    scene: Scene
    plan: RenderPlan
    layer: ImageLayer
    timings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    origin: tuple[int, int] = (0, 0)  # the frame's first pixel in image pixels (negative with overscan)
    deep: object = None  # the image's deep samples (DeepPixels) when the options ask for them

    @property
    def width(self) -> int:
        return self.plan.width

    @property
    def height(self) -> int:
        return self.plan.height


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


def plan_frame(reader, time_code, options: RenderOptions, *, check: bool = True) -> tuple[Scene, RenderPlan]:
    """Read the stage at ``time_code`` once and plan the frame: technique built, settings resolved, passes chosen,
    settings hash computed (``plan.settings_hash``); with ``check``, a frame over the memory or work limits is
    refused here (:class:`~warpsky.core.errors.ResourceError`), before anything is allocated, and so is an output the
    technique does not write or a data window without pixels."""
    scene = reader.scene_at(time_code, camera_path=options.camera)
    if options.pixel_aspect != 1.0:
        scene = replace(scene, camera=replace(scene.camera, pixel_aspect=float(options.pixel_aspect)))
    plan = make_plan(
        scene,
        technique=options.technique,
        settings=options.settings,
        resolution=options.resolution,
        device=options.device,
    )
    plan.settings_hash = settings_hash(plan, options, scene)
    check_outputs(options.outputs or (), plan)
    window_pixels(options.data_window, plan.width, plan.height)
    if check:
        check_resources(plan, max_memory=options.max_memory, work_limit=options.work_limit)
    return scene, plan


def check_outputs(outputs, plan: RenderPlan) -> None:
    """Each output is one every frame writes or an AOV of the plan's technique; else a SceneError naming the
    RenderVar and the techniques that write it."""
    for output in outputs:
        if output.source in SOURCES or output.source in plan.renderer.aovs:
            continue
        producers = aov_producers(output.source)
        raise SceneError(f"RenderVar {output.prim or output.source}: source {output.source} is written by "
                         f"technique {' or '.join(producers)}, not {plan.technique}")


def settings_hash(plan: RenderPlan, options: RenderOptions, scene: Scene | None = None) -> str:
    """Short hash of what changes a frame's pixels: the resolved settings, resolution, camera and format, and (with
    ``scene``) the identity of its input files — the stage, every medium's field file (and velocity file) and the
    dome's texture by size and modification time — so a batch re-renders frames whose data were rewritten (used to
    resume batches)."""
    inputs = []
    if scene is not None:
        dome = [scene.dome.source] if scene.dome is not None and scene.dome.source else []
        velocity = [m.velocity_source for m in scene.media if m.velocity_source]
        for path in [scene.source, *(m.source for m in scene.media), *velocity, *dome]:
            try:
                info = os.stat(path)
                inputs.append([str(path), info.st_size, info.st_mtime_ns])
            except (OSError, TypeError, ValueError):
                inputs.append([str(path), None, None])
    key = json.dumps(
        {"plan": json.loads(plan.settings_json()), "res": [plan.width, plan.height], "camera": options.camera,
         "half": options.half, "inputs": inputs, "outputs": [list(o.channels) for o in options.outputs or ()],
         "pixelAspect": options.pixel_aspect, "window": list(options.data_window), "colorspace": options.colorspace,
         "stage": repr(options.stage), **({"deep": True} if options.deep else {}),
         **({"deepProduct": True} if options.deep_product else {}),
         **({"deepSamples": options.deep_samples} if options.deep or options.deep_product else {}),
         **({"shutter": list(shutter_interval(scene, options)), "motionSamples": options.motion_samples}
            if scene is not None and blurs(scene, options, 0.0) else {})},
        sort_keys=True,
    )
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def render_frame(reader, time_code, out_path: Path, options: RenderOptions) -> FrameResult:
    """Render the stage at ``time_code`` (None: earliest) and write ``out_path`` atomically."""
    started = _time.perf_counter()
    scene, plan = plan_frame(reader, time_code, options)
    timings = {"plan": _time.perf_counter() - started}
    return write_frame(scene, plan, out_path, options, stage=reader.path, time_code=time_code, timings=timings,
                       reader=reader)


def render_image(scene: Scene, plan: RenderPlan, options: RenderOptions, *, stage, time_code,
                 timings: dict[str, float] | None = None, reader=None) -> RenderedImage:
    """Render a planned frame (``plan_frame``'s scene and plan, of the stage at ``stage`` and ``time_code``) into
    memory: composited, converted to the output colour space, its channels cropped to the data window. With the
    stage's ``reader`` and an open shutter, the frame is the average of sub-frames (:mod:`warpsky.render.motion`)."""
    if reader is not None and blurs(scene, options, time_code):
        image = blurred_image(reader, scene, plan, options, time_code, timings)
    else:
        image = rendered_image(scene, plan, options, timings)
    return output_image(image, options, stage=stage, time_code=time_code)


def blurred_image(reader, scene: Scene, plan: RenderPlan, options: RenderOptions, time_code,
                  timings) -> RenderedImage:
    """The average of the frame's sub-frames over its shutter (:mod:`warpsky.render.motion`), as the frame at
    ``time_code`` (its scene and plan: camera matrices and metadata); its deep samples are every sub-frame's,
    weighted to flatten to that average (:func:`~warpsky.output.deep.average_deep`)."""
    seeded = "seed" in json.loads(plan.settings_json())
    images = []
    with reader.sub_frames_of(time_code):  # a Volume's velocity moves its density to each sub-frame's time
        for k, t in enumerate(sub_frame_times(time_code, shutter_interval(scene, options), options.motion_samples)):
            sub = sub_frame_options(options, k, seeded)
            images.append(rendered_image(*plan_frame(reader, t, sub), sub, None))
    warnings = [line for image in images for line in image.warnings]
    layer = replace(images[0].layer, stats=add_stats([image.layer for image in images]))
    spent = {key: sum(image.timings.get(key, 0.0) for image in images) for key in images[0].timings}
    deep = average_deep([image.deep for image in images]) if images[0].deep is not None else None
    return replace(images[0], frame=average_frames([image.frame for image in images]), scene=scene, plan=plan,
                   deep=deep,
                   preview=np.mean([image.preview for image in images], axis=0), layer=layer,
                   timings={**dict(timings or {}), **spent}, warnings=list(dict.fromkeys(warnings)))


def rendered_image(scene: Scene, plan: RenderPlan, options: RenderOptions, timings) -> RenderedImage:
    """The frame at the scene's time, composited and converted, before its output channels are chosen."""
    timings = dict(timings or {})
    started = _time.perf_counter()
    bounds = render_bounds(options.data_window, plan.width, plan.height)
    deep = options.deep or options.deep_product
    layer, layers = render_layers(*overscanned(plan, scene, bounds), deep_samples=options.deep_samples if deep else 0)
    timings["passes"] = _time.perf_counter() - started
    linear = composite(layers, far=scene.camera.far)
    frame = convert_frame(linear, options.colorspace)
    timings["composite"] = _time.perf_counter() - started - timings["passes"]
    x, y = -bounds[0], -bounds[1]  # the image's first pixel in the frame
    preview = linear.rgba[y:y + plan.height, x:x + plan.width, :3]
    image = RenderedImage(frame, {}, {}, {}, None, preview, scene, plan, layer, timings,
                          warnings=gathered_warnings(layers), origin=(bounds[0], bounds[1]))
    if deep:
        image.deep = image_deep(layers, scene, options, (x, y, plan.width, plan.height))
    capped = capped_paths_warning(quality_stats(layer), plan)
    if capped:
        image.warnings.append(capped)
    return image


def image_deep(layers, scene: Scene, options: RenderOptions, region: tuple[int, int, int, int]):
    """The deep samples of the image's pixels (``region`` x, y, width, height of the rendered frame) in the output
    colour space."""
    from warpsky.output.color import DEFAULT_COLORSPACE, matrix_from_rec709
    from warpsky.output.deep import deep_from_layers

    matrix = None if options.colorspace == DEFAULT_COLORSPACE else matrix_from_rec709(options.colorspace)
    return deep_from_layers(layers, scene.camera.far, matrix, region)


def output_image(image: RenderedImage, options: RenderOptions, *, stage, time_code) -> RenderedImage:
    """``image`` (rendered once) with the channels, header and data window of the output ``options`` describe:
    several RenderProducts that share a camera and resolution are written from one render."""
    scene, plan = image.scene, image.plan
    outputs = options.outputs or default_outputs(sorted(image.frame.aovs), half=options.half)
    full = tuple(options.data_window) == FULL_WINDOW
    window = None if full else window_pixels(options.data_window, plan.width, plan.height)
    crop = None
    if window is not None:
        x, y = image.origin
        crop = (window[0] - x, window[1] - y, window[2] - x, window[3] - y)
        height, width = image.frame.depth.shape
        if min(crop[:2]) < 0 or crop[2] >= width or crop[3] >= height:
            raise SceneError(f"dataWindowNDC {tuple(options.data_window)} reaches beyond the frame rendered for "
                             "the product it shares a render with")
    channels = frame_channels(image.frame, outputs, crop)
    metadata = _metadata(scene, plan, options, image.layer, stage=stage, time_code=time_code)
    metadata["orderedChannels"] = ",".join(channels)
    metadata["previewExposure"] = float(png_exposure(scene, options, image.preview))  # contact sheets reuse it
    metadata["previewView"] = shown_view(options.view)
    if image.warnings:
        metadata["warnings"] = json.dumps(image.warnings)
    attributes = {**colour_attributes(options.colorspace), "pixelAspectRatio": float(options.pixel_aspect)}
    attributes.update(camera_attributes(scene.camera, plan.width, plan.height))
    return replace(image, channels=channels, metadata=metadata, attributes=attributes, window=window)


def overscanned(plan: RenderPlan, scene: Scene, bounds: tuple[int, int, int, int]) -> tuple[RenderPlan, Scene]:
    """``plan`` and ``scene`` rendering the pixel ``bounds`` (x0, y0, x1, y1) of the image, which may reach
    beyond it (overscan): the camera's film back grown and shifted so the image's pixels stay where they were."""
    width, height = plan.width, plan.height
    x0, y0, x1, y1 = bounds
    if bounds == (0, 0, width - 1, height - 1):
        return plan, scene
    wide, tall = x1 - x0 + 1, y1 - y0 + 1
    camera = scene.camera.conformed(width, height)
    h_ap, v_ap = camera.horizontal_aperture, camera.vertical_aperture
    camera = replace(camera, horizontal_aperture=h_ap * wide / width, vertical_aperture=v_ap * tall / height,
                     horizontal_aperture_offset=camera.horizontal_aperture_offset
                     + h_ap * ((x0 + 0.5 * wide) / width - 0.5),
                     vertical_aperture_offset=camera.vertical_aperture_offset
                     + v_ap * (0.5 - (y0 + 0.5 * tall) / height))
    return replace(plan, width=wide, height=tall), replace(scene, camera=camera)


def _write_image(image: RenderedImage, path: Path) -> Path:
    window = image.window
    return write_channels(path, image.channels, metadata=image.metadata, standard=image.attributes,
                          display=None if window is None else (image.width, image.height),
                          origin=(0, 0) if window is None else (window[0], window[1]))


def write_frame(scene: Scene, plan: RenderPlan, out_path: Path, options: RenderOptions, *, stage, time_code,
                timings: dict[str, float] | None = None, siblings=(), reader=None) -> FrameResult:
    """Render a planned frame (``plan_frame``'s scene and plan, of the stage at ``stage`` and ``time_code``) and
    write ``out_path`` atomically, plus the PNG preview when asked; ``siblings`` ((path, options) pairs of
    products with the same camera and resolution) are written from the same render."""
    image = render_image(scene, plan, options, stage=stage, time_code=time_code, timings=timings, reader=reader)
    timings, layer = image.timings, image.layer
    started = _time.perf_counter()
    if image.deep is not None:  # first: the flat frame, written last, is what marks the frame finished
        from warpsky.output.deep import deep_path, write_deep_exr
        from warpsky.output.exr import header_attributes

        deep_out = out_path if options.deep_product else deep_path(out_path)
        exr = write_deep_exr(deep_out, image.deep, header=header_attributes(image.metadata, image.attributes))
    if not options.deep_product:
        exr = _write_image(image, out_path)
    for path, sibling_options in siblings:
        sibling = output_image(image, sibling_options, stage=stage, time_code=time_code)
        sibling.metadata["settingsHash"] = settings_hash(plan, sibling_options, scene)
        _write_image(sibling, Path(path))
    png = None
    if options.png:
        png = write_png(Path(out_path).with_suffix(".png"), image.preview,
                        exposure=image.metadata["previewExposure"], view=options.view)
    timings["write"] = _time.perf_counter() - started
    quality = quality_stats(layer)
    warnings = image.warnings
    seconds = sum(timings.get(k, 0.0) for k in ("plan", "passes", "composite", "write"))
    return FrameResult(Path(exr), png, seconds, float(layer.stats.get("seconds", 0.0)), time_code, plan, timings,
                       quality, warnings)


def camera_attributes(camera, width: int, height: int) -> dict:
    """OpenEXR's ``worldToCamera`` (RenderMan's camera space: z > 0 in front) and ``worldToNDC`` (top left (0, 0),
    bottom right (1, 1)) of the camera conformed to the image, as Imath (row-vector) float matrices; world space is
    warpsky's Y-up metres."""
    return {"worldToCamera": as_imath_rows(camera.world_to_camera(left_handed=True)).astype(np.float32),
            "worldToNDC": as_imath_rows(camera.world_to_ndc(width, height)).astype(np.float32)}


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


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(word.title() for word in rest)


def _metadata(scene: Scene, plan: RenderPlan, options: RenderOptions, layer: ImageLayer, *, stage, time_code) -> dict:
    """The EXR header of a frame."""
    metadata = {
        "stage": str(Path(stage).resolve()),
        "camera": scene.camera.name,
        "timeCode": "earliest" if time_code is None else float(time_code),
        "technique": plan.technique,
        "settings": plan.settings_json(),
        "settingsHash": plan.settings_hash or settings_hash(plan, options, scene),
        "device": plan.device,
        "version": __version__,
        "renderSeconds": float(layer.stats.get("seconds", 0.0)),
        "lookups": int(layer.stats.get("lookups", 0)),
        "colorspace": options.colorspace,
    }
    for key, value in quality_stats(layer).items():
        metadata[_camel(key)] = value
    if options.deep or options.deep_product:
        metadata["deepSamples"] = int(options.deep_samples)
    if blurs(scene, options, time_code):
        metadata["shutterOpen"], metadata["shutterClose"] = (float(v) for v in shutter_interval(scene, options))
        metadata["motionSamples"] = int(options.motion_samples)
    if scene.sun is not None:
        metadata["sun"] = scene.sun.name
    parts = layer.stats.get("parts", [layer.stats])
    for runner in plan.pass_runners:
        metadata.update(runner.header(parts))
    return metadata
