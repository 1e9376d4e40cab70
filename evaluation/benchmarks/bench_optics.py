"""Benchmark: optics tables — first build and cached load for {cloud} and {cloud, rain, ice, snow}, and phase
lookup / sampling throughput in a Warp kernel (cpu, and cuda when present).

Goals: all four species' first build <= 120 s on the 2-core CPU machine; cached load <= 0.5 s.
The first build runs in an empty temporary cache, so it is a real first build; timings include Mie's numba JIT
and Warp's first kernel compile, and say so.

Run:  python evaluation/benchmarks/bench_optics.py [--json out/bench_optics.json] [--keep-cache DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from evaluation.benchmarks.common import bench_devices  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_optics.json")
    parser.add_argument("--keep-cache", type=Path, default=None, help="build into this cache instead of a temp dir")
    parser.add_argument("--count", type=int, default=4_000_000, help="lookups / samples per throughput run")
    args = parser.parse_args(argv)

    cache = args.keep_cache or Path(tempfile.mkdtemp(prefix="warpsky-bench-optics-"))
    os.environ["WARPSKY_CACHE"] = str(cache)

    import numpy as np
    import warp as wp

    from warpsky.core.device import init_warp
    from warpsky.optics import kernels as K
    from warpsky.optics.tables import DEFAULT_ORDERS, build_tables

    init_warp()
    rows = []
    for label, species in (("cloud", ["cloud"]), ("all four", ["cloud", "rain", "ice", "snow"])):
        started = time.perf_counter()
        tables = build_tables(species)
        first = time.perf_counter() - started
        started = time.perf_counter()
        build_tables(species)
        cached = time.perf_counter() - started
        rows.append({"species": label, "first_build_s": first, "cached_load_s": cached,
                     "built": [[n, k, round(s, 2)] for n, k, s in tables.built]})
        # the multiple-scattering tables slicing needs on top: Ams_0..N and F_n
        started = time.perf_counter()
        tables = build_tables(species, orders=DEFAULT_ORDERS)
        first = time.perf_counter() - started
        started = time.perf_counter()
        build_tables(species, orders=DEFAULT_ORDERS)
        cached = time.perf_counter() - started
        rows.append({"species": f"+Ams_{DEFAULT_ORDERS}", "first_build_s": first, "cached_load_s": cached,
                     "built": [[n, k, round(s, 2)] for n, k, s in tables.built]})
    print(f"optics tables (cache {cache}); first build includes numba JIT and Warp compiles")
    print(f"{'species':<10} {'first build s':>14} {'cached load s':>14}  built")
    for r in rows:
        built = ", ".join(f"{n} {k} {s:.1f}s" for n, k, s in r["built"]) or "-"
        print(f"{r['species']:<10} {r['first_build_s']:>14.2f} {r['cached_load_s']:>14.3f}  {built}")

    tables = build_tables(["cloud", "rain", "ice", "snow"])
    devices = bench_devices()
    throughput = []
    rng = np.random.default_rng(0)
    angles = rng.uniform(0, np.pi, args.count).astype(np.float32)
    for device in devices:
        dev_tables = K.DevicePhaseTables.upload(tables.phase, device)
        K.lookup(dev_tables, 1, angles[:1000], device)
        K.sample(dev_tables, 4, 1000, 0, device)
        wp.synchronize_device(device)
        started = time.perf_counter()
        K.lookup(dev_tables, 1, angles, device)
        wp.synchronize_device(device)
        lookup_s = time.perf_counter() - started
        started = time.perf_counter()
        K.sample(dev_tables, 4, args.count, 1, device)
        wp.synchronize_device(device)
        sample_s = time.perf_counter() - started
        throughput.append({"device": device, "lookups_per_s": args.count / lookup_s,
                           "samples_per_s": args.count / sample_s})
    print(f"\n{'device':<8} {'M RGB lookups/s':>16} {'M samples/s':>12}   (one launch, {args.count:,} threads,"
          " includes host<->device copies)")
    for t in throughput:
        print(f"{t['device']:<8} {t['lookups_per_s'] / 1e6:>16.1f} {t['samples_per_s'] / 1e6:>12.1f}")
    report = {"benchmark": "optics", "machine": platform.platform(), "tables": rows, "throughput": throughput}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
