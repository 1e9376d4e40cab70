"""The default technique as users run it, on a half of the scenery family: ``hybrid`` at its defaults (target 5 %)
with a time budget, at a given size, against the path tracer's references of that size (2048 spp, cached like
``warpsky bench error-vs-time``'s). Per stage: the paths per pixel it stopped at, seconds, its own error estimate,
and the measured relative RMSE over covered pixels, gross and net of the reference's noise, and bias; then the
median, p90 and worst over the half, with and without the fog-under-a-layer members.

Run:  python evaluation/scripts/family_budget_check.py FAMILY_DIR [--half test] [--res 128x128] [--budget 4] [--device
cpu]
          [--json docs/scenery_family/hybrid_128_budget4.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing


def measure(family: Path, half: str, width: int, height: int, budget: float, device: str) -> list[dict]:
    from evaluation.error_vs_time import (
        comparable_scene,
        error_metrics,
        frame_plan,
        reference_image,
        render_frame_radiance,
        scenery_covered,
    )
    from warpsky.render.header import quality_stats
    from warpsky.usd.stage import StageReader

    members = json.loads((family / "family.json").read_text())["members"]
    rows = []
    for member in members:
        if half != "all" and member["half"] != half:
            continue
        scene = comparable_scene(StageReader(str(family / member["stage"])).scene_at(None), log=lambda _: None)
        reference, _, variance, ref_seconds, _ = reference_image(scene, width, height, device, spp=2048,
                                                                 seed=1_000_003)
        covered = scenery_covered(scene, width, height, device)
        render_frame_radiance(frame_plan(scene, "hybrid", {}, 8, 8, device), scene)  # compiles: not timed
        started = time.perf_counter()
        image, _, _, layer = render_frame_radiance(frame_plan(scene, "hybrid", {"time_budget": budget}, width,
                                                              height, device), scene)
        seconds = time.perf_counter() - started
        quality = quality_stats(layer)
        errors = error_metrics(image, reference, covered, reference_variance=variance)
        rows.append({"stage": member["name"], "kind": member["kind"], "reference_seconds": float(ref_seconds),
                     "reference_noise_per_pixel": float(np.sqrt(variance[covered].mean()) / reference[covered].mean()),
                     "spp": quality.get("spp"), "seconds": seconds, "error_estimate": quality.get("error_estimate"),
                     "gross_rel_rmse": errors["rel_rmse"], "net_rel_rmse": errors["net_rmse"], "bias": errors["bias"]})
        row = rows[-1]
        print(f"{row['stage']:<16} ref noise {row['reference_noise_per_pixel']:6.3f}  spp {row['spp']:>4}  "
              f"{seconds:5.1f} s  estimate {row['error_estimate']:.3f}  gross {row['gross_rel_rmse']:.3f}  "
              f"net {row['net_rel_rmse']:.3f}  bias {row['bias']:+.3f}", flush=True)
    return rows


def summary(rows: list[dict]) -> str:
    net = np.array([r["net_rel_rmse"] for r in rows])
    worst = rows[int(np.argmax(net))]["stage"]
    return (f"{len(rows)} stages: net median {np.median(net):.3f}, p90 {np.percentile(net, 90):.3f}, worst "
            f"{net.max():.3f} ({worst}); gross worst {max(r['gross_rel_rmse'] for r in rows):.3f}; mean bias "
            f"{np.mean([r['bias'] for r in rows]):+.1%}; median {np.median([r['seconds'] for r in rows]):.1f} s")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("family", type=Path, help="a scenery family directory (family.json)")
    parser.add_argument("--half", choices=("tune", "test", "all"), default="test")
    parser.add_argument("--res", default="128x128", help="WxH (default 128x128)")
    parser.add_argument("--budget", type=float, default=4.0, help="hybrid's time_budget [s] (default 4)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, default=None, help="write the rows and summaries here")
    args = parser.parse_args(argv)
    try:
        width, height = (int(v) for v in args.res.lower().split("x"))
    except ValueError:
        parser.error(f"--res must be WxH, got {args.res!r}")
    rows = measure(args.family, args.half, width, height, args.budget, args.device)
    if not rows:
        parser.error(f"no {args.half} members in {args.family / 'family.json'}")
    plain = [r for r in rows if r["kind"] != "layer_fog"]
    lines = {"all": summary(rows), **({"without the fog-under-a-layer members": summary(plain)} if plain else {})}
    for label, line in lines.items():
        print(f"{label}: {line}")
    if args.json is not None:
        command = "python evaluation/scripts/family_budget_check.py "
        command += " ".join(argv if argv is not None else sys.argv[1:])
        args.json.write_text(json.dumps({"command": command, "rows": rows, "summary": lines}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
