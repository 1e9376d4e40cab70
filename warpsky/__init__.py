"""warpsky: atmospheric phenomena rendered with NVIDIA Warp from USD stages to EXR frames.

Importing this package is cheap: pxr, OpenEXR and warp load only in the modules that need them, and
:func:`render_stage` / :func:`render_to_exr` (:mod:`warpsky.api`) load on first use.
"""

from __future__ import annotations

__version__ = "0.1.0"

from warpsky.errors import SceneError, UsageError, WarpskyError

__all__ = ["SceneError", "UsageError", "WarpskyError", "__version__", "render_stage", "render_to_exr"]


def __getattr__(name: str):
    if name in ("render_stage", "render_to_exr"):
        from warpsky import api

        return getattr(api, name)
    raise AttributeError(f"module 'warpsky' has no attribute {name!r}")
