"""Benchmark: what deep output with several samples per volume adds to a frame.

For each stage, the frame's passes are run (warm: once before timing) without a deep image and with K volume samples
per volume layer (the depth profiles of the voxel media and the fog), then the deep image is built from the layers.
Printed per K: seconds of the passes, seconds added by the profiles, seconds of the deep image, its samples and the
relative error of its flattening against the composited frame (float32 samples).

Run:  python evaluation/benchmarks/bench_deep.py [--stages usd_scenes/cumulus.usda,usd_scenes/valley_fog.usda]
      [--technique single_scatter] [--res 128x128] [--samples 8,16] [--device cpu] [--json out/bench_deep.json]
No pass/fail: timings are read by people.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def timed(plan, scene, samples: int) -> tuple[float, list]:
    from warpsky.passes.frame import render_layers

    started = time.perf_counter()
    layers = render_layers(plan, scene, deep_samples=samples)[1]
    return time.perf_counter() - started, layers


def measure(stage: str, technique: str, resolution, samples: list[int], device: str) -> list[dict]:
    """One row per K of ``samples`` for ``stage`` (see the module docstring)."""
    from warpsky.output.deep import deep_from_layers, flatten
    from warpsky.passes.composite import composite
    from warpsky.render.plan import make_plan
    from warpsky.usd.stage import StageReader

    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique=technique, settings={}, resolution=resolution, device=device)
    for k in (0, *samples):  # compiles and first uploads
        timed(plan, scene, k)
    bare = timed(plan, scene, 0)[0]
    rows = []
    for k in samples:
        seconds, layers = timed(plan, scene, k)
        started = time.perf_counter()
        deep = deep_from_layers(layers, scene.camera.far)
        built = time.perf_counter() - started
        flat = composite(layers, scene.camera.far).rgba
        error = float(np.abs(flatten(deep) - flat).max() / max(float(flat[..., :3].max()), 1e-30))
        rows.append({"stage": Path(stage).name, "technique": technique, "size": f"{plan.width}x{plan.height}",
                     "samples": k, "passes_s": bare, "profiles_s": seconds - bare, "deep_image_s": built,
                     "deep_samples": int(deep.counts.sum()), "flatten_error": error})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stages", default="usd_scenes/cumulus.usda,usd_scenes/valley_fog.usda")
    parser.add_argument("--technique", default="single_scatter")
    parser.add_argument("--res", default="128x128")
    parser.add_argument("--samples", default="8,16")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    import warp as wp

    from warpsky.core.device import init_warp

    init_warp()
    width, height = (int(v) for v in args.res.split("x"))
    samples = [int(k) for k in args.samples.split(",")]
    rows = []
    with wp.ScopedDevice(args.device):
        for stage in args.stages.split(","):
            rows += measure(stage, args.technique, (width, height), samples, args.device)
    print(f"{'stage':<20} {'size':>9} {'K':>3} {'passes s':>9} {'profiles s':>10} {'deep s':>7} {'samples':>8} "
          f"{'flatten err':>11}")
    for r in rows:
        print(f"{r['stage']:<20} {r['size']:>9} {r['samples']:>3} {r['passes_s']:>9.3f} {r['profiles_s']:>10.3f} "
              f"{r['deep_image_s']:>7.3f} {r['deep_samples']:>8} {r['flatten_error']:>11.1e}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
