"""The frame's clock, so that a time budget is the wall time of the whole frame rather than of one loop in it.

A frame opens its clock (:func:`frame_clock`) when its stage is read (or its passes start); the block ends once its
EXR is written. A progressive technique (the hybrid's paths) spends what is left of its budget after
what ran before it, less what will run after it: the passes that follow, the composite and the write. How long that
took in the last frame of the same shape in this process is recorded when the block ends and expected again
(:func:`expected_after`); a first frame falls back on the technique's prior.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass


@dataclass
class FrameClock:
    """When the frame started and, once its progressive technique is done, when that was [perf_counter s]."""

    started: float
    key: tuple  # the frame's shape (technique, passes, size, device): what it expects to take after the technique
    progressive_done: float | None = None
    parts_left: int = 1  # renders of the frame still to come, this one included (sub-frames of motion blur)


_CLOCK: ContextVar[FrameClock | None] = ContextVar("warpsky_frame_clock", default=None)
#: Seconds the frames took after their progressive technique, by shape, in this process.
_AFTER: dict[tuple, float] = {}


@contextmanager
def frame_clock(key: tuple, started: float | None = None) -> Iterator[FrameClock]:
    """Open the frame's clock for the block, started now or at ``started`` (perf_counter s: when the frame's stage
    read began); when the block ends without an error, record how long the frame ran after its progressive technique
    (if it had one). A frame inside a frame (a sub-frame of motion blur) keeps the outer clock."""
    outer = _CLOCK.get()
    if outer is not None:
        yield outer
        return
    clock = FrameClock(time.perf_counter() if started is None else float(started), key)
    token = _CLOCK.set(clock)
    try:
        yield clock
        if clock.progressive_done is not None:
            _AFTER[key] = time.perf_counter() - clock.progressive_done
    finally:
        _CLOCK.reset(token)


def current() -> FrameClock | None:
    """The open frame clock, or None outside a frame (a technique called on its own)."""
    return _CLOCK.get()


def progressive_done() -> None:
    """Mark that the frame's progressive technique has finished its paths."""
    clock = _CLOCK.get()
    if clock is not None:
        clock.progressive_done = time.perf_counter()


def expected_after(clock: FrameClock | None) -> float | None:
    """Seconds the last frame of ``clock``'s shape ran after its progressive technique, or None."""
    return None if clock is None else _AFTER.get(clock.key)
