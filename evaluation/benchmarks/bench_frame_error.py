"""Benchmark: the default technique's *measured* error at the sizes users ship, against its time and its estimate.

At 384x256 and 1920x1080 a path-traced reference is too costly for the whole frame but cheap for a crop around the
cloud's centre, rendered alone through the camera's film back cut to it; the hybrid renders whole frames (under each
``--time-budget``, and with its default error target alone) and is measured on the same crop's covered pixels (the
media alone transmit less than 0.99 of the luminance): ``net`` is the relative RMSE with the reference's own noise
taken out (:func:`evaluation.error_vs_time.error_metrics`), ``estimate`` the frame's own error estimate (what stops
it), ``est/net`` their ratio. Times: ``render`` the frame's passes (the EXR header's renderSeconds), ``call`` the
whole in-process call (stage read, plan, frame), ``march`` the single-scattering march's part of the render, after
one untimed frame per size (warm kernel and table caches).

Run:  python evaluation/benchmarks/bench_frame_error.py [--stage usd_scenes/cumulus.usda]
          [--sizes 384x256,1920x1080] [--budgets 2,5,10,20] [--reference-spp 1024] [--crop-pixels 80]
          [--set uncovered_spp=256] [--json out/bench_frame_error.json]
The references are cached under $WARPSKY_CACHE/reference (by stage file, size, crop, samples, seed and version).
No pass/fail.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from evaluation.error_vs_time import error_metrics, frame_plan, render_frame_radiance  # noqa: E402
from evaluation.family import covered_pixels  # noqa: E402
from warpsky.api import render_stage  # noqa: E402
from warpsky.cli.options import setting_arg  # noqa: E402
from warpsky.core.files import atomic_write, cache_dir  # noqa: E402
from warpsky.core.version import __version__  # noqa: E402
from warpsky.render.overscan import overscanned  # noqa: E402
from warpsky.usd.stage import StageReader  # noqa: E402


def cloud_centre(stage: str) -> tuple[float, float]:
    """NDC (x, y) of the centroid of the pixels the media cover at 96x64 (y down;
    :func:`evaluation.family.covered_pixels`: a noise-free single-scatter frame of the media alone)."""
    covered = covered_pixels(StageReader(stage).scene_at(None), 96, 64, "cpu")
    ys, xs = np.nonzero(covered)
    if xs.size == 0:
        return 0.5, 0.5
    return (float(xs.mean()) + 0.5) / covered.shape[1], (float(ys.mean()) + 0.5) / covered.shape[0]


def crop_bounds(centre: tuple[float, float], width: int, height: int, pixels: int) -> tuple[int, int, int, int]:
    """Pixel bounds (x0, y0, x1, y1), inclusive, of a ``pixels`` x ``pixels`` crop around ``centre``, inside the
    frame."""
    x0 = min(max(int(round(centre[0] * width - 0.5 * pixels)), 0), width - pixels)
    y0 = min(max(int(round(centre[1] * height - 0.5 * pixels)), 0), height - pixels)
    return x0, y0, x0 + pixels - 1, y0 + pixels - 1


def reference_crop(stage: str, size: tuple[int, int], bounds, spp: int, seed: int = 7,
                   time_code: float | None = None) -> dict:
    """The path tracer's crop (radiance, variance of the mean, covered pixels, seconds) at ``time_code`` (None: the
    stage's earliest), cached: the crop rendered alone, through the camera's film back cut to it
    (:func:`warpsky.render.overscan.overscanned`), so its pixels are the frame's."""
    identity = [Path(stage).read_bytes().hex(), size, bounds, spp, seed, __version__]
    if time_code is not None:
        identity.append(float(time_code))
    key = hashlib.sha256(json.dumps(identity).encode())
    path = cache_dir() / "reference" / f"frame_crop_{key.hexdigest()[:20]}.npz"
    if path.is_file():
        with np.load(path) as data:
            return dict(data)
    started = time.perf_counter()
    scene = StageReader(stage).scene_at(time_code)
    plan, cropped = overscanned(frame_plan(scene, "path_tracer", {"spp": spp, "seed": seed}, *size, "cpu"), scene,
                                bounds)
    radiance, _, aovs, _ = render_frame_radiance(plan, cropped)
    out = {"radiance": radiance, "variance": aovs["variance"], "seconds": time.perf_counter() - started,
           "covered": covered_pixels(cropped, plan.width, plan.height, "cpu")}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: np.savez(tmp, **out))
    return out


