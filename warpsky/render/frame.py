"""Render one frame end to end: stage -> scene -> plan -> passes -> composite -> channels -> EXR (+ PNG preview).

The frame is planned once (:mod:`warpsky.render.planned`: a :class:`~warpsky.render.planned.PlannedFrame`), then
rendered (:func:`render_planned`: the passes and the composite, :mod:`warpsky.render.image`; a frame whose shutter
is open as the average of sub-frames, :mod:`warpsky.render.motion`) into a
:class:`~warpsky.render.image.RenderedImage` with its channels and header (:mod:`warpsky.render.header`), which
:func:`write_frame` writes (the command line and batches) and :func:`warpsky.render_stage` returns. The pixels a
data window needs beyond the image (overscan) and its crop: :mod:`warpsky.render.overscan`.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from pathlib import Path

from warpsky.core import deadline, progress
from warpsky.model.scene import Scene
from warpsky.output.exr import write_channels
from warpsky.output.png import write_png
from warpsky.render.compile_progress import compiling_for
from warpsky.render.compile_progress import install as announce_compiles
from warpsky.render.header import quality_stats
from warpsky.render.image import FrameRender, RenderedImage, composited, rendered_image
from warpsky.render.motion import average_renders, sub_frame_technique, sub_frame_times
from warpsky.render.options import RenderOptions
from warpsky.render.plan import RenderPlan
from warpsky.render.planned import PlannedFrame, frame_scene, planned, planned_frame


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


def render_frame(reader, time_code, out_path: Path, options: RenderOptions) -> FrameResult:
    """Render the stage at ``time_code`` (None: earliest) and write ``out_path`` atomically."""
    started = _time.perf_counter()
    frame = planned_frame(reader, time_code, options)
    return write_frame(frame, out_path, timings={"plan": _time.perf_counter() - started}, reader=reader,
                       started=started)


def render_image(scene: Scene, plan: RenderPlan, options: RenderOptions, *, stage, time_code,
                 timings: dict[str, float] | None = None, reader=None) -> RenderedImage:
    """Render a planned frame (``plan`` of ``scene``, the stage at ``stage`` and ``time_code``) into memory: see
    :func:`render_planned`; the frame's settings hash is the plan's when it has one."""
    frame = planned(scene, plan, options, time_code=time_code, stage=stage, digest=plan.settings_hash or None)
    return render_planned(frame, timings=timings, reader=reader)


def render_planned(frame: PlannedFrame, *, timings: dict[str, float] | None = None, reader=None) -> RenderedImage:
    """Render the planned ``frame`` into memory: composited, converted to the output colour space, its channels
    cropped to the data window. With the stage's ``reader`` and an open shutter, the frame is the average of
    sub-frames (:mod:`warpsky.render.motion`)."""
    with deadline.frame_clock(clock_key(frame)):
        return rendered_image(frame_render(frame, timings=timings, reader=reader), frame)


def clock_key(frame: PlannedFrame) -> tuple:
    """The frame's shape for its clock (:mod:`warpsky.core.deadline`): frames of one shape take about as long after
    their progressive technique."""
    plan = frame.plan
    return (plan.technique, plan.passes, plan.width, plan.height, plan.device, bool(frame.options.png),
            frame.options.deep_product)


def frame_render(frame: PlannedFrame, *, timings=None, reader=None) -> FrameRender:
    """The planned ``frame``'s pixels: one render at its time code, or with the stage's ``reader`` and an open
    shutter the average of its sub-frames (:func:`blurred_render`). A kernel module compiled on the way says so
    (:mod:`warpsky.render.compile_progress`)."""
    announce_compiles()
    with compiling_for(frame.plan.technique):
        if reader is not None and frame.blurred:
            return blurred_render(reader, frame, timings)
        return composited(frame.plan, frame.scene, frame.options, timings=timings)


def blurred_render(reader, frame: PlannedFrame, timings=None) -> FrameRender:
    """The average of the frame's sub-frames over its shutter (:mod:`warpsky.render.motion`): each renders with
    the frame's plan (its technique seeded per sub-frame, :func:`~warpsky.render.motion.sub_frame_technique`) and
    the scene read at the sub-frame's time; its deep samples are every sub-frame's, weighted to flatten to that
    average (:func:`~warpsky.output.deep.average_deep`)."""
    options, plan = frame.options, frame.plan
    renders = []
    with reader.sub_frames_of(frame.time_code):  # a Volume's velocity moves its density to each sub-frame's time
        times = sub_frame_times(frame.time_code, frame.motion, options.motion_samples)
        for k, t in enumerate(times):
            clock = deadline.current()
            if clock is not None:  # a time budget is the whole frame's: each sub-frame takes its share of the rest
                clock.parts_left = len(times) - k
            renders.append(composited(plan, frame_scene(reader, t, options), options,
                                      technique=sub_frame_technique(plan.renderer, k)))
    return average_renders(renders, timings)


def write_frame(frame: PlannedFrame, out_path: Path, *, timings: dict[str, float] | None = None, siblings=(),
                reader=None, started: float | None = None) -> FrameResult:
    """Render the planned ``frame`` and write ``out_path`` atomically, plus the PNG preview when asked;
    ``siblings`` ((path, PlannedFrame) pairs: :meth:`~warpsky.render.planned.PlannedFrame.for_options` of
    products with the same camera and resolution) are written from the same render. ``started``: when the frame's
    planning began (perf_counter s), where its time budget starts (default: now)."""
    label = "the frame" if frame.time_code is None else f"frame {frame.time_code:g}"
    with deadline.frame_clock(clock_key(frame), started), progress.working(f"rendering {label}"):
        exr, png, image = _render_and_write(frame, out_path, timings, siblings, reader)
    timings = image.timings
    layer = image.layer
    seconds = sum(timings.get(k, 0.0) for k in ("plan", "passes", "composite", "write"))
    return FrameResult(Path(exr), png, seconds, float(layer.stats.get("seconds", 0.0)), frame.time_code, frame.plan,
                       timings, quality_stats(layer), image.warnings)


def _render_and_write(frame: PlannedFrame, out_path: Path, timings, siblings, reader):
    """(EXR path, PNG path or None, image) of :func:`write_frame`, inside the frame's clock."""
    options = frame.options
    render = frame_render(frame, timings=timings, reader=reader)
    image = rendered_image(render, frame)
    timings = image.timings
    started = _time.perf_counter()
    if image.deep is not None:  # first: the flat frame, written last, is what marks the frame finished
        from warpsky.output.deep import deep_path, write_deep_exr
        from warpsky.output.exr import header_attributes

        deep_out = out_path if options.deep_product else deep_path(out_path)
        exr = write_deep_exr(deep_out, image.deep, header=header_attributes(image.metadata, image.attributes))
    if not options.deep_product:
        exr = _write_image(image, out_path)
    for path, sibling in siblings:
        _write_image(rendered_image(render, sibling), Path(path))
    png = None
    if options.png:
        png = write_png(Path(out_path).with_suffix(".png"), image.preview,
                        exposure=image.metadata["previewExposure"], view=options.view)
    timings["write"] = _time.perf_counter() - started
    return exr, png, image


def _write_image(image: RenderedImage, path: Path) -> Path:
    window = image.window
    return write_channels(path, image.channels, metadata=image.metadata, standard=image.attributes,
                          display=None if window is None else (image.width, image.height),
                          origin=(0, 0) if window is None else (window[0], window[1]))
