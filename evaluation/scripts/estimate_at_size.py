"""The hybrid's error estimate against its measured error at a shipped image size, on the validation family.

The family's references are 64 x 64 (:mod:`evaluation.family`); the denoiser behaves differently on larger
images (more pixels per cloud feature), so the estimate's calibration chosen there need not hold at the sizes users
render. Per member of ``--half``: an ``--crop`` pixel crop around the cloud's centre at ``--size``, path traced at
``--reference-spp`` and cached (:func:`evaluation.benchmarks.bench_frame_error.reference_crop`), then whole hybrid
frames at each ``--spp`` (every one of its paths kept: a target of 1e-6, so the frame's estimate is computed at
exactly that many paths per pixel), measured on the crop's covered pixels: ``net`` the relative RMSE with the
reference's noise taken out, ``raw`` the estimate before its calibration factor (estimate /
``ESTIMATE_CALIBRATION``), and ``net / raw``, the factor that would have made it exact.

Run:  python evaluation/scripts/estimate_at_size.py --half tune --size 256x256 --spp 16,64 --json out/est_tune.json
      python evaluation/scripts/estimate_at_size.py --half tune --spp 256 --target 0.05 --set adaptive=4
No pass/fail.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from evaluation.benchmarks.bench_frame_error import cloud_centre, crop_bounds, reference_crop  # noqa: E402
from evaluation.error_vs_time import error_metrics  # noqa: E402
from warpsky.api import render_stage  # noqa: E402
from warpsky.cli.options import setting_arg  # noqa: E402
from warpsky.techniques.hybrid.hybrid import ESTIMATE_CALIBRATION  # noqa: E402


def member_rows(stage: str, size: tuple[int, int], crop: int, reference_spp: int, spps: list[int],
                fixed: dict | None = None, target: float | None = None) -> list[dict]:
    """One row per path count for the member ``stage`` (with the hybrid settings ``fixed``); with ``target`` one
    row, the frame rendered to that error target with at most ``spps[-1]`` paths per pixel."""
    bounds = crop_bounds(cloud_centre(stage), *size, crop)
    reference = reference_crop(stage, size, bounds, reference_spp)
    if not reference["covered"].any():
        return []
    x0, y0, x1, y1 = bounds
    rows = []
    for spp in spps[-1:] if target is not None else spps:
        wanted = {**(fixed or {}), "spp": str(spp), "target_error": str(target if target is not None else 1e-6)}
        image = render_stage(stage, resolution=size, settings=wanted)
        radiance = np.asarray(image.frame.rgba)[y0:y1 + 1, x0:x1 + 1, :3]
        metrics = error_metrics(radiance, reference["radiance"], reference["covered"], reference["variance"])
        stats = image.layer.stats
        raw = float(stats.get("error_estimate", math.nan)) / ESTIMATE_CALIBRATION
        net = metrics["net_rmse"]
        # resolved: the reference's own noise is below the error measured (else net is mostly its noise)
        resolved = net > 0 and metrics["rel_rmse"] < 2.0 * net
        rows.append({"spp": spp, "net": net, "rel_rmse": metrics["rel_rmse"], "raw": raw, "bias": metrics["bias"],
                     "factor": net / raw if raw > 0 and resolved else math.nan,
                     "render": float(image.timings.get("passes", math.nan)), "frame_spp": stats.get("spp")})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", type=Path, default=ROOT / "data" / "family")
    parser.add_argument("--half", default="tune", choices=("tune", "test", "all"))
    parser.add_argument("--size", default="256x256")
    parser.add_argument("--crop", type=int, default=64, help="crop edge [px]")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--spp", default="16,64", help="paths per pixel of the hybrid frames")
    parser.add_argument("--only", default=None, help="comma-separated member names")
    parser.add_argument("--set", dest="fixed", type=setting_arg, action="append", default=[], metavar="NAME=VALUE",
                        help="a hybrid setting for every frame (repeatable)")
    parser.add_argument("--target", type=float, default=None, help="render each member once to this error target "
                        "(at most the last --spp paths per pixel) instead of at each --spp")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    spps = [int(v) for v in args.spp.split(",")]
    family = json.loads((args.family / "family.json").read_text())
    rows, fixed = [], dict(args.fixed)
    for member in family["members"]:
        if (args.half != "all" and member["half"] != args.half) or (
                args.only and member["name"] not in args.only.split(",")):
            continue
        for row in member_rows(str(args.family / member["stage"]), size, args.crop, args.reference_spp, spps,
                               fixed, args.target):
            rows.append({"member": member["name"], **row})
            print(f"{member['name']:<20} spp {row['spp']:>4}  net {row['net']:.4f} (raw RMSE {row['rel_rmse']:.4f})"
                  f"  raw estimate {row['raw']:.4f}  net/raw {row['factor']:.2f}  bias {row['bias']:+.4f}"
                  f"  {row['render']:.1f} s ({row['frame_spp']} spp)", flush=True)
    for spp in spps:
        factors = np.array([r["factor"] for r in rows if r["spp"] == spp and math.isfinite(r["factor"])])
        if factors.size:
            print(f"spp {spp}: net/raw over {factors.size} resolved members: geometric mean "
                  f"{math.exp(np.log(factors).mean()):.2f}, median {np.median(factors):.2f}, "
                  f"{factors.min():.2f}..{factors.max():.2f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"size": size, "spp": spps, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
