"""Benchmark: advected textures — ms per frame for a 512² advected layer (``AdvectedTexture.at``) and a
256³-sampled detail field (``advected_detail`` evaluated at 256³ points by ``AdvectedDetail.sample_grid``), cold
(random access: each frame from its layers' regenerations) and sequential (24 frames/s playback reusing the
previous frame's steps), on cpu and on each cuda device present.

Settings: 3 layers, period 120 s, internal step 1 s (a cold frame takes up to 120 steps per layer); layer: 512²
texture over 20 km, curl-noise flow on a 64² grid (also the coordinate grid); detail: 64³ texture over a
4 x 2 x 4 km box, flow and coordinates on 32 x 16 x 32. Timings exclude setup and the first (compiling) call and
include reading the result back to the host. No pass/fail: goals are read by people.

Run:  python evaluation/benchmarks/bench_advection.py [--json out/bench_advection.json] [--frames 8]
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

PERIOD_S = 120.0
STEP_S = 1.0
FRAME_S = 1.0 / 24.0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_advection.json")
    parser.add_argument("--frames", type=int, default=8, help="frames timed per case (cpu detail: at most 3)")
    args = parser.parse_args(argv)

    import numpy as np
    import warp as wp

    from warpsky.core.device import init_warp
    from warpsky.media.advection.advection import AdvectedDetail, AdvectedTexture, Flow2D, Flow3D, periodic_noise

    init_warp()
    devices = bench_devices()
    layer_texture = (1.0 + 0.25 * periodic_noise((512, 512), smoothing_texels=3.0, seed=1)).astype(np.float32)
    layer_extent = (20000.0, 20000.0)
    layer_flow = Flow2D.procedural(layer_extent, speed_m_s=8.0, scale_m=10000.0, resolution=(64, 64), seed=2,
                                   wind_m_s=(10.0, 3.0))
    detail_texture = (1.0 + 0.25 * periodic_noise((64, 64, 64), smoothing_texels=2.0, seed=3)).astype(np.float32)
    box = (4000.0, 2000.0, 4000.0)
    detail_flow = Flow3D.procedural(box, speed_m_s=5.0, scale_m=2000.0, resolution=(32, 16, 32), seed=4,
                                    wind_m_s=(8.0, 0.0, 2.0))
    rng = np.random.default_rng(7)
    cold_times = rng.uniform(-1.0e4, 1.0e4, 64)

    rows = []
    for device in devices:
        is_cpu = device == "cpu"
        layer = AdvectedTexture(layer_texture, layer_extent, layer_flow, period_s=PERIOD_S, step_s=STEP_S,
                                device=device)
        detail = AdvectedDetail(detail_texture, (-2000.0, 1000.0, -2000.0), detail_flow, period_s=PERIOD_S,
                                step_s=STEP_S, device=device)
        out = wp.zeros((256, 256, 256), dtype=float, device=device)
        cases = [
            ("layer 512^2", lambda t, layer=layer: layer.at(t).numpy(), layer, args.frames),
            ("detail 256^3", lambda t, detail=detail, out=out: detail.sample_grid(t, (256, 256, 256), out=out).numpy(),
             detail, min(args.frames, 3) if is_cpu else args.frames),
        ]
        for name, produce, source, count in cases:
            produce(0.0)  # compile / load, not timed
            wp.synchronize_device(device)
            # cold: every frame from scratch at a random time
            times = []
            for t in cold_times[:count]:
                source.reset()
                started = time.perf_counter()
                produce(float(t))
                wp.synchronize_device(device)
                times.append(time.perf_counter() - started)
            cold = float(np.mean(times))
            # sequential: consecutive frames at 24 frames/s
            start = 5000.0
            produce(start)
            wp.synchronize_device(device)
            started = time.perf_counter()
            for f in range(1, count + 1):
                produce(start + f * FRAME_S)
            wp.synchronize_device(device)
            sequential = (time.perf_counter() - started) / count
            rows.append({"device": device, "case": name, "cold_ms": 1e3 * cold, "sequential_ms": 1e3 * sequential,
                         "frames": count})
    print(f"advected textures: 3 layers, period {PERIOD_S:g} s, step {STEP_S:g} s "
          f"(cold frames: <= {int(PERIOD_S / STEP_S)} steps per layer); timings exclude the first compile")
    print(f"{'device':<8} {'case':<14} {'cold ms/frame':>14} {'sequential ms/frame':>20} {'frames':>7}")
    for r in rows:
        print(f"{r['device']:<8} {r['case']:<14} {r['cold_ms']:>14.1f} {r['sequential_ms']:>20.1f} {r['frames']:>7}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"machine": platform.platform(), "period_s": PERIOD_S, "step_s": STEP_S,
                                     "frame_s": FRAME_S, "rows": rows}, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
