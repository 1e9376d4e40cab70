"""A line on stderr for every Warp kernel module compiled, when it starts and when it is done.

Warp compiles a kernel module on its first launch and keeps the binary in its kernel cache
(``wp.config.kernel_cache_dir``), under the module's name and a hash of its code (the module hash: its kernels,
every function and struct they use, and the options); a later launch of the same code loads that binary. A first
render on a fresh machine compiles for minutes, which used to be silent. :func:`install` wraps Warp's
``Module._compile`` (called by ``Module.load`` for a module that is not loaded yet) so that a module whose binary is
not in the cache says so before it compiles::

    warpsky: compiling kernels for slicing on cpu: slice_kernel (about 40 s, first use only; cached in
             ~/.cache/warp/1.19.0) ...
    warpsky: ... still compiling slice_kernel (10 s)
    warpsky: ... slice_kernel compiled in 38 s

The estimate (CPU only) is :func:`~warpsky.render.kernel_cache.compile_seconds` of the C++ Warp's code generator has
just written, so the start line follows the code generation (a second at most) and costs nothing extra. A module found
in the cache prints nothing. :func:`compiling_for` names what the kernels are for (the frame's technique). Without
these private methods of Warp (another version) nothing is printed and nothing else changes.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time

from warpsky.core.progress import format_seconds, progress, record, ticking
from warpsky.render.kernel_cache import compile_seconds

#: Seconds between the "still compiling" lines of a long compile.
TICK_SECONDS = 10.0

_STATE = {"label": None, "installed": False}
_THREAD = threading.local()


@contextlib.contextmanager
def compiling_for(label: str | None):
    """Compiles inside the block are announced as kernels for ``label`` (a technique's name)."""
    previous, _STATE["label"] = _STATE["label"], label
    try:
        yield
    finally:
        _STATE["label"] = previous


def short_name(module_name: str) -> str:
    """A module's name as a line shows it: ``fog_kernels`` for ``warpsky.passes.fog.fog_kernels``, ``slice_kernel``
    for a factory-made ``slice_kernel__locals__slicing_kernels_1a2b3c4d``."""
    return module_name.split("__locals__")[0].rsplit(".", 1)[-1]


def _cache_dir() -> str:
    import warp as wp

    return str(wp.config.kernel_cache_dir)


def _is_cached(output_dir, output_name) -> bool:
    import warp as wp

    return bool(wp.config.cache_kernels) and os.path.exists(os.path.join(os.fspath(output_dir), output_name))


def _start_line(module, device, source_bytes: int | None) -> str:
    label = _STATE["label"]
    what = f"kernels for {label}" if label else "Warp kernels"
    estimate = ""
    if source_bytes is not None and str(device).startswith("cpu"):
        estimate = f"about {format_seconds(max(compile_seconds(source_bytes), 1.0))}, "
    return (f"compiling {what} on {device}: {short_name(module.name)} ({estimate}first use only; cached in "
            f"{_cache_dir()}) ...")


def _announce(module, source_bytes: int | None) -> None:
    """Print the start line of the compile this thread has pending, once, and start its "still compiling" ticks."""
    pending = getattr(_THREAD, "pending", None)
    if pending is None or pending["module"] is not module or pending["started"] is not None:
        return
    progress(_start_line(module, pending["device"], source_bytes))
    pending["started"] = time.perf_counter()
    pending["stop"] = ticking(f"compiling {short_name(module.name)}", pending["started"], TICK_SECONDS)[0]


def _wrap_compile(original):
    def _compile(self, device=None, output_dir=None, output_name=None, *args, **kwargs):
        if device is None or output_dir is None or output_name is None or _is_cached(output_dir, output_name):
            return original(self, device, output_dir, output_name, *args, **kwargs)
        pending = {"module": self, "device": device, "started": None, "stop": None}
        outer, _THREAD.pending = getattr(_THREAD, "pending", None), pending
        begun = time.perf_counter()
        try:
            compiled = original(self, device, output_dir, output_name, *args, **kwargs)
        finally:
            if pending["stop"] is not None:
                pending["stop"].set()
            _THREAD.pending = outer
        if compiled:
            seconds = time.perf_counter() - begun
            record("kernels", f"{short_name(self.name)} on {device}", seconds)
            said = "" if pending["started"] is not None else f" on {device} (cached in {_cache_dir()})"
            progress(f"... {short_name(self.name)} compiled{said} in {format_seconds(seconds)}")
        return compiled

    return _compile


def _wrap_codegen(original):
    def _run_codegen(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        source = result[0] if isinstance(result, tuple) and result and isinstance(result[0], str) else None
        _announce(self, None if source is None else len(source))
        return result

    return _run_codegen


def install() -> None:
    """Announce kernel compiles from now on in this process (once; a no-op where Warp lacks the methods)."""
    if _STATE["installed"]:
        return
    _STATE["installed"] = True
    try:
        from warp._src.context import Module
    except ImportError:
        return
    if not (callable(getattr(Module, "_compile", None)) and callable(getattr(Module, "_run_codegen", None))):
        return
    Module._compile = _wrap_compile(Module._compile)
    Module._run_codegen = _wrap_codegen(Module._run_codegen)
