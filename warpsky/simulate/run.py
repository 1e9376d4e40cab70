"""A whole ``warpsky simulate`` run: the solver stepped from frame to frame, each frame written as it is reached,
with a progress line every few seconds."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import warp as wp

from warpsky.core.errors import UsageError
from warpsky.core.progress import format_seconds, progress
from warpsky.simulate.solver import CloudSolver, SimulationSettings
from warpsky.simulate.sounding import Sounding, write_sounding

#: Seconds between progress lines.
PROGRESS_SECONDS = 5.0


@dataclass(frozen=True)
class RunSummary:
    """What a run did: the stage, the frames' seconds of storm life, wall seconds, steps and the water budget's
    relative change."""

    stage: Path
    frame_count: int
    storm_seconds: float
    wall_seconds: float
    step_count: int
    water_change: float


def simulate(sounding: Sounding, settings: SimulationSettings, *, frames: int, minutes: float, out: Path,
             device: str = "cpu", name: str = "storm") -> RunSummary:
    """Simulate ``minutes`` of storm life from ``sounding`` and write ``frames`` frames evenly over them (the last at
    the end; frame 1 at the first interval) into ``out/<name>/`` with the stage ``out/<name>.usda`` and the
    sounding used (``out/<name>.input_sounding``)."""
    from warpsky.simulate.frames import FrameWriter, weather_state

    if frames < 1:
        raise UsageError(f"--frames must be at least 1, got {frames}")
    if not minutes > 0.0:
        raise UsageError(f"--minutes must be positive, got {minutes}")
    out = Path(out)
    write_sounding(out / f"{name}.input_sounding", sounding)
    seconds_per_frame = 60.0 * minutes / frames
    started = time.perf_counter()
    with wp.ScopedDevice(device):
        solver = CloudSolver(sounding, settings, device)
        writer = FrameWriter(out / name, out / f"{name}.usda", seconds_per_frame)
        water_start = solver.water_total()
        progress(f"simulate: the grid moves at {solver.domain_speed[0]:.1f}, {solver.domain_speed[1]:.1f} m/s "
                 "(along x, along y) with the storm")
        last_line = [time.perf_counter()]

        def report(s: CloudSolver) -> None:
            now = time.perf_counter()
            if now - last_line[0] >= PROGRESS_SECONDS:
                last_line[0] = now
                progress(f"simulate: {s.time / 60.0:5.1f} of {minutes:g} min, step {s.step_count}, "
                         f"{format_seconds(now - started)} (projection: {s.projection.iterations} iterations)")

        fields = None
        for frame in range(1, frames + 1):
            solver.run(seconds_per_frame, callback=report)
            fields = solver.fields()
            writer.write(weather_state(fields, solver.base, (settings.dx, settings.dy), solver.time,
                                       solver.domain_speed))
            top = _cloud_top(fields, settings.dy)
            progress(f"simulate: frame {frame}/{frames} at {solver.time / 60.0:.1f} min written "
                     f"(cloud top {top / 1000.0:.1f} km, {format_seconds(time.perf_counter() - started)})")
        change = solver.water_total(fields) / water_start - 1.0
    return RunSummary(writer.stage, frames, solver.time, time.perf_counter() - started, solver.step_count, change)


def _cloud_top(fields: dict, spacing: float, threshold: float = 1.0e-5) -> float:
    """Height [m] of the top of the highest level holding more than ``threshold`` kg/kg of condensate (0: none)."""
    levels = (fields["cloud"].max(axis=(0, 2)) > threshold).nonzero()[0]
    return float((levels.max() + 1) * spacing) if len(levels) else 0.0
