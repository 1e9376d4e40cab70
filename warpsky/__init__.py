"""warpsky: atmospheric phenomena rendered with NVIDIA Warp from USD stages to EXR frames.

Importing this package loads warp (about 0.35 s, no device initialised) and nothing heavier: pxr and OpenEXR load
only in the modules that need them, and :func:`render_stage` / :func:`render_to_exr` (:mod:`warpsky.api`) load on
first use. It switches off Warp's generation of adjoint (gradient) code before any of warpsky's kernel modules is
defined (Warp reads ``warp.config.enable_backward`` when a module is created): warpsky never differentiates a
kernel, and without adjoints its modules compile several times faster (the deck pass's sm_90 module:
64 s with them, 7 s without, on a 2-core CPU).
"""

from __future__ import annotations

import warp as _wp

from warpsky.core.errors import SceneError, UsageError, WarpskyError
from warpsky.core.version import __version__

_wp.config.enable_backward = False


__all__ = ["SceneError", "UsageError", "WarpskyError", "__version__", "render_stage", "render_to_exr"]


def __getattr__(name: str):
    if name in ("render_stage", "render_to_exr"):
        from warpsky import api

        return getattr(api, name)
    raise AttributeError(f"module 'warpsky' has no attribute {name!r}")
