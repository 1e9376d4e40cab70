"""Device choice and launches that use every CPU core.

Warp runs one CPU launch on one thread but releases the GIL while it runs, so a frame split into row bands and
launched from several Python threads uses all cores (measured on two cores: 2.92 s instead of 5.76 s). On CUDA a
single launch covers the frame. Kernels that want this take ``row_offset`` as their last input and index rows as
``row_offset + tid``.
"""

from __future__ import annotations

import os
import sys
from concurrent.futures import ThreadPoolExecutor

import warp as wp

from warpsky.errors import UsageError

DEVICE_CHOICES = ("auto", "cpu", "cuda")


def init_warp(*, verbose: bool = False) -> None:
    """Initialise Warp; unless ``verbose``, only errors are logged (no banner, no "no CUDA driver" warning)."""
    if verbose or os.environ.get("WARPSKY_VERBOSE", "") not in ("", "0"):
        wp.init()
        return
    wp.config.log_level = wp.LOG_ERROR
    # Warp's native library prints a "no CUDA driver" warning on CPU-only machines straight to fd 2.
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def resolve_device(name: str = "auto") -> str:
    """Map ``auto``/``cpu``/``cuda``/``cuda:N`` to a Warp device name; ``auto`` prefers CUDA when present."""
    init_warp()
    name = (name or "auto").strip().lower()
    if name == "auto":
        return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"
    if name == "cpu":
        return "cpu"
    if name == "cuda" or name.startswith("cuda:"):
        if wp.get_cuda_device_count() == 0:
            raise UsageError(f"--device {name}: no CUDA device is available on this machine (use cpu or auto)")
        index = 0 if name == "cuda" else int(name.split(":", 1)[1])
        if index >= wp.get_cuda_device_count():
            raise UsageError(f"--device {name}: only {wp.get_cuda_device_count()} CUDA device(s) present")
        return f"cuda:{index}"
    raise UsageError(f"--device must be one of {', '.join(DEVICE_CHOICES)} or cuda:N, got {name!r}")


def cpu_thread_count() -> int:
    """Threads used for CPU launches (``$WARPSKY_CPU_THREADS``, default: all cores)."""
    value = os.environ.get("WARPSKY_CPU_THREADS")
    return max(1, int(value)) if value else max(1, os.cpu_count() or 1)


def launch_rows(kernel, height: int, width: int, inputs: list, device: str) -> None:
    """Launch a per-pixel kernel over ``height`` rows, in parallel row bands on the CPU.

    ``inputs`` are the kernel's arguments without the trailing ``row_offset``.
    """
    if height <= 0 or width <= 0:
        return
    if not str(device).startswith("cpu"):
        wp.launch(kernel, dim=(height, width), inputs=[*inputs, 0], device=device)
        return
    bands = min(cpu_thread_count() * 4, height)
    edges = [round(i * height / bands) for i in range(bands + 1)]

    def run(band: int) -> None:
        rows = edges[band + 1] - edges[band]
        if rows > 0:
            wp.launch(kernel, dim=(rows, width), inputs=[*inputs, edges[band]], device=device)

    # The first band runs alone so that the module is compiled or loaded once, not by racing threads.
    run(0)
    if bands == 1 or cpu_thread_count() == 1:
        for band in range(1, bands):
            run(band)
        return
    with ThreadPoolExecutor(max_workers=cpu_thread_count()) as pool:
        list(pool.map(run, range(1, bands)))
