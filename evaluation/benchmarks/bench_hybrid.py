"""Benchmark: the hybrid technique (exact single scattering + denoised path-traced multiple scattering) on the demo
cumulus, rendered to a target error: frames per second, paths per pixel reached, the error estimate, and how the
time splits between the single-scattering march, the paths and the denoiser.

Runs on the CPU and on every CUDA device present (at ``--size`` on the CPU, ``--gpu-size`` on GPUs). Timings are
warm: each device renders once, untimed, before its rows (first compiles excluded, and the JSON says so). No
pass/fail: the goals are read by people (on one GPU, 512 x 512 at a 5% target in under 0.1 s).

Run:  python evaluation/benchmarks/bench_hybrid.py [--size 128] [--gpu-size 512] [--targets 0.1,0.05] [--frames 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from evaluation.benchmarks.common import bench_devices, demo_scene  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", type=Path, default=ROOT / "usd_scenes" / "cumulus.usda")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_hybrid.json")
    parser.add_argument("--size", type=int, default=128, help="image width on the CPU [px]")
    parser.add_argument("--gpu-size", type=int, default=512, help="image width on GPUs [px]")
    parser.add_argument("--targets", default="0.1,0.05", help="target relative errors, comma-separated")
    parser.add_argument("--frames", type=int, default=3, help="timed frames per row (the median is reported)")
    parser.add_argument("--devices", default=None, help="comma-separated Warp devices (default: cpu + all cuda)")
    args = parser.parse_args(argv)

    import warp as wp

    from warpsky.core.device import cpu_thread_count, init_warp
    from warpsky.passes.frame import render_layers
    from warpsky.render.plan import make_plan

    init_warp()
    devices = bench_devices(args.devices)
    scene = demo_scene(args.stage)
    if scene is None:
        return 2
    rows = []
    for device in devices:
        width = args.size if device.startswith("cpu") else args.gpu_size
        warm = make_plan(scene, technique="hybrid", settings={"spp": "2", "target_error": "0"},
                         resolution=(width, None), device=device)
        render_layers(warm, scene)  # compile / load and the denoiser's first call: not timed
        for target in (float(t) for t in args.targets.split(",")):
            plan = make_plan(scene, technique="hybrid", settings={"target_error": repr(target), "spp": "4096"},
                             resolution=(width, None), device=device)
            times, layers = [], []
            for frame in range(args.frames):
                plan.renderer.settings = dataclasses.replace(plan.settings, seed=frame)
                started = time.perf_counter()
                layer, _ = render_layers(plan, scene)
                times.append(time.perf_counter() - started)
                layers.append(layer)
            seconds = statistics.median(times)
            stats = layers[times.index(min(times, key=lambda t: abs(t - seconds)))].stats
            rows.append({
                "device": device, "width": plan.width, "height": plan.height, "target_error": target,
                "seconds": seconds, "fps": 1.0 / seconds, "spp": stats.get("spp"),
                "error_estimate": stats.get("error_estimate"), "stopped_by": stats.get("stopped_by"),
                "single_scatter_seconds": stats.get("single_scatter_seconds"),
                "denoise_seconds": stats.get("denoise_seconds"), "capped_paths": stats.get("capped_paths"),
            })
    print(f"{'device':<8} {'size':>9} {'target':>7} {'seconds':>8} {'fps':>7} {'spp':>5} {'estimate':>9} "
          f"{'stopped by':>11} {'SS s':>6} {'denoise s':>9}")
    for r in rows:
        print(f"{r['device']:<8} {r['width']:>4}x{r['height']:<4} {r['target_error']:>7.3f} {r['seconds']:>8.3f} "
              f"{r['fps']:>7.2f} {r['spp']:>5} {r['error_estimate']:>9.4f} {r['stopped_by']:>11} "
              f"{r['single_scatter_seconds']:>6.3f} {r['denoise_seconds']:>9.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({
        "machine": platform.platform(), "cpu_threads": cpu_thread_count(), "warp": wp.config.version,
        "note": "warm frames: first compiles excluded; seconds are the median of the frames", "rows": rows,
    }, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
