"""Benchmark: is ``--time-budget`` a wall-clock promise? Every shipped stage rendered with the default technique at
each budget, the frame's wall time (from its first pass to its EXR written, as ``FrameResult.seconds`` counts it,
planning included) against the budget, in one process after one untimed frame per stage (warm caches, compiled
kernels). The goal: within max(10 %, 0.25 s) of the budget, or sooner where the frame stopped for another reason
(its error target reached, no paths to add). A stage whose passes that do not adapt (the single-
scattering march, the deck, fog, sky and stratiform passes, the paths' set-up) take longer than a budget cannot
keep it; the table says where the paths had to coarsen (``coarse``: the paths ran on coarser pixels to fit).

Run:  python evaluation/benchmarks/bench_time_budget.py [--res 96x64] [--budgets 1,5,20] [--stages a.usda,b.usda]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

TOLERANCE = 0.10  # of the budget
FLOOR = 0.25  # [s]


def frame_seconds(stage: Path, out: Path, res: tuple[int, int], budget: float | None, device: str) -> dict:
    """One frame of ``stage`` written to ``out``: its wall time, paths per pixel and film scale."""
    from warpsky.api import open_stage, render_options
    from warpsky.render.frame import write_frame
    from warpsky.render.planned import planned_frame

    settings = {} if budget is None else {"time_budget": str(budget)}
    started = time.perf_counter()
    reader, _, options = open_stage(stage, render_options(resolution=res, device=device, settings=settings), None,
                                    explicit={"resolution"})  # as --res: over the stage's render settings
    frame = planned_frame(reader, None, options)
    planned = time.perf_counter() - started
    result = write_frame(frame, out, reader=reader, started=started)
    coarse = any("larger than the frame's" in w for w in result.warnings)
    return {"seconds": planned + result.seconds, "spp": result.quality.get("spp"), "coarse": coarse,
            "stopped_by": result.quality.get("stopped_by", "-"), "warnings": result.warnings}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--res", default="96x64", help="frame size WxH (default 96x64)")
    parser.add_argument("--budgets", default="1,5,20", help="budgets [s], comma-separated (default 1,5,20)")
    parser.add_argument("--stages", default=None, help="comma-separated stages (default: every usd_scenes/*.usda)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_time_budget.json")
    args = parser.parse_args(argv)
    from warpsky.core.device import init_warp

    init_warp()
    width, height = (int(v) for v in args.res.lower().split("x"))
    budgets = [float(b) for b in args.budgets.split(",")]
    stages = ([Path(s) for s in args.stages.split(",")] if args.stages
              else sorted((ROOT / "usd_scenes").glob("*.usda")))
    rows = []
    print(f"{'stage':24s} {'budget':>7s} {'frame s':>8s} {'ratio':>6s} {'kept':>5s} {'spp':>5s} {'coarse':>6s} "
          f"{'stopped by':>11s}")
    with tempfile.TemporaryDirectory() as tmp:
        for stage in stages:
            frame_seconds(stage, Path(tmp) / "warm.exr", (width, height), 0.5, args.device)  # compiles, tables
            for budget in budgets:
                row = frame_seconds(stage, Path(tmp) / f"{stage.stem}_{budget}.exr", (width, height), budget,
                                    args.device)
                # a budget is a limit: a frame that ends sooner because it reached its error target or has no
                # paths to add (a stage of stratiform layers alone) keeps it too
                kept = row["seconds"] - budget <= max(TOLERANCE * budget, FLOOR) and (
                    budget - row["seconds"] <= max(TOLERANCE * budget, FLOOR) or row["stopped_by"] != "time_budget")
                rows.append({"stage": stage.name, "budget": budget, **row, "kept": kept})
                print(f"{stage.name:24s} {budget:7.2f} {row['seconds']:8.2f} {row['seconds'] / budget:6.2f} "
                      f"{'yes' if kept else 'no':>5s} {row['spp'] or 0:5d} {'yes' if row['coarse'] else 'no':>6s} "
                      f"{row['stopped_by']:>11s}",
                      flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"res": args.res, "device": args.device, "rows": rows}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
