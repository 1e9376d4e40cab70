"""Progress lines for slow first-time work (kernel compiles, optics and air tables), so that nothing runs silently for
long: one line on stderr before the work says what it is, about how long it takes and where its result is cached, and
the work is recorded with its time for ``warpsky prepare``'s summary.

``warpsky --quiet`` (or ``$WARPSKY_QUIET=1``, which Dask workers inherit) silences the lines; the records are kept.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

#: The environment variable that silences progress lines (``1``).
QUIET_ENV = "WARPSKY_QUIET"


@dataclass(frozen=True)
class Work:
    """One piece of first-time work done in this process: its kind (``kernels``, ``optics``, ``air``), what it
    was, and its seconds."""

    kind: str
    what: str
    seconds: float


#: Every piece of first-time work done in this process, in order.
DONE: list[Work] = []
_LOCK = threading.Lock()


@contextmanager
def quieted(silence: bool = True):
    """Progress lines silenced inside the block (and in the workers started there), as ``--quiet`` asks; the
    environment is restored after it."""
    if not silence:
        yield
        return
    previous = os.environ.get(QUIET_ENV)
    os.environ[QUIET_ENV] = "1"
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(QUIET_ENV, None)
        else:
            os.environ[QUIET_ENV] = previous


def quiet() -> bool:
    return os.environ.get(QUIET_ENV, "") not in ("", "0")


def progress(message: str) -> None:
    """Print ``warpsky: <message>`` on stderr at once, unless quiet."""
    if not quiet():
        print(f"warpsky: {message}", file=sys.stderr, flush=True)


def record(kind: str, what: str, seconds: float) -> None:
    with _LOCK:
        DONE.append(Work(kind, what, float(seconds)))


def format_seconds(seconds: float) -> str:
    """``0.4 s``, ``12 s``, ``3 min 5 s``."""
    if seconds < 10.0:
        return f"{seconds:.1f} s"
    if seconds < 60.0:
        return f"{seconds:.0f} s"
    minutes, rest = divmod(round(seconds), 60)
    return f"{minutes} min {rest} s"


def ticking(doing: str, started: float, every: float, detail=None) -> tuple[threading.Event, threading.Thread]:
    """Say ``... still <doing> (N s)`` every ``every`` seconds from ``started`` (perf_counter s) on a daemon thread
    until the returned event is set, with ``detail()`` after the seconds where it returns text; (that event, the
    thread)."""
    stop = threading.Event()

    def tick():
        while not stop.wait(every):
            extra = detail() if detail is not None else ""
            elapsed = format_seconds(time.perf_counter() - started)
            progress(f"... still {doing} ({elapsed}{'; ' + extra if extra else ''})")

    thread = threading.Thread(target=tick, name="warpsky-progress", daemon=True)
    thread.start()
    return stop, thread


@contextmanager
def announced(kind: str, what: str, start: str, done: str | None = None, *, every: float = 10.0):
    """Say ``start`` before building ``what`` (a table) in the ``with`` block, ``done`` (``{seconds}`` filled in)
    after it, and, while it runs longer, ``... still building the <what> (N s)`` every ``every`` seconds (Python
    switches threads while the work runs, unless one call into a C library holds the interpreter's lock all along);
    the work is recorded (:data:`DONE`)."""
    progress(start)
    started = time.perf_counter()
    stop, ticker = ticking(f"building the {what}", started, every)
    try:
        yield
    finally:
        stop.set()
        ticker.join()
    seconds = time.perf_counter() - started
    record(kind, what, seconds)
    if done is not None:
        progress(done.format(seconds=format_seconds(seconds)))


#: The status line of the work :func:`working` is timing in this context (a one-item list), or None.
_STATUS: ContextVar[list | None] = ContextVar("warpsky_status", default=None)


@contextmanager
def working(doing: str, every: float = 10.0):
    """Say ``... still <doing> (N s; <status>)`` every ``every`` seconds while the block runs (a frame: nothing for
    one that takes less), with the last :func:`status` the work inside reported."""
    holder = [""]
    token = _STATUS.set(holder)
    stop, ticker = ticking(doing, time.perf_counter(), every, lambda: holder[0])
    try:
        yield
    finally:
        stop.set()
        ticker.join()
        _STATUS.reset(token)


def status(text: str) -> None:
    """Report where the work :func:`working` times stands (shown in its next line); nothing outside one."""
    holder = _STATUS.get()
    if holder is not None:
        holder[0] = text
