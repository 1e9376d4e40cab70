"""Benchmark: the path tracer on the demo cumulus at optical scales 1x, 4x, 16x — paths/s, samples/s and the
tracking cost per path (tentative collisions), with local majorants (8-voxel cells) and one global majorant.

Runs on the CPU and on every CUDA device present. Timings exclude the first (compiling) render of each device and
say so. No pass/fail: goals are read by people. (The Mitsuba 3 comparison of issue 4 is not part of this run yet.)

Run:  python benchmarks/bench_path_tracer.py [--size 128] [--spp 16] [--json out/bench_path_tracer.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


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

    from warpsky.device import cpu_thread_count, init_warp
    from warpsky.scene.usd import StageReader
    from warpsky.techniques.path_tracer.technique import PathTracer, PathTracerSettings

    init_warp()
    devices = args.devices.split(",") if args.devices else ["cpu"] + [
        f"cuda:{i}" for i in range(wp.get_cuda_device_count())
    ]
    if not (ROOT / "data" / "cumulus.nvdb").exists() and args.stage.name == "cumulus.usda":
        print("data/cumulus.nvdb is missing: run `python tools/make_cumulus.py` (or `make data`)", file=sys.stderr)
        return 2
    base = StageReader(args.stage).scene_at(None)
    size, spp = args.size, args.spp
    rows = []
    for device in devices:
        PathTracer(PathTracerSettings(spp=1), device=device).render(base, 8, 8)  # compile / load, not timed
        for scale in (float(s) for s in args.scales.split(",")):
            media = tuple(dataclasses.replace(m, extinction_scale=m.extinction_scale * scale) for m in base.media)
            scene = dataclasses.replace(base, media=media)
            for block in (8, 100000):
                settings = PathTracerSettings(spp=spp, majorant_block=block)
                started = time.perf_counter()
                layer = PathTracer(settings, device=device).render(scene, size, size)
                seconds = time.perf_counter() - started
                paths = size * size * spp
                rows.append({
                    "device": device, "scale": scale, "majorant": "local 8" if block == 8 else "global",
                    "seconds": seconds, "paths_per_s": paths / seconds,
                    "steps_per_path": layer.stats["tracking_steps"] / paths,
                    "capped_paths": layer.stats["capped_paths"],
                    "mean_radiance": float(layer.radiance.mean()),
                })
    print(f"path tracer, {args.stage.name}, {size}x{size}, {spp} spp; excludes the first compile")
    print(f"{'device':<8} {'scale':>5} {'majorant':>9} {'s':>7} {'k paths/s':>10} {'steps/path':>11} {'capped':>7}")
    for r in rows:
        print(f"{r['device']:<8} {r['scale']:>5g} {r['majorant']:>9} {r['seconds']:>7.2f} "
              f"{r['paths_per_s'] / 1e3:>10.1f} {r['steps_per_path']:>11.1f} {r['capped_paths']:>7}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({
        "machine": platform.platform(), "cpu_threads": cpu_thread_count(), "warp": wp.config.version, "rows": rows,
    }, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
