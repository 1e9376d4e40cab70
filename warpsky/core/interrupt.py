"""Stopping a render on request (Ctrl-C) within a fraction of a second, anywhere it runs.

Kernels cannot be stopped once launched, so every long launch is split into chunks (row bands on the CPU, see
:func:`warpsky.core.device.launch_rows`; passes of paths) and each chunk starts only if no stop was asked for. The
request is a process-wide flag: the CLI's SIGINT handler sets it (and raises ``KeyboardInterrupt`` in the main
thread, which is waiting on the chunks), a Dask client sets it on its workers (``client.run(request_stop)``), and
the threads running chunks read it between chunks. A render that stops raises :class:`Interrupted`; no output is
written, as EXRs are written only once a frame is complete (and then atomically).

A process that renders for several clients (a Dask worker of a shared cluster) is stopped per batch instead: the
frame's thread runs inside :func:`stop_scope` with the batch's token, and ``request_stop(token)`` stops only the
renders of that scope.

What a stop cannot cut short: one chunk already running (at most a row band, sized to take about
:data:`warpsky.core.device.BAND_SECONDS`) and a kernel being compiled (Warp's compiler runs to its end first).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

_STOP = threading.Event()
_STOPPED_TOKENS: set[str] = set()
_SCOPE = threading.local()


class Interrupted(Exception):  # noqa: N818 - named for what happened, like KeyboardInterrupt
    """The render was asked to stop (Ctrl-C in the CLI, or the batch client stopping its workers)."""

    def __init__(self, message: str = "interrupted"):
        super().__init__(message)


def request_stop(token: str | None = None) -> None:
    """Ask every render in this process (with ``token``: every render in that :func:`stop_scope`) to stop at its
    next chunk."""
    if token is None:
        _STOP.set()
    else:
        _STOPPED_TOKENS.add(token)


def clear_stop() -> None:
    """Forget the process-wide stop request (a new render may start)."""
    _STOP.clear()


def current_scope() -> str | None:
    """The token of the :func:`stop_scope` this thread runs in, if any."""
    return getattr(_SCOPE, "token", None)


def stop_requested(token: str | None = None) -> bool:
    """Whether renders of this process, or of scope ``token``, were asked to stop."""
    return _STOP.is_set() or (token is not None and token in _STOPPED_TOKENS)


def check_stop(token: str | None = None) -> None:
    """Raise :class:`Interrupted` when a stop was asked for (of this process, or of scope ``token``, by default
    the calling thread's)."""
    if stop_requested(token if token is not None else current_scope()):
        raise Interrupted()


@contextlib.contextmanager
def stop_scope(token: str | None):
    """Renders started by this thread while inside stop when ``request_stop(token)`` is called."""
    previous = current_scope()
    _SCOPE.token = token
    try:
        yield
    finally:
        _SCOPE.token = previous


def _on_sigint(signum, frame) -> None:
    _STOP.set()
    raise KeyboardInterrupt


@contextlib.contextmanager
def sigint_stops_renders():
    """While inside, Ctrl-C (SIGINT) sets the stop flag for the threads running chunks and raises
    ``KeyboardInterrupt`` in the main thread; outside, the previous handler is back and the flag cleared. Does
    nothing outside the main thread, where Python cannot install signal handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        _STOP.clear()


@contextlib.contextmanager
def sigint_ignored():
    """SIGINT ignored while inside (child processes started here inherit it: a terminal's Ctrl-C, sent to the
    whole process group, then reaches only the parent, which stops them itself)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def exit_at_once(code: int):
    """Exit the process with ``code`` now, its ``atexit`` handlers run and its output flushed, without unloading the
    libraries it loaded (USD, Warp and numpy take about 0.3 s to unload on a 2-core CPU); for a program whose work is
    done and whose ``finally`` blocks have run."""
    import atexit

    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be said there
            pass
    os._exit(code)


def report_interrupt(*, exit_now: bool = False) -> int:
    """Say "interrupted" on its own line (ending a batch's progress bar first) and return the exit code 130; with
    ``exit_now``, exit the process at once instead: every ``finally`` has run by then (temporary files removed,
    Dask closed), and unloading USD, Warp and numpy would add about half a second before the prompt returns."""
    from tqdm import tqdm

    for bar in list(getattr(tqdm, "_instances", ())):
        bar.close()
    print("warpsky: interrupted", file=sys.stderr)
    if exit_now:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    return 130
