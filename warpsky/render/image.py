"""One frame's pixels: the passes' layers composited (:func:`composited`: a :class:`FrameRender`), then the
output that ``warpsky.render_stage`` returns and an EXR is written from (:func:`rendered_image`: a
:class:`RenderedImage`, built whole: channels cropped to the data window, header and attributes).

Several RenderProducts that differ only in their channels and data window are written from one
:class:`FrameRender`, each as its own :class:`RenderedImage`.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.image import ImageLayer, gathered_warnings
from warpsky.model.scene import Scene
from warpsky.output.color import DEFAULT_COLORSPACE, convert_frame
from warpsky.output.products import default_outputs, frame_channels, render_bounds
from warpsky.passes.composite import Frame, composite
from warpsky.passes.frame import render_layers
from warpsky.render.header import capped_paths_warning, exr_attributes, frame_metadata, quality_stats
from warpsky.render.options import RenderOptions
from warpsky.render.overscan import overscanned, window_crop
from warpsky.render.plan import RenderPlan
from warpsky.render.planned import PlannedFrame


@dataclass(frozen=True)
class FrameRender:
    """What the passes and the composite made of a frame (or the average of its sub-frames), before an output is
    chosen.

    Attributes:
        frame: The composited frame in the output colour space, over the rendered pixels (overscan included).
        preview: (H, W, 3) linear Rec.709 radiance of the image's own pixels, for the PNG preview.
        layer: The depth-merged layer of the technique and the other passes (its stats: seconds, samples, ...).
        warnings: One line each from the passes and the technique.
        origin: The rendered frame's first pixel in image pixels (negative with overscan).
        timings: Seconds per step: ``passes``, ``composite`` (and the caller's, e.g. ``plan``).
        deep: The image's deep samples (:class:`~warpsky.output.deep.DeepPixels`) when the options ask for them.
    """

    frame: Frame
    preview: np.ndarray
    layer: ImageLayer
    warnings: list[str]
    origin: tuple[int, int]
    timings: dict
    deep: object = None


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
        scene, plan: The frame's scene and plan (of its time code, for a blurred frame too).
        layer: The depth-merged layer (its stats).
        warnings: One line each from every pass and the technique (a target error not reached, a camera under
            the terrain, paths stopped at the bounce cap): printed by the command line, kept in the batch log and
            written into the EXR header.
        origin: The frame's first pixel in image pixels (negative with overscan).
        deep: The image's deep samples (DeepPixels) when the options ask for them.
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
    origin: tuple[int, int] = (0, 0)
    deep: object = None

    @property
    def width(self) -> int:
        return self.plan.width

    @property
    def height(self) -> int:
        return self.plan.height


def composited(plan: RenderPlan, scene: Scene, options: RenderOptions, *, technique=None, timings=None) -> FrameRender:
    """The frame of ``plan`` at ``scene``'s time: every pass run (with ``technique``, default the plan's), the layers
    composited and converted to the output colour space, over the pixels the data window needs."""
    timings = dict(timings or {})
    started = _time.perf_counter()
    bounds = render_bounds(options.data_window, plan.width, plan.height)
    deep = options.deep_output
    frame_plan, frame_scene = overscanned(plan, scene, bounds)
    layer, layers = render_layers(frame_plan, frame_scene, technique,
                                  deep_samples=options.deep_samples if deep else 0)
    timings["passes"] = _time.perf_counter() - started
    linear = composite(layers, far=scene.camera.far)
    frame = convert_frame(linear, options.colorspace)
    timings["composite"] = _time.perf_counter() - started - timings["passes"]
    x, y = -bounds[0], -bounds[1]  # the image's first pixel in the frame
    preview = linear.rgba[y:y + plan.height, x:x + plan.width, :3]
    warnings = gathered_warnings(layers)
    capped = capped_paths_warning(quality_stats(layer), plan)
    if capped:
        warnings.append(capped)
    samples = image_deep(layers, scene, options, (x, y, plan.width, plan.height)) if deep else None
    return FrameRender(frame, preview, layer, warnings, (bounds[0], bounds[1]), timings, samples)


def image_deep(layers, scene: Scene, options: RenderOptions, region: tuple[int, int, int, int]):
    """The deep samples of the image's pixels (``region`` x, y, width, height of the rendered frame) in the output
    colour space."""
    from warpsky.output.color import matrix_from_rec709
    from warpsky.output.deep import deep_from_layers

    matrix = None if options.colorspace == DEFAULT_COLORSPACE else matrix_from_rec709(options.colorspace)
    return deep_from_layers(layers, scene.camera.far, matrix, region)


def rendered_image(render: FrameRender, frame: PlannedFrame) -> RenderedImage:
    """The output of the planned ``frame`` from ``render``, built whole: its channels cropped to the data window,
    its header and attributes."""
    options = frame.options
    outputs = options.outputs or default_outputs(sorted(render.frame.aovs), half=options.half)
    crop = window_crop(frame.window, render.origin, render.frame.depth.shape, options.data_window)
    channels = frame_channels(render.frame, outputs, crop)
    metadata = frame_metadata(frame, render.layer, channels, render.preview, render.warnings)
    return RenderedImage(render.frame, channels, metadata, exr_attributes(frame), frame.window, render.preview,
                         frame.scene, frame.plan, render.layer, dict(render.timings), list(render.warnings),
                         render.origin, render.deep)
