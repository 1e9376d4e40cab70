"""Benchmark: the memory estimate ``warpsky info`` prints against the peak resident size of the render it predicts.

For every stage and resolution, ``warpsky render STAGE <tmp>.exr --res WxH --time-budget S`` runs in a fresh
process whose peak resident size (``ru_maxrss``, read by a small launcher process) is the *peak*; the *estimate* is
the plan's host total (:meth:`~warpsky.core.resources.MemoryEstimate.host_total`, what ``warpsky info`` prints as
"memory about ...") for the same stage, resolution, technique and settings, read through the Python API in this
process. The ratio estimate / peak is the figure the estimate is held to (0.8-1.25). A row also gives the
estimate's largest parts. The process baseline (Python with NumPy, Warp and USD imported, before any stage is
opened) is measured once the same way and printed above the table; the estimate includes it, and the opened stage
(:data:`~warpsky.core.resources.PROCESS_BYTES`).

Run:  python evaluation/benchmarks/bench_memory.py [--res 96x64,384x256] [--stages usd_scenes/a.usda,...]
          [--technique hybrid] [--time-budget 2] [--json out/bench_memory.json]
      (one render per stage and size, 18 by default, with warm kernel and table caches; a cold first render
      compiles and builds its tables first). Results and what the estimate counts: docs/validation/memory.md.
No pass/fail: the exit status is 0 whatever the ratios; a failed render is reported and makes it 1.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

#: What the baseline process imports: what every ``warpsky render`` has loaded before it reads a stage.
BASELINE_CODE = ("import numpy, warp, pxr.Usd, warpsky.core.device as d; d.init_warp(); "
                 "import warpsky.api, warpsky.cli.main")


#: A small launcher that runs its arguments and writes their peak resident size [KiB] to the file named first. The
#: peak must be read in a process this small: a child's ``ru_maxrss`` starts from its parent's resident size at the
#: fork (Linux carries the forked address space's high-water mark through ``exec``), and this benchmark's own process
#: holds every stage it has planned.
LAUNCHER = ("import resource, subprocess, sys; code = subprocess.call(sys.argv[2:]); "
            "open(sys.argv[1], 'w').write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)); "
            "sys.exit(code)")


def peak_rss(command: list[str]) -> tuple[int, int, float, str]:
    """(exit status, peak resident size [bytes], wall seconds, the last lines of its output) of ``command`` run in
    a fresh process, started by :data:`LAUNCHER`."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="warpsky-rss-") as tmp:
        result = subprocess.run([sys.executable, "-c", LAUNCHER, f"{tmp}/maxrss", *command], capture_output=True,
                                text=True)
        peak = int(Path(f"{tmp}/maxrss").read_text()) * 1024 if Path(f"{tmp}/maxrss").exists() else 0
    tail = "\n".join((result.stdout + result.stderr).strip().splitlines()[-3:])
    return result.returncode, peak, time.perf_counter() - start, tail


def warpsky_command() -> list[str]:
    """The ``warpsky`` console script beside this interpreter, else ``python -m warpsky.cli.main``."""
    script = Path(sys.executable).with_name("warpsky")
    return [str(script)] if script.exists() else [sys.executable, "-m", "warpsky.cli.main"]


def frame_estimate(stage: Path, width: int, height: int, technique: str | None, budget: float):
    """The plan's memory estimate of ``stage`` at ``width`` x ``height`` as ``warpsky render`` makes it, with the
    frame's device."""
    from warpsky.api import open_stage, render_options
    from warpsky.core.device import init_warp
    from warpsky.render.planned import planned_frame

    init_warp()
    kwargs = {"resolution": (width, height), "settings": {"time_budget": budget}}
    if technique:
        kwargs["technique"] = technique
    explicit = {"resolution"} | ({"technique"} if technique else set())
    reader, _, options = open_stage(stage, render_options(**kwargs), None, explicit=explicit)
    plan = planned_frame(reader, None, options, check=False).plan
    return plan.memory, plan.device, plan.technique


def parse_res(text: str) -> list[tuple[int, int]]:
    return [tuple(int(v) for v in item.lower().split("x")) for item in text.split(",")]


def format_mib(size: float) -> str:
    return f"{size / 2**20:,.0f} MiB"


def measure(stage: Path, width: int, height: int, args, workdir: Path) -> dict:
    """One row: the estimate, the render's peak and their ratio."""
    estimate, device, technique = frame_estimate(stage, width, height, args.technique, args.time_budget)
    total = estimate.host_total(device)
    command = [*warpsky_command(), "render", str(stage), str(workdir / f"{stage.stem}_{width}x{height}.exr"),
               "--res", f"{width}x{height}", "--time-budget", f"{args.time_budget:g}", "-q"]
    if args.technique:
        command += ["--technique", args.technique]
    status, peak, seconds, tail = peak_rss(command)
    return {"stage": stage.name, "resolution": f"{width}x{height}", "technique": technique, "estimate": total,
            "peak": peak, "ratio": total / peak if peak else float("nan"), "status": status, "seconds": seconds,
            "parts": estimate.largest_parts(3), "command": " ".join(["warpsky", *command[len(warpsky_command()):]]),
            **({"error": tail} if status else {})}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stages", default=None, help="comma-separated stages (default: every usd_scenes/*.usda)")
    parser.add_argument("--res", default="96x64,384x256", help="comma-separated resolutions WxH")
    parser.add_argument("--technique", default=None, help="technique (default: the default technique)")
    parser.add_argument("--time-budget", type=float, default=2.0, help="--time-budget of each render [s]")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_memory.json")
    args = parser.parse_args(argv)
    stages = ([Path(s) for s in args.stages.split(",")] if args.stages
              else sorted((ROOT / "usd_scenes").glob("*.usda")))
    _, baseline, _, _ = peak_rss([sys.executable, "-c", BASELINE_CODE])
    print(f"process baseline (Python, NumPy, Warp, USD and warpsky imported): {format_mib(baseline)}")
    print(f"{'stage':<26} {'res':>8} {'estimate':>11} {'peak RSS':>11} {'ratio':>6}  largest parts of the estimate")
    rows, failed = [], 0
    with tempfile.TemporaryDirectory(prefix="warpsky-memory-") as tmp:
        for stage in stages:
            for width, height in parse_res(args.res):
                row = measure(stage, width, height, args, Path(tmp))
                rows.append(row)
                if row["status"]:
                    failed += 1
                    print(f"{row['stage']:<26} {row['resolution']:>8} render failed ({row['status']}): "
                          f"{row['error']}", flush=True)
                    continue
                flag = "" if 0.8 <= row["ratio"] <= 1.25 else "  <- outside 0.8-1.25"
                print(f"{row['stage']:<26} {row['resolution']:>8} {format_mib(row['estimate']):>11} "
                      f"{format_mib(row['peak']):>11} {row['ratio']:>6.2f}  {row['parts']}{flag}", flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"baseline": baseline, "time_budget": args.time_budget, "rows": rows},
                                        indent=1))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
