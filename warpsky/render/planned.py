"""A frame planned once: the scene read at its time code, the plan (technique and passes built, settings resolved),
and the typed values every later step reads instead of working them out again (:class:`PlannedFrame`).

Planning reads the stage, makes the plan (:func:`~warpsky.render.plan.make_plan`), checks the outputs, the data
window and (with ``check``) the memory and work limits, stats the input files and hashes the settings
(:mod:`warpsky.render.settings_hash`), each once. The render (:mod:`warpsky.render.frame`), its motion blur, its
header and a batch's resume check take them from here; a blurred frame's sub-frames reuse the plan and read only
the scene at their own times (:func:`frame_scene`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from warpsky.core.errors import SceneError
from warpsky.core.resources import check_resources
from warpsky.model.scene import Scene
from warpsky.output.products import FULL_WINDOW, window_pixels
from warpsky.render.motion import blurs, shutter_interval
from warpsky.render.options import RenderOptions
from warpsky.render.plan import RenderPlan, make_plan
from warpsky.render.registry import aov_producers
from warpsky.render.settings_hash import input_files, settings_hash
from warpsky.usd.render_settings import SOURCES


@dataclass(frozen=True)
class PlannedFrame:
    """One frame of one output, planned once.

    Attributes:
        scene: The scene at the frame's time code (its camera with the options' pixel aspect).
        plan: The frame's plan: technique and passes built, settings resolved and typed.
        options: How the output is rendered and written.
        time_code: The frame's time code (None: the stage's earliest time, never blurred).
        stage: The stage file it was read from (the EXR header names it).
        motion: (open, close) [frames] when the shutter is open with more than one sub-frame, else None: what the
            settings hash covers (:func:`~warpsky.render.motion.blurs`, whatever the time code).
        window: Pixel bounds (x0, y0, x1, y1) of the data window, or None for the whole image.
        inputs: (path, size, modification time) of every input file (:func:`~warpsky.render.settings_hash.
            input_files`), stat'ed once; None when the frame was given its hash instead.
        settings_hash: :func:`~warpsky.render.settings_hash.settings_hash` of the frame.
    """

    scene: Scene
    plan: RenderPlan
    options: RenderOptions
    time_code: float | None
    stage: Path
    motion: tuple[float, float] | None
    window: tuple[int, int, int, int] | None
    inputs: tuple | None
    settings_hash: str

    @property
    def blurred(self) -> bool:
        """Whether the frame is the average of sub-frames over its shutter (:mod:`warpsky.render.motion`)."""
        return self.motion is not None and self.time_code is not None

    def for_options(self, options: RenderOptions) -> PlannedFrame:
        """The same frame written with other ``options`` that share its render (a sibling RenderProduct: other
        channels or data window): its outputs and window checked, its own settings hash, the files not stat'ed
        again."""
        return planned(self.scene, self.plan, options, time_code=self.time_code, stage=self.stage,
                       inputs=self.inputs)


def frame_scene(reader, time_code, options: RenderOptions) -> Scene:
    """The scene at ``time_code`` as the options see it: through their camera, with their pixel aspect."""
    scene = reader.scene_at(time_code, camera_path=options.camera)
    if options.pixel_aspect != 1.0:
        scene = replace(scene, camera=replace(scene.camera, pixel_aspect=float(options.pixel_aspect)))
    return scene


def planned_frame(reader, time_code, options: RenderOptions, *, check: bool = True) -> PlannedFrame:
    """Read the stage at ``time_code`` once and plan the frame (technique built, settings resolved, passes chosen);
    with ``check``, a frame over the memory or work limits is refused here
    (:class:`~warpsky.core.errors.ResourceError`), before anything is allocated, and so is an output the technique
    does not write or a data window without pixels."""
    scene = frame_scene(reader, time_code, options)
    plan = make_plan(scene, technique=options.technique, settings=options.settings, resolution=options.resolution,
                     device=options.device)
    frame = planned(scene, plan, options, time_code=time_code, stage=reader.path, check=check)
    plan.settings_hash = frame.settings_hash
    return frame


def plan_frame(reader, time_code, options: RenderOptions, *, check: bool = True) -> tuple[Scene, RenderPlan]:
    """:func:`planned_frame`'s (scene, plan), the plan's ``settings_hash`` set."""
    frame = planned_frame(reader, time_code, options, check=check)
    return frame.scene, frame.plan


def planned(scene: Scene, plan: RenderPlan, options: RenderOptions, *, time_code, stage, inputs: tuple | None = None,
            digest: str | None = None, check: bool = False) -> PlannedFrame:
    """``plan`` of ``scene`` as a :class:`PlannedFrame` of ``options``: the outputs and the data window checked, the
    input files stat'ed (unless ``inputs`` are given, or its ``digest``), the settings hashed and, with ``check``,
    the frame's memory and work checked against the limits."""
    motion = shutter_interval(scene, options) if blurs(scene, options, 0.0) else None
    if digest is None:
        inputs = input_files(scene) if inputs is None else inputs
        digest = settings_hash(plan, options, inputs, motion)
    check_outputs(options.outputs or (), plan)
    window = window_pixels(options.data_window, plan.width, plan.height)
    if check:
        check_resources(plan, max_memory=options.max_memory, work_limit=options.work_limit)
    return PlannedFrame(scene, plan, options, time_code, Path(stage), motion,
                        None if tuple(options.data_window) == FULL_WINDOW else window, inputs, digest)


def check_outputs(outputs, plan: RenderPlan) -> None:
    """Each output is one every frame writes or an AOV of the plan's technique; else a SceneError naming the
    RenderVar and the techniques that write it."""
    for output in outputs:
        if output.source in SOURCES or output.source in plan.renderer.aovs:
            continue
        producers = aov_producers(output.source)
        raise SceneError(f"RenderVar {output.prim or output.source}: source {output.source} is written by "
                         f"technique {' or '.join(producers)}, not {plan.technique}")
