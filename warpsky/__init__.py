"""warpsky: atmospheric phenomena rendered with NVIDIA Warp from USD stages to EXR frames.

Importing this package loads nothing heavy: Warp, pxr and OpenEXR load only in the modules that need them (Warp's
configuration, :mod:`warpsky.core.warp_config`, is applied the moment it is imported), and :func:`render_stage` /
:func:`render_to_exr` (:mod:`warpsky.api`) load on first use.
"""

from __future__ import annotations

from warpsky.core.errors import SceneError, UsageError, WarpskyError
from warpsky.core.version import __version__
from warpsky.core.warp_config import configure_warp_on_import

configure_warp_on_import()


__all__ = ["SceneError", "UsageError", "WarpskyError", "__version__", "render_stage", "render_to_exr"]


def __getattr__(name: str):
    if name in ("render_stage", "render_to_exr"):
        from warpsky import api

        return getattr(api, name)
    raise AttributeError(f"module 'warpsky' has no attribute {name!r}")
