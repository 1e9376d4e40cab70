"""Benchmark: single-scattering ray march on the demo cumulus, ms/frame and density lookups/s.

Prints a table and writes JSON. Runs on the CPU and on every CUDA device present. Timings exclude the first
(compiling) render of each configuration, and say so. No pass/fail: goals are read by people.

Run:  python evaluation/benchmarks/bench_single_scatter.py [--stage usd_scenes/cumulus.usda] [--json
out/bench_single_scatter.json]
"""

from __future__ import annotations

import argparse
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
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_single_scatter.json")
    parser.add_argument("--sizes", default="256,512", help="square image sizes, comma-separated")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--devices", default=None, help="comma-separated Warp devices (default: cpu + all cuda)")
    args = parser.parse_args(argv)

    import warp as wp

    from warpsky.core.device import cpu_thread_count, init_warp
    from warpsky.render.plan import make_plan

    init_warp()
    devices = bench_devices(args.devices)
    scene = demo_scene(args.stage)
    if scene is None:
        return 2
    rows = []
    for device in devices:
        for size in (int(s) for s in args.sizes.split(",")):
            plan = make_plan(scene, technique="single_scatter", resolution=(size, size), device=device)
            technique = plan.renderer
            technique.render(scene, size, size)  # compile / load, not timed
            times, lookups = [], 0
            for _ in range(args.repeats):
                started = time.perf_counter()
                layer = technique.render(scene, size, size)
                times.append(time.perf_counter() - started)
                lookups = layer.stats["lookups"]
            best = min(times)
            rows.append({
                "device": device, "width": size, "height": size, "ms_per_frame": 1e3 * best,
                "ms_median": 1e3 * sorted(times)[len(times) // 2], "lookups": lookups,
                "lookups_per_s": lookups / best, "pixels_per_s": size * size / best,
                "settings": plan.settings_dict(),
            })
    header = (f"{'device':<8} {'size':>9} {'ms/frame':>10} {'median ms':>10} {'Mlookups':>9} {'Mlookups/s':>11} "
              f"{'Mpix/s':>8}")
    print(f"single_scatter on {args.stage.name}; best of {args.repeats} after one untimed compile/warm-up render;"
          f" CPU threads {cpu_thread_count()}")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['device']:<8} {r['width']:>4}x{r['height']:<4} {r['ms_per_frame']:>10.1f} {r['ms_median']:>10.1f} "
              f"{r['lookups'] / 1e6:>9.1f} {r['lookups_per_s'] / 1e6:>11.1f} {r['pixels_per_s'] / 1e6:>8.3f}")
    report = {"benchmark": "single_scatter", "stage": str(args.stage), "machine": platform.platform(),
              "processor": platform.processor(), "cpu_threads": cpu_thread_count(),
              "warp": wp.__version__, "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
