"""Benchmark: what a path costs in the storm, and the default technique on it against a path-traced reference.

Part 1, the exact path tracer on ``usd_scenes/storm.usda`` at one frame, as shipped and with parts of the scene
removed (the advected detail, the species other than cloud, the air) and with the diffraction peaks cut after
the first event (``forward_cut``): paths per second and, per path, tentative
collisions and majorant crossings (``steps``), those of shadow rays towards the sun and scattering events. Part 2
(with ``--reference EXR``, a path-traced frame with a variance AOV at the same size, e.g. ``warpsky render
usd_scenes/storm.usda ref.exr --frames 40 --res 96 --technique path_tracer --spp 2048 --seed 99 --float``):
hybrid at each ``--budgets`` time budget, its error estimate against its measured error over the pixels the media
cover (net: the reference's own noise taken out). Warm timings (one untimed render first). No pass/fail.

Run:  python evaluation/benchmarks/bench_storm.py [--frame 40] [--size 48] [--spp 16] [--reference ref.exr --ref-size
96]
      [--budgets 10,40]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def variants(scene) -> list[tuple[str, object, dict]]:
    """(label, scene, extra settings) of the storm as shipped, without detail, other species or air, and with the
    diffraction peaks cut after the first event (``forward_cut``, hybrid's default)."""
    from warpsky.techniques.hybrid.hybrid import HybridSettings

    without_detail = tuple(dataclasses.replace(m, detail=None) for m in scene.media)
    cloud = tuple(m for m in scene.media if m.species == "cloud")
    cut = HybridSettings().forward_cut or 3.0
    return [("as shipped", scene, {}), ("no detail", dataclasses.replace(scene, media=without_detail), {}),
            ("cloud only", dataclasses.replace(scene, media=cloud), {}),
            ("no air", dataclasses.replace(scene, atmosphere=None), {}),
            (f"cut {cut:g} deg", scene, {"forward_cut": cut})]


def path_rows(scene, size: int, spp: int) -> list[dict]:
    from evaluation.speed import path_breakdown
    from warpsky.passes.frame import render_layers
    from warpsky.render.plan import make_plan

    rows = []
    for label, variant, extra in variants(scene):
        plan = make_plan(variant, technique="path_tracer", settings={"spp": spp, "seed": 1, **extra},
                         resolution=(size, None))
        render_layers(plan, variant)
        started = time.perf_counter()
        main, _ = render_layers(plan, variant)
        seconds = time.perf_counter() - started
        rows.append({"variant": label, "seconds": seconds, "paths_per_s": float(main.stats["paths"]) / seconds,
                     **path_breakdown(main), "capped": main.stats["capped_paths"]})
    return rows


def hybrid_rows(stage: Path, frame: float, reference: Path, size: int, budgets: list[float]) -> list[dict]:
    import warpsky
    from evaluation.error_vs_time import error_metrics
    from warpsky.core.numerics import LUMINANCE_WEIGHTS
    from warpsky.output.exr import read_exr

    ref = read_exr(reference)
    truth = ref.rgba()[..., :3]
    variance = np.stack([ref.channels[f"variance.{c}"] for c in "RGB"], -1)
    warpsky.render_stage(stage, frame, resolution=(size, None), device="cpu", settings={"spp": 2})
    rows = []
    for budget in budgets:
        started = time.perf_counter()
        image = warpsky.render_stage(stage, frame, resolution=(size, None), device="cpu",
                                     settings={"time_budget": budget})
        seconds = time.perf_counter() - started
        covered = (image.layer.transmittance @ LUMINANCE_WEIGHTS) < 0.99
        measured = error_metrics(image.frame.rgba[..., :3], truth, covered, variance)
        estimate = image.metadata.get("errorEstimate")
        rows.append({"budget": budget, "seconds": seconds, "spp": image.metadata.get("spp"), "estimate": estimate,
                     "net_rmse": measured["net_rmse"], "rel_rmse": measured["rel_rmse"], "bias": measured["bias"],
                     "reference_noise": float(np.sqrt(variance[covered].mean()) / truth[covered].mean())})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", type=Path, default=ROOT / "usd_scenes" / "storm.usda")
    parser.add_argument("--frame", type=float, default=40.0)
    parser.add_argument("--size", type=int, default=48, help="image width of part 1 [px]")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--reference", type=Path, default=None)
    parser.add_argument("--ref-size", type=int, default=96, help="image width of the reference [px]")
    parser.add_argument("--budgets", default="10,40")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_storm.json")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from warpsky.core.device import init_warp
    from warpsky.usd.stage import StageReader

    init_warp()
    scene = StageReader(args.stage).scene_at(args.frame)
    rows = path_rows(scene, args.size, args.spp)
    print(f"path tracer, {args.size} px wide, {args.spp} spp, frame {args.frame:g}")
    print(f"{'variant':<12} {'s':>6} {'k paths/s':>10} {'steps/path':>11} {'shadow':>8} {'events':>7} {'capped':>7}")
    for r in rows:
        print(f"{r['variant']:<12} {r['seconds']:6.2f} {r['paths_per_s'] / 1e3:10.1f} {r['steps']:11.1f} "
              f"{r['shadow_steps']:8.1f} {r['events']:7.1f} {r['capped']:7d}")
    out = {"frame": args.frame, "size": args.size, "spp": args.spp, "path_tracer": rows}
    if args.reference is not None:
        budgets = [float(b) for b in args.budgets.split(",")]
        out["hybrid"] = hybrid_rows(args.stage, args.frame, args.reference, args.ref_size, budgets)
        print(f"hybrid against {args.reference} ({args.ref_size} px wide)")
        print(f"{'budget s':>8} {'s':>6} {'spp':>5} {'estimate':>9} {'net':>7} {'bias':>7} {'ref noise':>9}")
        for r in out["hybrid"]:
            print(f"{r['budget']:8g} {r['seconds']:6.2f} {r['spp']:5d} {r['estimate']:9.3f} {r['net_rmse']:7.3f} "
                  f"{r['bias']:+7.3f} {r['reference_noise']:9.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=1))
    print(args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
