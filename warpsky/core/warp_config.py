"""Warp's configuration for warpsky, applied the moment Warp is imported, so that importing warpsky does not import
Warp (about 0.4 s): ``warpsky --help`` and the argument checks run without it.

warpsky switches off Warp's generation of adjoint (gradient) code before any of its kernel modules is defined (Warp
reads ``warp.config.enable_backward`` when a module is created): warpsky never differentiates a kernel, and without
adjoints its modules compile several times faster (the deck pass's sm_90 module: 64 s with them, 7 s without, on a
2-core CPU). :func:`configure_warp_on_import` sets it at once when Warp is already imported, else when Warp's own
``__init__`` has run, before the module that imported it goes on (an import hook on ``sys.meta_path`` that removes
itself after its one use).
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys


def configure(warp_module) -> None:
    """warpsky's settings of Warp's global configuration."""
    warp_module.config.enable_backward = False


class _ConfigureWarp(importlib.abc.MetaPathFinder):
    """Finds nothing itself: on the import of ``warp`` it takes Warp's own spec and has it run :func:`configure`
    after the package's ``__init__``."""

    def find_spec(self, name, path=None, target=None):
        if name != "warp":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            configure(module)

        spec.loader.exec_module = exec_module
        return spec


def configure_warp_on_import() -> None:
    """Configure Warp now if it is imported, else when it is (once per process)."""
    if sys.modules.get("warp") is not None:
        configure(sys.modules["warp"])
    elif not any(isinstance(finder, _ConfigureWarp) for finder in sys.meta_path):
        sys.meta_path.insert(0, _ConfigureWarp())
