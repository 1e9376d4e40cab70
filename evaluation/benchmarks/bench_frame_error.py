"""Benchmark: the default technique's *measured* error at the sizes users ship, against its time and its estimate.

At 384x256 and 1920x1080 a path-traced reference of a crop (``dataWindowNDC``) around the cloud's centre is too
costly for the whole frame but cheap for the crop; the hybrid renders whole frames (under each ``--time-budget``,
and with its default error target alone) and is measured on the same crop's covered pixels (the media alone
transmit less than 0.99 of the luminance): ``net`` is the relative RMSE with the reference's own noise taken out
(:func:`evaluation.error_vs_time.error_metrics`), ``estimate`` the frame's own error estimate (what stops it),
``est/net`` their ratio. Times: ``render`` the frame's passes (the EXR header's renderSeconds), ``call`` the whole
in-process call (stage read, plan, frame), ``march`` the single-scattering march's part of the render, after one
untimed frame per size (warm kernel and table caches).

Run:  python evaluation/benchmarks/bench_frame_error.py [--stage usd_scenes/cumulus.usda]
          [--sizes 384x256,1920x1080] [--budgets 2,5,10,20] [--reference-spp 1024] [--crop-pixels 80]
          [--json out/bench_frame_error.json]
The references are cached under $WARPSKY_CACHE/reference (by stage file, size, crop, samples and seed).
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

from evaluation.error_vs_time import error_metrics  # noqa: E402
from evaluation.family import covered_pixels  # noqa: E402
from warpsky.api import render_stage  # noqa: E402
from warpsky.core.files import atomic_write, cache_dir  # noqa: E402
from warpsky.usd.stage import StageReader  # noqa: E402


def media_covered(stage: str, size: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the pixels the media cover (:func:`evaluation.family.covered_pixels`: a noise-free
    single-scatter frame of the media alone)."""
    scene = StageReader(stage).scene_at(None)
    return covered_pixels(scene, size[0], size[1], "cpu")


def cloud_centre(stage: str) -> tuple[float, float]:
    """NDC (x, y) of the centroid of the pixels the media cover at 96x64 (y down)."""
    covered = media_covered(stage, (96, 64))
    ys, xs = np.nonzero(covered)
    if xs.size == 0:
        return 0.5, 0.5
    return (float(xs.mean()) + 0.5) / covered.shape[1], (float(ys.mean()) + 0.5) / covered.shape[0]


def crop_window(centre: tuple[float, float], width: int, height: int, pixels: int) -> tuple[float, ...]:
    """NDC window (xmin, ymin, xmax, ymax) of about ``pixels`` x ``pixels`` around ``centre``, inside the frame."""
    half_x, half_y = 0.5 * pixels / width, 0.5 * pixels / height
    x = min(max(centre[0], half_x), 1.0 - half_x)
    y = min(max(centre[1], half_y), 1.0 - half_y)
    return (x - half_x, y - half_y, x + half_x, y + half_y)


def reference_crop(stage: str, size: tuple[int, int], window, spp: int, seed: int = 7) -> dict:
    """The path tracer's crop (radiance, transmittance, variance of the mean, seconds, ``bounds`` x0, y0, x1, y1 of
    the crop in image pixels), cached."""
    key = hashlib.sha256(json.dumps([Path(stage).read_bytes().hex()[:4096], size, window, spp, seed]).encode())
    path = cache_dir() / "reference" / f"frame_crop_{key.hexdigest()[:20]}.npz"
    if path.is_file():
        with np.load(path) as data:
            return dict(data)
    started = time.perf_counter()
    image = render_stage(stage, resolution=size, technique="path_tracer", data_window=window,
                         settings={"spp": str(spp), "seed": str(seed)})
    x0, y0, x1, y1 = image.window
    ox, oy = image.origin
    crop = (slice(y0 - oy, y1 - oy), slice(x0 - ox, x1 - ox))
    out = {"radiance": np.asarray(image.frame.rgba)[crop][..., :3],
           "transmittance": np.asarray(image.frame.transmittance)[crop],
           "variance": np.asarray(image.frame.aovs["variance"])[crop], "seconds": time.perf_counter() - started,
           "bounds": np.asarray(image.window)}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: np.savez(tmp, **out))
    return out


def hybrid_row(stage: str, size: tuple[int, int], reference: dict, covered: np.ndarray, budget: float | None) -> dict:
    """One whole hybrid frame, measured on the crop."""
    settings = {} if budget is None else {"time_budget": str(budget)}
    started = time.perf_counter()
    image = render_stage(stage, resolution=size, settings=settings)
    call = time.perf_counter() - started
    x0, y0, x1, y1 = (int(v) for v in reference["bounds"])
    radiance = np.asarray(image.frame.rgba)[y0:y1, x0:x1, :3]
    ref = reference["radiance"]
    if radiance.shape != ref.shape:
        raise RuntimeError(f"crop {radiance.shape} against reference {ref.shape}")
    metrics = error_metrics(radiance, ref, covered, reference["variance"])
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
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    centre = cloud_centre(args.stage)
    rows = []
    print(f"{'size':>10} {'budget':>7} {'render':>8} {'call':>8} {'march':>7} {'spp':>5} {'ms':>3} {'stopped by':>12} "
          f"{'estimate':>9} {'net':>7} {'bias':>7} {'est/net':>8}")
    for text in args.sizes.split(","):
        size = tuple(int(v) for v in text.lower().split("x"))
        window = crop_window(centre, *size, args.crop_pixels)
        reference = reference_crop(args.stage, size, window, args.reference_spp)
        x0, y0, x1, y1 = (int(v) for v in reference["bounds"])
        covered = media_covered(args.stage, size)[y0:y1, x0:x1]
        render_stage(args.stage, resolution=size, settings={"time_budget": "1"})  # warm: compiles, tables
        for budget in [float(b) for b in args.budgets.split(",") if b] + [None]:
            row = hybrid_row(args.stage, size, reference, covered, budget)
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
