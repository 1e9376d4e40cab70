"""From a composited frame to the channels of one output image: which warpsky outputs, under which names, in
which precision, over which data window.

Without UsdRender prims a frame is written with warpsky's default channels (:func:`default_outputs`): the beauty
as ``R, G, B, A``, ``transmittance.R/G/B``, ``depth.Z`` and every AOV the technique writes. A RenderProduct's
``orderedVars`` choose and order the channels instead (:class:`~warpsky.usd.render_settings.OutputVar`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.output.exr import as_half


@dataclass(frozen=True)
class OutputVar:
    """One channel group of an output image.

    Attributes:
        layer: EXR layer name ("" for the beauty's unprefixed R, G, B, A, which Nuke reads as its rgba layer).
        source: The warpsky output (a key of :data:`SOURCES`).
        components: Channel suffixes written, e.g. ``RGBA``, ``RGB``, ``Z``.
        half: Written as half floats (else 32-bit float).
        prim: The RenderVar prim path, for messages ("" for the built-in default outputs).
    """

    layer: str
    source: str
    components: str
    half: bool = False
    prim: str = ""

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(f"{self.layer}.{c}" if self.layer else c for c in self.components)

FULL_WINDOW = (0.0, 0.0, 1.0, 1.0)


def default_outputs(aov_names=(), *, half: bool = True) -> tuple[OutputVar, ...]:
    """warpsky's own channels: beauty RGBA (half unless ``half`` is False), transmittance, depth and the AOVs."""
    outputs = [OutputVar("", "color", "RGBA", half), OutputVar("transmittance", "transmittance", "RGB"),
               OutputVar("depth", "depth", "Z")]
    outputs += [OutputVar(name, name, "RGB") for name in aov_names]
    return tuple(outputs)


def required_channels(outputs) -> tuple[str, ...]:
    """Every channel name ``outputs`` write, in order."""
    return tuple(channel for output in outputs for channel in output.channels)


def window_pixels(window, width: int, height: int, *, where: str = "dataWindowNDC") -> tuple[int, int, int, int]:
    """Pixel bounds (x0, y0, x1, y1), inclusive, top-left origin, of the pixels whose centres the NDC window
    (xmin, ymin, xmax, ymax; NDC (0, 0) is the image's bottom left, (1, 1) its top right) contains, by the
    rasterisation rule UsdRender names: a centre on the left or top edge is in, one on the right or bottom edge
    out, so windows that share an edge share no pixel and leave none out. Outside the unit square the bounds
    leave the image (overscan: negative or beyond the last pixel), up to one image size on every side."""
    xmin, ymin, xmax, ymax = (float(v) for v in window)
    if min(xmin, ymin) < -1.0 or max(xmax, ymax) > 2.0:
        raise SceneError(f"{where} {tuple(window)} overscans by more than one image size (the window must lie "
                         "within -1..2 in NDC)")
    x0, x1 = math.ceil(xmin * width - 0.5), math.ceil(xmax * width - 0.5) - 1
    y0, y1 = math.ceil((1.0 - ymax) * height - 0.5), math.ceil((1.0 - ymin) * height - 0.5) - 1
    if x1 < x0 or y1 < y0:
        raise SceneError(f"{where} {tuple(window)} holds no pixel centre of the {width}x{height} image")
    return x0, y0, x1, y1


def render_bounds(window, width: int, height: int) -> tuple[int, int, int, int]:
    """Pixel bounds (x0, y0, x1, y1) a frame renders: the image's, grown to the data ``window``'s overscan."""
    x0, y0, x1, y1 = window_pixels(window, width, height)
    return min(x0, 0), min(y0, 0), max(x1, width - 1), max(y1, height - 1)


def _source(frame, output: OutputVar) -> np.ndarray:
    """The (H, W, C) array of ``output``'s source in ``frame``."""
    if output.source == "color":
        return frame.rgba if output.components == "RGBA" else frame.rgba[..., :3]
    if output.source == "alpha":
        return frame.rgba[..., 3:4]
    if output.source == "transmittance":
        return frame.transmittance
    if output.source == "depth":
        return frame.depth[..., None]
    if output.source not in frame.aovs:
        raise SceneError(f"RenderVar {output.prim or output.source}: this render has no {output.source} output "
                         f"(it has {', '.join(sorted(frame.aovs)) or 'no AOVs'})")
    return frame.aovs[output.source]


def frame_channels(frame, outputs, window: tuple[int, int, int, int] | None = None) -> dict[str, np.ndarray]:
    """Channel name -> (h, w) array for ``outputs`` of a composited frame, cropped to the pixel ``window``."""
    channels = {}
    for output in outputs:
        values = _source(frame, output)
        if window is not None:
            x0, y0, x1, y1 = window
            values = values[y0:y1 + 1, x0:x1 + 1]
        for i, name in enumerate(output.channels):
            channels[name] = (as_half(name, values[..., i]) if output.half
                              else np.ascontiguousarray(values[..., i], dtype=np.float32))
    return channels
