"""Benchmark: temporal reuse of the hybrid's paths (``temporal``) on a sequence of frames rendered in one process.

Renders frames 1..``--frames`` of ``--stage`` at ``--size`` with the default technique (plus ``--set``), once per
``--temporal`` value (the history dropped before each sequence; with 0, frames are independent and only the
measured ones are rendered), and prints per frame: seconds of the in-process call, new paths per pixel, the
frame's error estimate, and on the ``--measure`` frames (all of them with ``--static``) the measured net error on
the crop around the cloud's centre against the path tracer's crop at that time code
(:func:`evaluation.benchmarks.bench_frame_error.reference_crop`, cached; with ``--static`` one reference at the
stage's default time, every frame being that scene) and the RMS change from the frame before relative to the level.
An untimed frame first warms the kernel caches.

Run:  python evaluation/benchmarks/bench_temporal.py --static [--stage usd_scenes/cumulus.usda] [--size 384x256]
          [--frames 6] [--temporal 0,0.75] [--reference-spp 1024] [--json out/bench_temporal.json]
      python evaluation/benchmarks/bench_temporal.py --stage usd_scenes/cumulus_wind.usda --frames 24
          --measure 12,24
No pass/fail.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from evaluation.benchmarks.bench_frame_error import cloud_centre, crop_bounds, reference_crop  # noqa: E402


def measured(image, reference: dict, bounds) -> tuple[np.ndarray, dict]:
    """(the crop's radiance, :func:`~evaluation.error_vs_time.error_metrics` against ``reference``)."""
    from evaluation.error_vs_time import error_metrics

    x0, y0, x1, y1 = bounds
    crop = np.asarray(image.frame.rgba)[y0:y1 + 1, x0:x1 + 1, :3]
    return crop, error_metrics(crop, reference["radiance"], reference["covered"], reference["variance"])


def sequence(stage: str, size: tuple[int, int], frames: list[int], temporal: str, references: dict, bounds,
             fixed: dict) -> list[dict]:
    from warpsky.api import render_stage
    from warpsky.techniques.hybrid import history

    history.forget()
    rows, before = [], None
    for frame in frames:
        started = time.perf_counter()
        image = render_stage(stage, time=frame, resolution=size, settings={**fixed, "temporal": temporal})
        seconds = time.perf_counter() - started
        stats = image.layer.stats
        row = {"temporal": float(temporal), "frame": frame, "seconds": round(seconds, 2), "spp": stats.get("spp"),
               "estimate": stats.get("error_estimate")}
        line = (f"temporal {temporal:>5} frame {frame:3d}: {seconds:6.2f} s, {stats.get('spp')} new paths per pixel, "
                f"estimate {stats.get('error_estimate', float('nan')):.2%}")
        if frame in references:
            crop, metrics = measured(image, references[frame], bounds)
            covered = references[frame]["covered"]
            row.update(net=metrics["net_rmse"], bias=metrics["bias"])
            line += f", net {metrics['net_rmse']:.2%}, bias {metrics['bias']:+.2%}"
            if before is not None:
                row["change"] = float(np.sqrt(np.mean((crop - before)[covered] ** 2)) / crop[covered].mean())
                line += f", change {row['change']:.2%}"
            before = crop
        rows.append(row)
        print(line, flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", default=str(ROOT / "usd_scenes" / "cumulus.usda"))
    parser.add_argument("--size", default="384x256")
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--measure", default="", help="frames measured against their own reference")
    parser.add_argument("--static", action="store_true", help="one reference (the stage's default time) for all")
    parser.add_argument("--temporal", default="0,0.75")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--crop-pixels", type=int, default=80)
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    from warpsky.api import render_stage

    size = tuple(int(v) for v in args.size.split("x"))
    fixed = dict(item.split("=", 1) for item in args.set)
    bounds = crop_bounds(cloud_centre(args.stage), *size, args.crop_pixels)
    frames = list(range(1, args.frames + 1))
    if args.static:
        reference = reference_crop(args.stage, size, bounds, args.reference_spp)
        references = {frame: reference for frame in frames}
    else:
        references = {int(f): reference_crop(args.stage, size, bounds, args.reference_spp, time_code=int(f))
                      for f in args.measure.split(",") if f}
    render_stage(args.stage, resolution=size, settings={"spp": "2", "target_error": "0"})  # warm caches
    rows = []
    for value in args.temporal.split(","):
        alone = float(value) == 0.0 and not args.static
        rows += sequence(args.stage, size, sorted(references) if alone else frames, value, references, bounds, fixed)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
