"""warpsky: atmospheric phenomena rendered with NVIDIA Warp from USD stages to EXR frames.

Importing this package is cheap: pxr, OpenEXR and warp load only in the modules that need them.
"""

from __future__ import annotations

__version__ = "0.1.0"

from warpsky.errors import SceneError, UsageError, WarpskyError

__all__ = ["SceneError", "UsageError", "WarpskyError", "__version__"]