def hybrid_row(stage: str, size: tuple[int, int], bounds, reference: dict, budget: float | None,
               fixed: dict | None = None) -> dict:
    """One whole hybrid frame (with the settings ``fixed``), measured on the crop ``bounds``."""
    settings = dict(fixed or {}) if budget is None else {**(fixed or {}), "time_budget": str(budget)}
    started = time.perf_counter()
    image = render_stage(stage, resolution=size, settings=settings)
    call = time.perf_counter() - started
    x0, y0, x1, y1 = bounds
    radiance = np.asarray(image.frame.rgba)[y0:y1 + 1, x0:x1 + 1, :3]
    metrics = error_metrics(radiance, reference["radiance"], reference["covered"], reference["variance"])
    stats = image.layer.stats
    estimate = float(stats.get("error_estimate", math.nan))
    net = metrics["net_rmse"]
    return {"size": f"{size[0]}x{size[1]}", "budget": budget, "render": float(image.timings.get("passes", math.nan)),
            "call": call, "march": float(stats.get("single_scatter_seconds", math.nan)), "spp": stats.get("spp"),
            "ms_scale": stats.get("ms_scale"),
            "stopped_by": stats.get("stopped_by"), "estimate": estimate, "net": metrics["net_rmse"],
            "bias": metrics["bias"], "est_over_net": estimate / net if net else math.nan}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", default=str(ROOT / "usd_scenes" / "cumulus.usda"))
    parser.add_argument("--sizes", default="384x256,1920x1080")
    parser.add_argument("--budgets", default="2,5,10,20", help="time budgets [s]; the default target is added")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--crop-pixels", type=int, default=80, help="crop edge [px] at every size")
    parser.add_argument("--set", dest="fixed", type=setting_arg, action="append", default=[], metavar="NAME=VALUE",
                        help="a hybrid setting for every frame (repeatable), e.g. uncovered_spp=256")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    fixed = dict(args.fixed)
    centre = cloud_centre(args.stage)
    rows = []
    print(f"{'size':>10} {'budget':>7} {'render':>8} {'call':>8} {'march':>7} {'spp':>5} {'ms':>3} {'stopped by':>12} "
          f"{'estimate':>9} {'net':>7} {'bias':>7} {'est/net':>8}")
    for text in args.sizes.split(","):
        size = tuple(int(v) for v in text.lower().split("x"))
        bounds = crop_bounds(centre, *size, args.crop_pixels)
        reference = reference_crop(args.stage, size, bounds, args.reference_spp)
        render_stage(args.stage, resolution=size, settings={**fixed, "time_budget": "1"})  # warm: compiles, tables
        for budget in [float(b) for b in args.budgets.split(",") if b] + [None]:
            row = hybrid_row(args.stage, size, bounds, reference, budget, fixed)
            rows.append(row | {"reference_seconds": float(reference["seconds"])})
            print(f"{row['size']:>10} {('-' if budget is None else f'{budget:g} s'):>7} {row['render']:8.2f} "
                  f"{row['call']:8.2f} {row['march']:7.2f} {row['spp']!s:>5} {row['ms_scale']!s:>3} "
                  f"{row['stopped_by']!s:>12} "
                  f"{row['estimate']:9.4f} {row['net']:7.4f} {row['bias']:+7.4f} {row['est_over_net']:8.2f}",
                  flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"centre": centre, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
