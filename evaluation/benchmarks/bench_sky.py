"""Benchmark: the analytic sky pass — ns per pixel at 512² and 1920x1080 (cpu, and cuda when present) — the
float32 kernel's error against float64 quadrature of Riley Eq. 8 over a grid of views, suns and altitudes, and the
sky's error against the path tracer's air (every order of scattering) over sun elevations 90..0 deg, views >= 2 deg
above the horizon and ground albedos 0, 0.3, 0.9 (evaluation.sky_error), with and without the multiple-
scattering table, and the ground's sky irradiance.

Timings exclude the first (compiling) launch and say so. No pass/fail: goals are read by people.

Run:  python evaluation/benchmarks/bench_sky.py [--json out/bench_sky.json] [--spp 2048] [--no-error]
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
from evaluation.benchmarks.common import bench_devices  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_sky.json")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--spp", type=int, default=2048, help="paths per pixel of each path-traced case")
    parser.add_argument("--no-error", action="store_true", help="skip the comparison with the path tracer")
    parser.add_argument("--air", default="rayleigh",
                        help="comma-separated airs of the comparison: rayleigh (Riley's gas), aerosols (with "
                             "Bruneton's and Hillaire's Earth aerosols), earth (aerosols and ozone)")
    parser.add_argument("--earth", default="flat",
                        help="comma-separated earths of the comparison: flat (Riley's), round (the Earth's radius; "
                             "adds suns in twilight, down to -6 deg)")
    args = parser.parse_args(argv)

    import numpy as np
    import warp as wp

    from warpsky.core.device import init_warp
    from warpsky.media.air import analytic as sky
    from warpsky.model.scene import Atmosphere, Camera, Scene, Sun
    from warpsky.passes.sky.sky import Sky

    init_warp()
    devices = bench_devices()
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
    from evaluation.sky_quadrature import BETA, GAMMA, cases, quadrature

    table = cases(600, seed=5)
    want = np.array([quadrature(*c) for c in table])

    @wp.kernel
    def evaluate(rows_in: wp.array(dtype=wp.vec4), beta: wp.vec3, gamma: float, out: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        r = rows_in[i]
        out[i] = sky.air_inscatter(beta, gamma, r[0], r[1], r[2], r[3])

    packed = np.array([(h, v, s, 1e30 if np.isinf(d) else d) for h, v, s, d in table], dtype=np.float32)
    out = wp.zeros(len(table), dtype=wp.vec3, device="cpu")
    wp.launch(evaluate, dim=len(table), inputs=[wp.array(packed, dtype=wp.vec4, device="cpu"),
                                                wp.vec3(*BETA.tolist()), GAMMA, out], device="cpu")
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
    cases = [] if args.no_error else [c for earth in args.earth.split(",") for air in args.air.split(",")
                                      for c in error_table(args.spp, air, earth)]
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"machine": platform.platform(), "rows": rows,
                                     "error_float64": {"max": float(err64.max()), "mean": float(err64.mean())},
                                     "error_float32": {"max": float(err32.max()), "mean": float(err32.mean())},
                                     "path_tracer_cases": cases}, indent=2))
    print(f"wrote {args.json}")
    return 0


def error_table(spp: int, air: str = "rayleigh", earth: str = "flat") -> list[dict]:
    """Every sky and ground case of :mod:`evaluation.sky_error` for the air ``air``, printed per (sun,
    albedo)."""
    import numpy as np

    from evaluation import sky_error as se

    started = time.perf_counter()
    cases = []
    print(f"\nsky against the path tracer ({earth} earth, air '{air}', {spp} paths per pixel, 8x8 pixels 1 deg "
          "across)")
    print("per (sun, albedo): the worst view's |error| per channel net of 2 sigma of the tracer's noise; "
          "'ground': the ground's radiance (sun + sky irradiance)")
    print(f"{'sun':>5} {'albedo':>6}  {'table sky':>10} {'single sky':>10} {'table ground':>12} "
          f"{'single ground':>13} {'noise':>6}")
    for sun in se.sun_elevations(earth):
        # few paths reach the sunlit air of a low sun: more paths keep the tracer's noise near the others'
        paths = spp * (se.LOW_SUN_PATHS if sun <= 0.0 else 1)
        for albedo in se.ALBEDOS:
            group = [se.sky_case(sun, view, albedo, spp=paths, air=air, earth=earth) for view in se.VIEWS
                     if se.clear_of_the_sun(sun, view)]
            ground = se.ground_case(sun, albedo, spp=paths, air=air, earth=earth) if albedo > 0.0 else None
            cases.extend(group + ([ground] if ground else []))
            noise = max(float(np.max(se.relative_errors(c)[1])) for c in group)
            g = (f"{se.net(ground):>12.1%} {se.net(ground, 'single'):>13.1%}" if ground
                 else f"{'-':>12} {'-':>13}")
            print(f"{sun:>5.0f} {albedo:>6.1f}  {max(se.net(c) for c in group):>10.1%} "
                  f"{max(se.net(c, 'single') for c in group):>10.1%} {g} {noise:>6.1%}", flush=True)
    for key in ("table", "single"):
        for kind in ("sky", "ground"):
            errs = np.array([float(np.max(np.abs(se.relative_errors(c, key)[0]))) for c in cases
                             if c["kind"] == kind])
            bias = np.mean([se.relative_errors(c, key)[0] for c in cases if c["kind"] == kind], axis=0)
            print(f"{key:>6} {kind:<6} |error| median {np.median(errs):.1%}  p90 {np.percentile(errs, 90):.1%}  "
                  f"worst {errs.max():.1%}  bias R/G/B {' / '.join(f'{b:+.1%}' for b in bias)}")
    print(f"({len(cases)} cases in {time.perf_counter() - started:.0f} s)")
    return cases


if __name__ == "__main__":
    sys.exit(main())
