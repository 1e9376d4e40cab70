"""The hybrid's error estimate against its measured error from a few to thousands of paths per pixel.

A stage's cloud and sun alone (no air, no ground; :func:`evaluation.benchmarks.bench_cycles.sun_only_stage`, the
scene the Cycles comparison uses) at ``--size`` square, against the exact path tracer at ``--reference-spp``
(cached, :class:`evaluation.benchmarks.bench_cycles.Judge`). For each ``--spp`` and seed, one hybrid frame with every
path kept (a target of 1e-4, so the estimate is taken at exactly that count): its *net* error (the reference's
noise taken out), its estimate, their ratio and its time; with ``--halves-only`` also the estimate from the two
denoised halves alone (the denoiser's bias bound of :mod:`warpsky.techniques.hybrid.estimate` set to zero, the
estimate before that bound existed) for the same paths.

Run:  python evaluation/scripts/estimate_at_spp.py --spp 64,256,1024,4096 --seeds 7,8 --halves-only
No pass/fail.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def frame(scene, size: int, spp: int, seed: int, halves_only: bool = False):
    """(layer, seconds) of one hybrid frame at exactly ``spp`` paths per pixel."""
    from warpsky.render.plan import make_plan
    from warpsky.techniques.hybrid import estimate

    bound = estimate.with_denoiser_bias
    if halves_only:
        estimate.with_denoiser_bias = lambda *args: 0.0
    try:
        plan = make_plan(scene, technique="hybrid", settings={"spp": str(spp), "target_error": "1e-4",
                                                              "seed": str(seed)},
                         resolution=(size, size), device="cpu")
        started = time.perf_counter()
        layer = plan.renderer.render(scene, size, size)
        return layer, time.perf_counter() - started
    finally:
        estimate.with_denoiser_bias = bound


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stage", type=Path, default=ROOT / "usd_scenes" / "cumulus.usda")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", default="64,256,1024,4096", help="paths per pixel, comma-separated")
    parser.add_argument("--seeds", default="7,8", help="seeds, comma-separated")
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--halves-only", action="store_true", help="also the estimate without the bias bound")
    parser.add_argument("--work", type=Path, default=ROOT / "data" / "estimate_at_spp")
    args = parser.parse_args(argv)

    from evaluation.benchmarks.bench_cycles import Judge, sun_only_stage
    from warpsky.core.device import init_warp
    from warpsky.usd.stage import StageReader

    init_warp()
    derived = sun_only_stage(args.stage, args.work / f"{args.stage.stem}_sun_only.usda", args.size)
    scene = StageReader(derived).scene_at(None)
    judge = Judge(scene, args.size, args.reference_spp, 1, print)
    print("| paths per pixel | seed | net | estimate | estimate / net | halves only | halves / net | s |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for spp in (int(x) for x in args.spp.split(",")):
        for seed in (int(x) for x in args.seeds.split(",")):
            layer, seconds = frame(scene, args.size, spp, seed)
            net = judge.metrics(layer.radiance)["net_rmse"]
            estimate = layer.stats["error_estimate"]
            halves = " | "
            if args.halves_only:
                old, _ = frame(scene, args.size, spp, seed, halves_only=True)
                value = old.stats["error_estimate"]
                halves = f"{value:.4f} | {value / net:.2f}"
            print(f"| {spp} | {seed} | {net:.4f} | {estimate:.4f} | {estimate / net:.2f} | {halves} | "
                  f"{seconds:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
