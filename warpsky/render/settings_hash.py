"""The settings hash: a short digest of everything that changes a frame's pixels, which a batch compares with the
one in a finished EXR's header to skip the frame (:mod:`warpsky.batch.run`).

It covers the plan's resolved settings (:meth:`~warpsky.render.plan.RenderPlan.settings_record`), the
resolution, camera, output format and channels, the shutter of a blurred frame and the identity of every input file
by size and modification time (:func:`input_files`, stat'ed once per frame by :mod:`warpsky.render.planned`), so a
batch renders again the frames whose data were rewritten.
"""

from __future__ import annotations

import hashlib
import json
import os


def input_files(scene) -> tuple[tuple[str, int | None, int | None], ...]:
    """(path, size, modification time [ns]) of each file the scene was read from: the stage, every medium's field
    file (and velocity file) and the dome's texture; (path, None, None) for one that cannot be stat'ed."""
    dome = [scene.dome.source] if scene.dome is not None and scene.dome.source else []
    velocity = [m.velocity_source for m in scene.media if m.velocity_source]
    out = []
    for path in [scene.source, *(m.source for m in scene.media), *velocity, *dome]:
        try:
            info = os.stat(path)
            out.append((str(path), info.st_size, info.st_mtime_ns))
        except (OSError, TypeError, ValueError):
            out.append((str(path), None, None))
    return tuple(out)


def settings_hash(plan, options, inputs=(), motion: tuple[float, float] | None = None) -> str:
    """Short hash of what changes a frame's pixels: ``plan``'s resolved settings, resolution and ``options``' camera
    and format, the ``inputs`` (:func:`input_files`; none for a frame hashed without its scene) and, for a frame
    whose shutter is open, its ``motion`` interval (open, close) and sub-frames."""
    key = json.dumps(
        {"plan": plan.settings_record(), "res": [plan.width, plan.height], "camera": options.camera,
         "half": options.half, "inputs": [list(item) for item in inputs],
         "outputs": [list(o.channels) for o in options.outputs or ()],
         "pixelAspect": options.pixel_aspect, "window": list(options.data_window), "colorspace": options.colorspace,
         "stage": repr(options.stage), **({"deep": True} if options.deep else {}),
         **({"deepProduct": True} if options.deep_product else {}),
         **({"deepSamples": options.deep_samples} if options.deep_output else {}),
         **({"shutter": list(motion), "motionSamples": options.motion_samples} if motion is not None else {})},
        sort_keys=True,
    )
    return hashlib.sha256(key.encode()).hexdigest()[:16]
