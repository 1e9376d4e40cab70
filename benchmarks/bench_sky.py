"""Benchmark: the analytic sky pass — ns per pixel at 512² and 1920x1080 (cpu, and cuda when present) — and the
float32 kernel's error against float64 quadrature of Riley Eq. 8 over a grid of views, suns and altitudes.

Timings exclude the first (compiling) launch and say so. No pass/fail: goals are read by people.

Run:  python benchmarks/bench_sky.py [--json out/bench_sky.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_sky.json")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)

    import numpy as np
    import warp as wp

    from warpsky.device import init_warp
    from warpsky.media import air_analytic as sky
    from warpsky.passes.sky.sky import Sky
    from warpsky.scene.model import Atmosphere, Camera, Scene, Sun

    init_warp()
    devices = ["cpu"] + [f"cuda:{i}" for i in range(wp.get_cuda_device_count())]
    rotation = np.eye(3)
    camera = Camera("cam", np.array([0.0, 10.0, 0.0]), rotation, 20.0, 36.0, 24.0)
    scene = Scene(camera, Sun(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.ones(3)),
                  atmosphere=Atmosphere())
    rows = []
    for device in devices:
        sky_pass = Sky(device=device)
        sky_pass.render(scene, 8, 8)  # compile / load, not timed
        for width, height in ((512, 512), (1920, 1080)):
            times = []
            for _ in range(args.repeats):
                started = time.perf_counter()
                sky_pass.render(scene, width, height)
                times.append(time.perf_counter() - started)
            best = min(times)
            rows.append({"device": device, "width": width, "height": height, "ms": 1e3 * best,
                         "ns_per_pixel": 1e9 * best / (width * height)})
    # float32 kernel vs float64 quadrature
    from warpsky.evaluation.sky_quadrature import BETA, GAMMA, cases, quadrature

    table = cases(600, seed=5)
    want = np.array([quadrature(*c) for c in table])

    @wp.kernel
    def evaluate(rows_in: wp.array(dtype=wp.vec4), beta: wp.vec3, gamma: float, out: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        r = rows_in[i]
        out[i] = sky.air_inscatter(beta, gamma, r[0], r[1], r[2], r[3])

    packed = np.array([(h, v, s, 1e30 if np.isinf(d) else d) for h, v, s, d in table], dtype=np.float32)
    out = wp.zeros(len(table), dtype=wp.vec3, device="cpu")
    wp.launch(evaluate, dim=len(table), inputs=[wp.array(packed, dtype=wp.vec4), wp.vec3(*BETA.tolist()), GAMMA, out])
    got32 = out.numpy().astype(np.float64)
    got64 = np.array([sky.inscatter(BETA, GAMMA, *c) for c in table])
    scale = np.maximum(want.max(axis=1, keepdims=True), 1e-12)
    err32 = np.abs(got32 - want) / scale
    err64 = np.abs(got64 - want) / scale
    print("sky pass (timings exclude the first compile)")
    print(f"{'device':<8} {'size':>10} {'ms':>8} {'ns/pixel':>9}")
    for r in rows:
        print(f"{r['device']:<8} {r['width']}x{r['height']:<5} {r['ms']:>8.2f} {r['ns_per_pixel']:>9.1f}")
    print(f"\nerror vs float64 quadrature over {len(table)} (altitude, view, sun, distance) cases, "
          "relative to each case's largest channel")
    print(f"{'evaluation':<20} {'max':>10} {'mean':>10}")
    print(f"{'float64 (numpy)':<20} {err64.max():>10.2e} {err64.mean():>10.2e}")
    print(f"{'float32 (kernel)':<20} {err32.max():>10.2e} {err32.mean():>10.2e}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"machine": platform.platform(), "rows": rows,
                                     "error_float64": {"max": float(err64.max()), "mean": float(err64.mean())},
                                     "error_float32": {"max": float(err32.max()), "mean": float(err32.mean())}},
                                    indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
