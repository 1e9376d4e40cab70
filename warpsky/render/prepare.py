"""Everything a frame needs before its first pixel, done ahead of time (``warpsky prepare``): the stage read and the
frame planned, the optics tables its plan needs, and the Warp kernels and air tables its passes use.

Which kernels a frame launches is decided while it renders (each technique picks the variants of its kernel factories
by the scene's features), so they are compiled by a warm-up: the same plan, the same scene and settings, rendered at a
few pixels and thrown away. Every compile and table build on the way prints its progress line and is recorded
(:mod:`warpsky.core.progress`); :func:`prepare_frame` returns the parts with their times. A later render of the frame
finds everything in the caches: Warp's kernel cache and ``$WARPSKY_CACHE``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

from warpsky.core import progress
from warpsky.core.files import cache_dir
from warpsky.optics.prepare import prepare_tables, tables_needed
from warpsky.render.frame import render_planned
from warpsky.render.planned import planned_frame

#: Width [pixels] of the warm-up frame (its height keeps the frame's aspect).
WARM_UP_WIDTH = 8


@dataclass(frozen=True)
class Part:
    """One part of the preparation: its name, seconds, and what it did."""

    name: str
    seconds: float
    detail: str


def warm_up_size(width: int, height: int) -> tuple[int, int]:
    """The warm-up frame's size for a ``width`` x ``height`` frame."""
    small = min(width, WARM_UP_WIDTH)
    return small, max(1, round(small * height / width))


def _table_key(need) -> tuple:
    return need.species, need.kind, need.extra


def _work_detail(work: list, none: str) -> str:
    if not work:
        return none
    return ", ".join(f"{w.what} {progress.format_seconds(w.seconds)}" for w in work)


def prepare_frame(reader, time_code, options) -> tuple[object, list[Part]]:
    """Plan the frame of ``reader``'s stage at ``time_code`` with ``options`` and build what it needs; (the planned
    frame, its parts)."""
    import warp as wp

    mark = len(progress.DONE)
    started = time.perf_counter()
    frame = planned_frame(reader, time_code, options)
    plan = frame.plan
    parts = [Part("plan", time.perf_counter() - started, f"{plan.technique} on {plan.device} at "
                  f"{plan.width}x{plan.height}, passes {' -> '.join(plan.passes)}")]

    started = time.perf_counter()
    needed = tables_needed(frame.scene, plan)
    built = {_table_key(need) for need in prepare_tables(frame.scene, plan)}
    names = [f"{need.species} {need.kind}{need.extra}: {'built' if _table_key(need) in built else 'cached'}"
             for need in needed]
    parts.append(Part("optics tables", time.perf_counter() - started,
                      (", ".join(names) + f" (in {cache_dir() / 'optics'})") if names else "none needed"))

    started = time.perf_counter()
    width, height = warm_up_size(plan.width, plan.height)
    small = planned_frame(reader, time_code, replace(options, resolution=(width, height)), check=False)
    render_planned(small)
    warm = time.perf_counter() - started
    work = progress.DONE[mark:]
    kernels = [w for w in work if w.kind == "kernels"]
    tables = [w for w in work if w.kind not in ("kernels", "optics")]
    cached = f"none compiled: all in Warp's kernel cache ({wp.config.kernel_cache_dir})"
    parts.append(Part("kernels", sum(w.seconds for w in kernels), _work_detail(kernels, cached)))
    parts.append(Part("other tables", sum(w.seconds for w in tables),
                      _work_detail(tables, f"none built: in the cache ({cache_dir()}) or not needed")))
    parts.append(Part("warm-up frame", warm, f"{width}x{height} pixels, compiles and builds included, nothing written"))
    return frame, parts


def format_parts(stage, frame, parts: list[Part]) -> str:
    """The summary ``warpsky prepare`` prints."""
    total = sum(part.seconds for part in parts if part.name in ("plan", "optics tables", "warm-up frame"))
    lines = [f"prepared {stage} in {progress.format_seconds(total)}: a {frame.plan.width}x{frame.plan.height} frame "
             f"of {frame.plan.technique} on {frame.plan.device} now finds its kernels and tables in the caches"]
    lines += [f"  {part.name:<14} {progress.format_seconds(part.seconds):>9}  {part.detail}" for part in parts]
    return "\n".join(lines)
