"""Benchmark: the path tracer on the demo cumulus at optical scales 1x, 4x, 16x — paths/s, samples/s and the
tracking cost per path (tentative collisions), with local majorants (8-voxel cells) and one global majorant,
paths per pixel of one launch (0: one thread per pixel) and device arrays allocated by the frame
(:mod:`warpsky.core.device_buffers`: the sums and kept paths are reused; a majorant grid of another cell size is a new
upload).

Runs on the CPU and on every CUDA device present. Timings exclude the first (compiling) render of each device and
say so. No pass/fail: goals are read by people. With Mitsuba 3 installed (extra ``compare``), the same scene without
its ground plane is rendered by both at equal samples with box-filtered pixels, and the table adds each one's
efficiency = 1 / (relative variance of the image mean x seconds): the ratio says who reaches equal error sooner.

Run:  python evaluation/benchmarks/bench_path_tracer.py [--size 128] [--spp 16] [--json out/bench_path_tracer.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from evaluation.benchmarks.common import bench_devices, demo_scene  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", type=Path, default=ROOT / "usd_scenes" / "cumulus.usda")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_path_tracer.json")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--scales", default="1,4,16", help="optical-thickness multipliers, comma-separated")
    parser.add_argument("--devices", default=None, help="comma-separated Warp devices (default: cpu + all cuda)")
    args = parser.parse_args(argv)

    import warp as wp

    from warpsky.core import device_buffers
    from warpsky.core.device import cpu_thread_count, init_warp
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings, per_sample_launches

    init_warp()
    devices = bench_devices(args.devices)
    base = demo_scene(args.stage)
    if base is None:
        return 2
    size, spp = args.size, args.spp
    rows = []
    for device in devices:
        PathTracer(PathTracerSettings(spp=1), device=device).render(base, 8, 8)  # compile / load, not timed
        for scale in (float(s) for s in args.scales.split(",")):
            media = tuple(dataclasses.replace(m, extinction_scale=m.extinction_scale * scale) for m in base.media)
            scene = dataclasses.replace(base, media=media)
            for block in (8, 100000):
                settings = PathTracerSettings(spp=spp, majorant_block=block)
                allocated = device_buffers.allocation_count()
                started = time.perf_counter()
                tracer = PathTracer(settings, device=device)
                layer = tracer.render(scene, size, size)
                seconds = time.perf_counter() - started
                per_pass = int(tracer.resolved_settings(scene).samples_per_pass)
                paths = size * size * spp
                rows.append({
                    "device": device, "scale": scale, "majorant": "local 8" if block == 8 else "global",
                    "seconds": seconds, "paths_per_s": paths / seconds,
                    "steps_per_path": layer.stats["tracking_steps"] / paths,
                    "capped_paths": layer.stats["capped_paths"],
                    "mean_radiance": float(layer.radiance.mean()),
                    "samples_per_launch": per_sample_launches(device, size * size, per_pass),
                    "allocations": device_buffers.allocation_count() - allocated,
                })
    compare = []
    try:
        from evaluation import mitsuba as bridge

        bridge.import_mitsuba()
    except Exception as exc:  # noqa: BLE001 - optional: say why and go on
        print(f"(no Mitsuba comparison: {exc})", file=sys.stderr)
        bridge = None
    if bridge is not None:
        import numpy as np

        for scale in (float(s) for s in args.scales.split(",")):
            media = tuple(dataclasses.replace(m, extinction_scale=m.extinction_scale * scale) for m in base.media)
            scene = dataclasses.replace(base, media=media, ground=None)
            mean, variance, mi_seconds = bridge.render(scene, size, size, spp=spp * 16, runs=16)
            settings = PathTracerSettings(spp=spp * 16, pixel_jitter=1)
            started = time.perf_counter()
            layer = PathTracer(settings, device="cpu").render(scene, size, size)
            ws_seconds = time.perf_counter() - started

            def efficiency(image, var, seconds):
                relative = var.sum() / max(image.sum(), 1e-30) ** 2
                return 1.0 / (relative * seconds)

            ours = efficiency(layer.radiance.astype(np.float64), layer.aovs["variance"], ws_seconds)
            theirs = efficiency(mean, variance, mi_seconds)
            compare.append({"scale": scale, "warpsky_s": ws_seconds, "mitsuba_s": mi_seconds,
                            "warpsky_mean": float(layer.radiance.mean()), "mitsuba_mean": float(mean.mean()),
                            "efficiency_ratio": ours / theirs})
    print(f"path tracer, {args.stage.name}, {size}x{size}, {spp} spp; excludes the first compile")
    print(f"{'device':<8} {'scale':>5} {'majorant':>9} {'s':>7} {'k paths/s':>10} {'steps/path':>11} {'capped':>7} "
          f"{'spp/launch':>10} {'allocs':>6}")
    for r in rows:
        print(f"{r['device']:<8} {r['scale']:>5g} {r['majorant']:>9} {r['seconds']:>7.2f} "
              f"{r['paths_per_s'] / 1e3:>10.1f} {r['steps_per_path']:>11.1f} {r['capped_paths']:>7} "
              f"{r['samples_per_launch']:>10} {r['allocations']:>6}")
    if compare:
        print(f"\nvs Mitsuba 3 volpath llvm_ad_rgb (cpu, no ground, {spp * 16} spp, box-filtered pixels)")
        print(f"{'scale':>5} {'warpsky s':>10} {'mitsuba s':>10} {'mean ws':>9} {'mean mi':>9} "
              f"{'efficiency ws/mi':>17}")
        for r in compare:
            print(f"{r['scale']:>5g} {r['warpsky_s']:>10.2f} {r['mitsuba_s']:>10.2f} {r['warpsky_mean']:>9.5f} "
                  f"{r['mitsuba_mean']:>9.5f} {r['efficiency_ratio']:>17.2f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({
        "machine": platform.platform(), "cpu_threads": cpu_thread_count(), "warp": wp.config.version, "rows": rows,
        "mitsuba": compare,
    }, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
