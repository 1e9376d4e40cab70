"""Error against run time on every shipped stage: ``warpsky bench error-vs-time`` on each ``usd_scenes/*.usda``
(its first time code) with every technique that renders it, against the path tracer's reference, and one table
for the README (per stage and technique, or the pass that draws the stage for it: net relative RMSE, bias and
seconds at the first rung of its ladder and at the last one the budget reached).

Net relative RMSE: the relative RMSE with the reference's own per-pixel variance taken out. A technique that
refuses a stage gets its refusal in the table instead of figures.

Run:  python evaluation/scripts/stage_error_table.py [--stages usd_scenes] [--width 96] [--budget 40] [--reference-spp
1024]
          [--device cpu] [--out out/stages] [--docs docs/error_vs_time/stages.json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

TECHNIQUES = ("hybrid", "single_scatter", "slicing", "path_tracer")


def measure(path: Path, *, width: int, budget: float, reference_spp: int, device: str, log) -> dict:
    """One stage's report as a dict: reference figures, rows, and the techniques that refused it."""
    from evaluation.error_vs_time import run_report
    from warpsky.core.errors import WarpskyError
    from warpsky.render.plan import make_plan, resolve_resolution
    from warpsky.usd.stage import StageReader

    scene = StageReader(str(path)).scene_at(None)
    width, height = resolve_resolution(scene, (width, None))
    rows, refused, reference = [], {}, {}
    accepted = []
    for technique in TECHNIQUES:  # a refusal is a row of its own, not the end of the stage
        try:
            make_plan(scene, technique=technique, resolution=(width, height), device=device)
            accepted.append(technique)
        except WarpskyError as error:
            refused[technique] = str(error)
    started = time.perf_counter()
    report = run_report(scene, techniques=accepted, width=width, height=height, device=device, budget=budget,
                        reference_spp=reference_spp, log=log)
    rows = [asdict(row) for row in report.rows]
    reference = dict(report.reference)
    return {"stage": path.name, "width": width, "height": height, "reference_spp": reference_spp,
            "budget": budget, "seconds": time.perf_counter() - started, "reference": reference, "rows": rows,
            "refused": refused}


def _net(row: dict) -> float:
    """The row's net relative RMSE, or its relative RMSE where the net one is undefined."""
    net = row.get("net_rmse")
    return row["rel_rmse"] if net is None or not math.isfinite(net) else net


def _fmt(row: dict) -> str:
    return f"{_net(row):.2f} / {row['bias']:+.0%} / {row['seconds']:.2g} s"


def table(reports: list[dict]) -> str:
    """Markdown: per stage and measured row family (a technique, or the pass that draws the stage for the
    techniques that leave it to that pass), its first rung and the last one the budget reached."""
    lines = ["| stage | ref noise | row | first rung: net / bias / s | last rung: net / bias / s |",
             "|---|---:|---|---|---|"]
    for report in reports:
        noise = report["reference"].get("rel_noise_per_pixel")
        labels = list(dict.fromkeys(r["technique"] for r in report["rows"]))
        entries = [(label, [r for r in report["rows"] if r["technique"] == label]) for label in labels]
        entries += [(f"{name}: refused ({why})", []) for name, why in report["refused"].items()]
        for index, (label, mine) in enumerate(entries):
            stage = report["stage"] if index == 0 else ""
            noise_text = f"{noise:.3f}" if index == 0 and noise is not None else ""
            if not mine:
                lines.append(f"| {stage} | {noise_text} | {label} | | |")
                continue
            first, last = (r["setting"].replace(", target_error=0", "") for r in (mine[0], mine[-1]))
            lines.append(f"| {stage} | {noise_text} | {label} | {first}: {_fmt(mine[0])} | {last}: {_fmt(mine[-1])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stages", type=Path, default=ROOT / "usd_scenes", help="folder of .usda stages")
    parser.add_argument("--only", default="", help="comma-separated stage names to measure (default: all)")
    parser.add_argument("--width", type=int, default=96, help="image width; height from the camera (default 96)")
    parser.add_argument("--budget", type=float, default=40.0, help="seconds of ladders per stage (default 40)")
    parser.add_argument("--reference-spp", type=int, default=1024, help="reference paths per pixel (default 1024)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "stages", help="per-stage JSON reports")
    parser.add_argument("--docs", type=Path, default=None, help="also write every report into this JSON")
    args = parser.parse_args(argv)
    only = {name.strip() for name in args.only.split(",") if name.strip()}
    stages = sorted(p for p in args.stages.glob("*.usda") if not only or p.name in only or p.stem in only)
    if not stages:
        parser.error(f"no .usda stages in {args.stages}" + (f" named {sorted(only)}" if only else ""))
    args.out.mkdir(parents=True, exist_ok=True)
    reports = []
    for path in stages:
        print(f"{path.name}: measuring", flush=True)
        report = measure(path, width=args.width, budget=args.budget, reference_spp=args.reference_spp,
                         device=args.device, log=lambda line: print(f"  {line}", flush=True))
        (args.out / f"{path.stem}.json").write_text(json.dumps(report, indent=1) + "\n")
        reports.append(report)
    print(table(reports))
    if args.docs is not None:
        command = "python evaluation/scripts/stage_error_table.py "
        command += " ".join(argv if argv is not None else sys.argv[1:])
        args.docs.parent.mkdir(parents=True, exist_ok=True)
        args.docs.write_text(json.dumps({"command": command, "reports": reports}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
