"""Device choice and launches that use every CPU core.

Warp runs one CPU launch on one thread but releases the GIL while it runs, so a frame split into row bands and
launched from several Python threads uses all cores (measured on two cores: 2.92 s instead of 5.76 s). On CUDA a
single launch covers the frame. Kernels that want this take ``row_offset`` as their last input and index rows as
``row_offset + tid``. The bands are sized by time (:data:`BAND_SECONDS`), not by count, so that a stop request
(:mod:`warpsky.core.interrupt`) is honoured within a fraction of a second however long the whole launch takes.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import warp as wp

from warpsky.core.errors import UsageError
from warpsky.core.interrupt import check_stop, current_scope, stop_requested


def is_cpu(device) -> bool:
    """Whether ``device`` (a name such as ``cpu`` or ``cuda:0``, or a Warp device) is the CPU."""
    return str(device).startswith("cpu")

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


#: Seconds a CPU row band is sized to take. A stop (Ctrl-C) waits for the bands already running, so about this long.
BAND_SECONDS = 0.1
#: The largest CPU row band, as a fraction of the frame's rows per thread (bounds a band sized on cheap rows that
#: lands on costly ones).
BAND_SHARE = 4

#: Longest time per row [s] seen for a kernel at a frame size, so that the next launch (the next slice, the next
#: pass of paths) sizes its bands right away.
_ROW_SECONDS: dict[tuple, float] = {}


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def _row_pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of ``threads`` row-band workers, started once (a frame's launches reuse its threads
    instead of starting new ones per launch: about 1 ms per thread start on this 2-core machine). Workers only run
    ``wp.launch`` calls and never wait on the pool, so callers on several threads can share it."""
    with _POOLS_LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="warpsky-rows")
        return pool


def launch_rows(kernel, height: int, width: int, inputs: list, device: str) -> None:
    """Launch a per-pixel kernel over ``height`` rows, in parallel row bands on the CPU.

    ``inputs`` are the kernel's arguments without the trailing ``row_offset``. On the CPU the bands are sized from
    the time per row measured so far to take about :data:`BAND_SECONDS`, and a band starts only while no stop was
    asked for (:mod:`warpsky.core.interrupt`); a launch that was stopped raises
    :class:`~warpsky.core.interrupt.Interrupted`, as its output is incomplete.
    """
    check_stop()
    if height <= 0 or width <= 0:
        return
    if not is_cpu(device):
        wp.launch(kernel, dim=(height, width), inputs=[*inputs, 0], device=device)
        return
    # Compile or load the module once, here, not by racing threads, and outside the timed bands.
    wp.load_module(kernel.module, device=device)
    threads = min(cpu_thread_count(), height)
    key = (kernel, height, width)
    bands = RowBands(height, threads, _ROW_SECONDS.get(key), stop_token=current_scope())

    def work() -> None:
        while (band := bands.take()) is not None:
            first, rows = band
            started = time.perf_counter()
            try:
                wp.launch(kernel, dim=(rows, width), inputs=[*inputs, first], device=device)
            except BaseException:
                bands.failed = True
                raise
            bands.record(rows, time.perf_counter() - started)

    try:
        if threads == 1:
            work()
        else:
            pool = _row_pool(threads)
            for future in [pool.submit(work) for _ in range(threads)]:
                future.result()
    finally:
        if bands.row_seconds is not None:
            _ROW_SECONDS[key] = bands.row_seconds
    check_stop(bands.stop_token)


class RowBands:
    """Rows of one launch handed out in bands: the first band per thread is one row (a probe) unless an earlier
    launch measured the time per row; then each band is sized from the longest time per row seen to take about
    :data:`BAND_SECONDS`, growing at most fourfold over the largest band so far and at most 1 / BAND_SHARE of the
    rows per thread. No band is handed out once a stop was asked for or a band failed."""

    def __init__(self, height: int, threads: int, row_seconds: float | None = None, *, stop_token: str | None = None):
        self.height = height
        self.stop_token = stop_token
        self.threads = threads
        self.row_seconds = row_seconds
        self.next_row = 0
        self.largest = 0 if row_seconds is None else height
        self.failed = False
        self._lock = threading.Lock()

    def take(self) -> tuple[int, int] | None:
        """(first row, row count) of the next band, or None when there is none to run."""
        with self._lock:
            if self.failed or self.next_row >= self.height or stop_requested(self.stop_token):
                return None
            rows = 1
            if self.row_seconds is not None:
                rows = int(BAND_SECONDS / max(self.row_seconds, 1e-9))
                rows = min(rows, 4 * max(self.largest, 1), -(-self.height // (self.threads * BAND_SHARE)))
            rows = max(1, min(rows, self.height - self.next_row))
            first = self.next_row
            self.next_row += rows
            return first, rows

    def record(self, rows: int, seconds: float) -> None:
        """A band of ``rows`` rows took ``seconds``."""
        with self._lock:
            self.row_seconds = max(self.row_seconds or 0.0, seconds / rows)
            self.largest = max(self.largest, rows)
