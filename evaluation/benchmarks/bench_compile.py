"""Benchmark: how long Warp takes to compile warpsky's CPU kernel modules, against the size of their generated C++.

For one variant (the first) of every kernel factory of every technique, and the last variant of each (the most
features), the module is compiled into an empty kernel cache (a temporary ``WARP_CACHE_PATH``) and timed; its
generated C++ is measured by Warp's code generator (:func:`warpsky.render.kernel_cache.module_source_bytes`). A line
seconds = intercept + slope * MB is fitted by least squares and compared with the constants the first-compile
notice uses (:data:`~warpsky.render.kernel_cache.COMPILE_INTERCEPT_S`,
:data:`~warpsky.render.kernel_cache.COMPILE_SECONDS_PER_MB`).

Measured on this project's 2-core CPU (Warp 1.19, 9 modules): 0.017-0.548 MB of C++ compile in 0.2-4.0 s; the
fit is -0.23 s + 7.9 s/MB, and the notice's 0 s + 7.9 s/MB predicts the 13.6 s total as 16.0 s (the largest
module, the path tracer with every feature, 4.0 s against 4.3 s). A cold first demo frame compiles six modules
(the two of hybrid's factories, which the notice counts as about 4 s, and the sky pass, the air tables and the
field sampler): 61 s for the whole command, of which the render's own 54 s.

Run:  python evaluation/benchmarks/bench_compile.py [--json out/bench_compile.json]   (under a minute on 2 CPU cores)
No pass/fail: goals are read by people.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def modules_to_time() -> list[tuple[str, object]]:
    """(label, Warp module): first and last variant of every technique's kernel factories, each module once."""
    from warpsky.core.kernel_variants import variants
    from warpsky.render.kernel_cache import built_kernels, technique_factories
    from warpsky.render.registry import technique_names

    factories = {id(f): (f, d) for name in technique_names() for f, d in technique_factories(name)}
    out, seen = [], set()
    for factory, domains in factories.values():
        options = variants(domains)
        for flags in {id(o): o for o in (options[0], options[-1])}.values():
            for kernel in built_kernels(factory, flags):
                if kernel.module.name not in seen:
                    seen.add(kernel.module.name)
                    label = f"{factory.__name__}({', '.join(f'{k}={v}' for k, v in flags.items())})"
                    out.append((label, kernel.module))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="warpsky-compile-") as cache:
        os.environ["WARP_CACHE_PATH"] = cache
        import numpy as np
        import warp as wp

        from warpsky.core.device import init_warp
        from warpsky.render.kernel_cache import COMPILE_INTERCEPT_S, COMPILE_SECONDS_PER_MB, module_source_bytes

        init_warp()
        device = wp.get_device("cpu")
        rows = []
        print(f"{'module':<72} {'C++ MB':>7} {'compile s':>10}")
        for label, module in modules_to_time():
            size = module_source_bytes(module)
            start = time.perf_counter()
            module.load(device)
            seconds = time.perf_counter() - start
            rows.append({"module": label, "bytes": size, "seconds": seconds})
            print(f"{label[:72]:<72} {size / 1e6:>7.3f} {seconds:>10.1f}", flush=True)
    megabytes = np.array([r["bytes"] / 1e6 for r in rows])
    seconds = np.array([r["seconds"] for r in rows])
    slope, intercept = np.polyfit(megabytes, seconds, 1)
    predicted = COMPILE_INTERCEPT_S + COMPILE_SECONDS_PER_MB * megabytes
    worst = float(np.max(np.abs(predicted - seconds) / seconds))
    print(f"fit: {intercept:.2f} s + {slope:.1f} s/MB; the notice's constants {COMPILE_INTERCEPT_S:g} s + "
          f"{COMPILE_SECONDS_PER_MB:g} s/MB: worst relative error {worst:.0%} over {len(rows)} modules, "
          f"total {seconds.sum():.0f} s measured, {predicted.sum():.0f} s predicted")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "intercept_s": intercept, "seconds_per_mb": slope,
                                         "worst_relative_error": worst}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
