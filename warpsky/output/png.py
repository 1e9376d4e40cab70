"""PNG previews of linear Rec.709 radiance through a display view (the EXR stays scene-linear).

The default view is OpenColorIO's: its built-in default config's ``ACES 2.0 - SDR 100 nits (Rec.709)`` view of the
``sRGB - Display`` (a filmic curve: scene 0.18 -> 35 % of display white, 1 -> 71 %, 3 -> 87 %, highlights rolling
off instead of clipping); ``--view`` picks another view of that display (``Un-tone-mapped``, ``Video
(colorimetric)``) or ``simple``, warpsky's own curve that needs no OpenColorIO: per channel y = 1 - exp(-x), then
the sRGB transfer curve. Non-finite or negative input counts as 0. The exposure scales radiance first: by default
from the frame itself, its 99.5th-percentile luminance mapped to 3 (:func:`auto_exposure`), else the renderer's
sun-based scale (a white Lambertian surface facing the sun -> 1) times 2^EV from ``--exposure``. The PNG's text
chunks name the view and the exposure (``warpsky:view``, ``warpsky:exposure``).
"""

from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.core.files import atomic_write

#: OpenColorIO's built-in config, its display, and the default view of the previews.
OCIO_CONFIG = "ocio://default"
DISPLAY = "sRGB - Display"
DEFAULT_VIEW = "ACES 2.0 - SDR 100 nits (Rec.709)"
#: warpsky's own curve (no OpenColorIO needed).
SIMPLE_VIEW = "simple"
#: The automatic exposure maps this percentile of the frame's luminance ...
AUTO_PERCENTILE = 99.5
#: ... to this scene value (87 % of display white in the default view; brighter pixels roll off).
AUTO_LEVEL = 3.0
#: Rec. 709 luminance weights.
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def tonemap(rgb: np.ndarray, *, exposure: float = 1.0) -> np.ndarray:
    """Linear radiance (H, W, 3) -> sRGB-encoded uint8 (H, W, 3)."""
    x = np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    x = np.maximum(x, 0.0) * exposure
    y = -np.expm1(-x)
    encoded = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1.0 / 2.4) - 0.055)
    return np.clip(np.round(encoded * 255.0), 0, 255).astype(np.uint8)


def auto_exposure(rgb: np.ndarray) -> float:
    """The scale that maps the :data:`AUTO_PERCENTILE` percentile of ``rgb``'s luminance (finite, positive pixels)
    to :data:`AUTO_LEVEL`; 1 for a black frame."""
    lum = np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0) @ _LUMINANCE
    lum = lum[lum > 0.0]
    if lum.size == 0:
        return 1.0
    level = float(np.percentile(lum, AUTO_PERCENTILE))
    return AUTO_LEVEL / level if level > 0.0 else 1.0


def color_installed() -> bool:
    """Whether OpenColorIO is installed, asked without importing it (30 ms)."""
    return importlib.util.find_spec("PyOpenColorIO") is not None


def views() -> tuple[str, ...]:
    """The views a preview can take: the OpenColorIO config's views of :data:`DISPLAY` (none without OpenColorIO),
    then :data:`SIMPLE_VIEW`."""
    if not color_installed():
        return (SIMPLE_VIEW,)
    try:
        config = _config()
    except ImportError:
        return (SIMPLE_VIEW,)
    return (*config.getViews(DISPLAY), SIMPLE_VIEW)


@functools.cache
def _config():
    import PyOpenColorIO as OCIO

    return OCIO.Config.CreateFromBuiltinConfig(OCIO_CONFIG)


@functools.cache
def _processor(view: str):
    import PyOpenColorIO as OCIO

    transform = OCIO.DisplayViewTransform(src="Linear Rec.709 (sRGB)", display=DISPLAY, view=view)
    return _config().getProcessor(transform).getDefaultCPUProcessor()


def check_view(view: str) -> str:
    """``view`` when a preview can take it, else a UsageError naming the choices. The default view is always
    accepted: without OpenColorIO :func:`encode` shows it through :data:`SIMPLE_VIEW` (so OpenColorIO, 30 ms,
    loads only for another view or a preview)."""
    if view == DEFAULT_VIEW:
        return view
    choices = views()
    if view != DEFAULT_VIEW and view not in choices:
        missing = "" if len(choices) > 1 else " (OpenColorIO is not installed: pip install 'warpsky[color]')"
        raise UsageError(f"--view {view!r} is not a view of {DISPLAY!r}; choose one of "
                         f"{', '.join(repr(v) for v in choices)}{missing}")
    return view


def encode(rgb: np.ndarray, *, exposure: float = 1.0, view: str = DEFAULT_VIEW) -> np.ndarray:
    """Linear Rec.709 radiance (H, W, 3) -> display-encoded uint8 (H, W, 3) through ``view``; the default view
    falls back to :data:`SIMPLE_VIEW` where OpenColorIO is not installed."""
    view = shown_view(view)
    if view == SIMPLE_VIEW:
        return tonemap(rgb, exposure=exposure)
    check_view(view)
    x = np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    pixels = np.ascontiguousarray((np.maximum(x, 0.0) * exposure).astype(np.float32))
    _processor(view).applyRGB(pixels)
    return np.clip(np.round(np.nan_to_num(pixels) * 255.0), 0, 255).astype(np.uint8)


def shown_view(view: str) -> str:
    """The view :func:`encode` applies for ``view`` (the default without OpenColorIO is the simple curve)."""
    return SIMPLE_VIEW if view == DEFAULT_VIEW and not color_installed() else view


def write_png(path: str | os.PathLike, rgb: np.ndarray, *, exposure: float = 1.0, view: str = DEFAULT_VIEW) -> Path:
    """Write the preview of ``rgb`` through ``view`` at ``exposure`` atomically; its text chunks name both."""
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    image = Image.fromarray(encode(rgb, exposure=exposure, view=view), mode="RGB")
    info = PngInfo()
    info.add_text("warpsky:view", f"{DISPLAY} / {shown_view(view)}")
    info.add_text("warpsky:exposure", f"{exposure:.6g}")
    return atomic_write(path, lambda tmp: image.save(tmp, format="PNG", pnginfo=info))
