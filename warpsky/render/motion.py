"""Motion blur: a frame seen over the camera's shutter, as the average of sub-frames at stratified times.

A blurred pixel is the time average of what the pixel sees while the shutter is open, (1 / (c - o)) * integral
over [t + o, t + c] of I(s) ds, with o, c the camera's ``shutter:open`` and ``shutter:close`` in frames (or
``--shutter``). warpsky renders the stage at N times, the midpoints of N equal parts of that interval
(``--motion-samples``, default :data:`DEFAULT_SAMPLES`), each read from the stage as any frame is (time-sampled
transforms of Volumes, lights, cameras and meshes, animated attributes, detail advection), and averages them: the
midpoint rule, exact for motion linear within each part and second order otherwise. Radiance, transmittance and
AOVs are averaged (a variance AOV as the variance of the mean, divided by N once more); depth, which does not
blur, is the nearest over the sub-frames. A frame whose shutter is closed (open = close, USD's default) is
rendered once at its time code, bit for bit as without motion blur. Each sub-frame is a full render, so a blurred
frame costs N frames; Monte Carlo techniques may take N times fewer paths per sub-frame for the same noise, their
seed differing per sub-frame (``seed + k``) so the sub-frames' noise does not repeat.

A blurred frame is planned once, at its time code (:mod:`warpsky.render.planned`): every sub-frame renders with the
frame's plan, its technique and passes built and their settings resolved once, and re-reads only what is
time-sampled, the scene at the sub-frame's time. A sub-frame's seed is the frame's typed settings with ``seed``
moved on (:func:`sub_frame_technique`), no text parsed again.

A Volume with a velocity field (a simulation's ``vel`` grid) is read at each sub-frame's time with its density
moved along that velocity from the state its file holds (:mod:`warpsky.media.voxels.velocity`), so a cached simulation
blurs within the frame. A deep EXR of a blurred frame holds every sub-frame's samples, weighted to flatten to the
average (:func:`~warpsky.output.deep.average_deep`). A render without a time code (the API's
``time=None``, the stage's earliest time) is not blurred.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np

#: Sub-frames of a blurred frame unless ``--motion-samples`` says otherwise.
DEFAULT_SAMPLES = 8


def shutter_interval(scene, options) -> tuple[float, float]:
    """(open, close) [frames relative to the frame]: ``options.shutter`` when given, else the camera's."""
    return tuple(options.shutter) if options.shutter is not None else tuple(scene.camera.shutter)


def blurs(scene, options, time_code) -> bool:
    """Whether the frame at ``time_code`` is rendered with motion blur (an open shutter, more than one sample)."""
    open_, close = shutter_interval(scene, options)
    return time_code is not None and close > open_ and options.motion_samples > 1


def sub_frame_times(time_code: float, interval: tuple[float, float], samples: int) -> list[float]:
    """Midpoints of ``samples`` equal parts of ``[time_code + open, time_code + close]``."""
    open_, close = interval
    return [float(time_code) + open_ + (close - open_) * (k + 0.5) / samples for k in range(samples)]


def sub_frame_technique(technique, k: int):
    """The technique of sub-frame ``k``: ``technique`` itself, or one with the same resolved settings but its seed
    moved on by ``k`` when its settings have a seed (a Monte Carlo technique), so the sub-frames' noise differs."""
    settings = technique.settings
    if k == 0 or "seed" not in {f.name for f in dataclasses.fields(settings)}:
        return technique
    return technique.with_settings(replace(settings, seed=settings.seed + k))


def average_frames(frames):
    """One :class:`~warpsky.passes.composite.Frame` from sub-frames: see the module docstring."""
    from warpsky.passes.composite import Frame

    n = len(frames)
    mean = [np.mean([getattr(f, name) for f in frames], axis=0).astype(np.float32) for name in ("rgba",
                                                                                                "transmittance")]
    depth = np.min([f.depth for f in frames], axis=0).astype(np.float32)
    aovs = {}
    for name in frames[0].aovs:
        values = np.mean([f.aovs[name] for f in frames], axis=0)
        aovs[name] = (values / n if name.endswith("variance") else values).astype(np.float32)
    return Frame(mean[0], mean[1], depth, aovs)


def add_stats(layers) -> dict:
    """The first sub-frame's stats with the seconds, lookups and paths of all of them added up."""
    stats = dict(layers[0].stats)
    for key in ("seconds", "lookups", "paths"):
        if key in stats:
            stats[key] = type(stats[key])(sum(layer.stats.get(key, 0) for layer in layers))
    return stats


def average_renders(renders, timings=None):
    """One render (:class:`~warpsky.render.image.FrameRender`) of a frame from those of its sub-frames: the frames
    and previews averaged, the stats' seconds, lookups and paths added up, the deep samples merged
    (:func:`~warpsky.output.deep.average_deep`), every warning once and the seconds per step summed on top of
    ``timings`` (the frame's own, e.g. its planning)."""
    first = renders[0]
    deep = None
    if first.deep is not None:
        from warpsky.output.deep import average_deep

        deep = average_deep([render.deep for render in renders])
    warnings = [line for render in renders for line in render.warnings]
    spent = {key: sum(render.timings.get(key, 0.0) for render in renders) for key in first.timings}
    return replace(first, frame=average_frames([render.frame for render in renders]),
                   preview=np.mean([render.preview for render in renders], axis=0),
                   layer=replace(first.layer, stats=add_stats([render.layer for render in renders])), deep=deep,
                   timings={**dict(timings or {}), **spent}, warnings=list(dict.fromkeys(warnings)))
