"""Stratiform layer + radiosity timings (Bouthors 2006 §6): ms per frame at 1024x768 with ~50% of the pixels on
clouds and a 512² thickness map, radiosity ms per iteration and iterations to converge, device arrays allocated
per warm frame (:mod:`warpsky.core.device_buffers`; 0 when every buffer is reused); cpu and cuda when present.
With ``--slab-table`` also prints the slab-vs-Monte-Carlo table (per order and total, the paper's 9 cases).

    python evaluation/benchmarks/bench_stratiform.py [--device cpu|cuda|all] [--json] [--slab-table --photons 400000]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))


def frame_benchmark(device: str, width: int, height: int, repeats: int) -> dict:
    from conftest import look_rotation

    from warpsky.core import device_buffers
    from warpsky.media.stratiform.thickness import GroundTexture, StratiformLayer, procedural_thickness
    from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun
    from warpsky.passes.stratiform.stratiform import Stratiform, StratiformSettings

    layer = StratiformLayer(procedural_thickness(512, cover=0.5, max_thickness=500.0, seed=2), 1200.0,
                            (-12000.0, -12000.0), (24000.0, 24000.0))
    albedo = np.full((256, 256, 3), 0.9, np.float32)
    albedo[:128] = (0.05, 0.08, 0.1)
    texture = GroundTexture(albedo, (-12000.0, -12000.0), (24000.0, 24000.0))
    cam = Camera("c", np.array([0.0, 2.0, 1500.0]), look_rotation((0.0, 0.75, -1.0)), 14.0, 36.0, 27.0, far=2e5)
    scene = Scene(cam, Sun((0.4, 0.75, 0.3), (1.0, 1.0, 1.0)), ground=Ground(0.0), atmosphere=Atmosphere())
    technique = Stratiform(StratiformSettings(radiosity=1), device=device)
    out = technique.render(scene, width, height, layer=layer, ground_texture=texture)  # compile + warm up
    shading, total = [], []
    allocated = device_buffers.allocation_count()
    for _ in range(repeats):
        out = technique.render(scene, width, height, layer=layer, ground_texture=texture)
        shading.append(out.stats["shading_seconds"])
        total.append(out.stats["seconds"])
    allocations = (device_buffers.allocation_count() - allocated) / max(repeats, 1)
    covered = float(np.mean(out.transmittance[..., 1] < 0.999))
    return {"device": device, "width": width, "height": height, "covered_fraction": covered,
            "shading_ms": 1e3 * min(shading), "frame_ms": 1e3 * min(total),
            "radiosity_iterations": out.stats["radiosity_iterations"],
            "radiosity_ms_per_iteration": 1e3 * out.stats["radiosity_seconds"] / out.stats["radiosity_iterations"],
            "radiosity_residual": out.stats["radiosity_residual"], "allocations_per_frame": allocations}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="all")
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=768)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--slab-table", action="store_true")
    parser.add_argument("--photons", type=int, default=400_000)
    args = parser.parse_args(argv)
    import warp as wp

    from warpsky.core.device import init_warp

    init_warp()
    devices = ["cpu"] + (["cuda:0"] if wp.get_cuda_device_count() else [])
    if args.device != "all":
        devices = [args.device]
    rows = [frame_benchmark(d, args.width, args.height, args.repeats) for d in devices]
    result = {"frames": rows}
    if args.slab_table:
        from evaluation.stratiform_compare import compare_case, format_table
        from warpsky.passes.stratiform.optics import stratiform_optics

        started = time.perf_counter()
        optics = stratiform_optics()
        cases = [compare_case(optics, h, th, args.photons, device=devices[-1])
                 for h in (5.0, 100.0, 500.0) for th in (30.0, 70.0, 80.0)]
        result["slab_table"] = format_table(cases)
        result["slab_seconds"] = time.perf_counter() - started
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{'device':<8} {'size':>10} {'covered':>8} {'shading ms':>11} {'frame ms':>9} {'fps':>7} {'rad it':>7} "
          f"{'ms/it':>7} {'residual':>9} {'allocs':>6}")
    for r in rows:
        print(f"{r['device']:<8} {r['width']:>5}x{r['height']:<4} {r['covered_fraction']:8.2f} {r['shading_ms']:11.1f} "
              f"{r['frame_ms']:9.1f} {1e3 / r['frame_ms']:7.1f} {r['radiosity_iterations']:7d} "
              f"{r['radiosity_ms_per_iteration']:7.2f} {r['radiosity_residual']:9.2e} "
              f"{r['allocations_per_frame']:6.1f}")
    if args.slab_table:
        print(result["slab_table"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
