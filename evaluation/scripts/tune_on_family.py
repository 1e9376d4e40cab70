"""Choose a technique's setting on one half of the validation family and report it on the other.

For every value of one setting (``--grid NAME=V1,V2,...``, the other settings fixed by ``--set``), render each
member of ``--half`` at the family's resolution, compare with its cached path-traced reference over the covered
pixels, and print per value: median, p90 and worst relative RMSE (raw, and with the reference's own noise taken
out), median and mean bias, median seconds. The references must be cached (``warpsky bench error-vs-time --family
DIR --half all --references-only``, on a GPU if there is one).

Run:  python evaluation/scripts/tune_on_family.py hybrid --grid mean_radius=-1,3,6,12 --set spp=16 --set target_error=0
      python evaluation/scripts/tune_on_family.py slicing --grid xi=0,0.02,0.05,0.1 --half test --json out/xi_test.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def measure(technique: str, values: dict, family_dir: Path, half: str, width: int, height: int, device: str,
            reference_spp: int, log=print) -> list[dict]:
    """One row per member: rel_rmse, net_rmse, bias, seconds of ``technique`` with ``values``."""
    from evaluation.error_vs_time import error_metrics, frame_plan, reference_image, render_frame_radiance
    from evaluation.family import covered_pixels, family_reference_key, family_reference_path
    from evaluation.family_stages import load_family
    from warpsky.core.errors import UsageError
    from warpsky.usd.stage import StageReader

    rows = []
    for member in load_family(family_dir)["members"]:
        if half != "all" and member["half"] != half:
            continue
        scene = StageReader(family_dir / member["stage"]).scene_at(None)
        key = family_reference_key(scene, width, height, reference_spp, 1_000_003)
        if not family_reference_path(key).is_file():
            raise UsageError(f"no cached reference for {member['stage']} ({reference_spp} spp): render the "
                             "references first (warpsky bench error-vs-time --family ... --references-only)")
        reference, _, variance, _, _ = reference_image(scene, width, height, device, spp=reference_spp,
                                                       seed=1_000_003, cache_path=family_reference_path(key))
        covered = covered_pixels(scene, width, height, device)
        plan = frame_plan(scene, technique, values, width, height, device)
        plan.renderer.render(scene, 8, 8)  # compile / load: not timed
        started = time.perf_counter()
        radiance, _, _, layer = render_frame_radiance(plan, scene)
        seconds = time.perf_counter() - started
        metrics = error_metrics(radiance, reference, covered, variance)
        estimate = float(layer.stats.get("error_estimate", math.nan))
        ratio = estimate / metrics["net_rmse"] if metrics["net_rmse"] > 0 else math.nan
        rows.append({"stage": member["name"], "kind": member["kind"], "seconds": seconds, **metrics,
                     "estimate": estimate, "estimate_ratio": ratio, "spp": layer.stats.get("spp")})
        log(f"    {member['name']:<20} rel RMSE {metrics['rel_rmse']:.4f} net {metrics['net_rmse']:.4f} "
            f"bias {metrics['bias']:+.4f} {seconds:.3f} s"
            + (f"  estimate {estimate:.4f} ({ratio:.2f} x net) at {layer.stats.get('spp')} spp"
               if math.isfinite(estimate) else ""))
    return rows


def summary(rows: list[dict]) -> dict:
    raw = np.array([r["rel_rmse"] for r in rows])
    net = np.array([r["net_rmse"] for r in rows])
    bias = np.array([r["bias"] for r in rows])
    worst = rows[int(np.argmax(net))]["stage"]
    ratios = np.array([r["estimate_ratio"] for r in rows if math.isfinite(r.get("estimate_ratio", math.nan))])
    calibration = ({"ratio_median": float(np.median(ratios)), "ratio_min": float(ratios.min()),
                    "ratio_max": float(ratios.max())} if ratios.size else {})
    return {**calibration, "stages": len(rows), "median": float(np.median(raw)), "p90": float(np.percentile(raw, 90)),
            "worst": float(raw.max()), "net_median": float(np.median(net)), "net_p90": float(np.percentile(net, 90)),
            "net_worst": float(net.max()), "net_worst_stage": worst, "median_bias": float(np.median(bias)),
            "mean_bias": float(bias.mean()), "median_abs_bias": float(np.median(np.abs(bias))),
            "median_seconds": float(np.median([r["seconds"] for r in rows]))}


def grid_value(text: str):
    """A ``--grid`` or ``--set`` value: a whole number, a number, or a word (``auto``) passed on as it is."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("technique")
    parser.add_argument("--grid", required=True, metavar="NAME=V1,V2", help="the setting to vary and its values")
    parser.add_argument("--set", dest="fixed", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--family", type=Path, default=ROOT / "data" / "family")
    parser.add_argument("--half", default="tune", choices=("tune", "test", "all"))
    parser.add_argument("--res", type=int, default=None, help="image size (square) of the references (default: "
                        "the family's, family.json image_size)")
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, default=None, help="write every row and summary here")
    parser.add_argument("--quiet", action="store_true", help="no per-stage lines")
    args = parser.parse_args(argv)

    from warpsky.core.device import init_warp

    init_warp()
    if args.res is None:
        from evaluation.family_stages import load_family

        args.res = int(load_family(args.family).get("image_size", 128))
    name, _, values = args.grid.partition("=")
    fixed = {}
    for item in args.fixed:
        key, _, value = item.partition("=")
        fixed[key] = grid_value(value)
    results = []
    for text in values.split(","):
        value = grid_value(text)
        settings = {**fixed, name: value}
        print(f"{args.technique} {settings}")
        rows = measure(args.technique, settings, args.family, args.half, args.res, args.res, args.device,
                       args.reference_spp, log=(lambda *_: None) if args.quiet else print)
        results.append({"settings": settings, "summary": summary(rows), "rows": rows})
    print(f"\n{args.technique} on the {args.half} half of {args.family} ({args.res}x{args.res}, {args.device}); "
          "net = with the reference's own noise taken out")
    print(f"{name:>12} {'median':>8} {'p90':>8} {'worst':>8} {'net med':>8} {'net p90':>8} {'net worst':>9} "
          f"{'med bias':>9} {'mean bias':>9} {'median s':>9}")
    for r in results:
        s = r["summary"]
        print(f"{r['settings'][name]!s:>12} {s['median']:>8.4f} {s['p90']:>8.4f} {s['worst']:>8.4f} "
              f"{s['net_median']:>8.4f} {s['net_p90']:>8.4f} {s['net_worst']:>9.4f} {s['median_bias']:>+9.4f} "
              f"{s['mean_bias']:>+9.4f} {s['median_seconds']:>9.3f}"
              + (f"   estimate / net: median {s['ratio_median']:.2f}, {s['ratio_min']:.2f}..{s['ratio_max']:.2f}"
                 if "ratio_median" in s else ""))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"technique": args.technique, "half": args.half, "results": results},
                                        indent=1, default=lambda v: None if isinstance(v, float) and math.isnan(v)
                                        else v))
    return 0


if __name__ == "__main__":
    sys.exit(main())
