"""Benchmark: half-angle slicing on the demo cumulus and the storm (frame 40: cloud, rain, snow, ice) — ms per frame
and samples/s at 256²/128 slices, 512²/256 slices (Riley's interactive setting) and 768²/512 slices, cpu and cuda
when present, and peak device memory on cuda. On cuda each configuration runs twice: with the sweep captured as a
CUDA graph and replayed (``graph``; its first frame, which captures, is shown apart) and as plain launches
(``plain``). Timings exclude the first (compiling) render and say so. No pass/fail: goals are read by people
(512² x 256 slices in <= 3 s on the 2-core CPU; >= 100 fps on one modern GPU).

Run:  python evaluation/benchmarks/bench_slicing.py [--json out/bench_slicing.json] [--configs 256x128,512x256]
      [--stages cumulus.usda,storm.usda@40] (stages under usd_scenes/, @ picks the time code)
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
    parser.add_argument("--stages", default="cumulus.usda,storm.usda@40",
                        help="stages under usd_scenes/, comma-separated, each optionally @TIME")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "bench_slicing.json")
    parser.add_argument("--configs", default="256x128,512x256,768x512", help="SIZExSLICES, comma-separated")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--convergence", action="store_true",
                        help="instead: the slice-count convergence sequence of each light update on a soft puff")
    args = parser.parse_args(argv)
    if args.convergence:
        return convergence()


    from warpsky.core.device import init_warp
    from warpsky.techniques.slicing import sweep
    from warpsky.techniques.slicing.slicing import Slicing, SlicingSettings
    from warpsky.usd.stage import StageReader

    init_warp()
    scenes = []
    for item in args.stages.split(","):
        name, _, when = item.partition("@")
        if name == "cumulus.usda" and not (ROOT / "data" / "cumulus.nvdb").exists():
            print("data/cumulus.nvdb is missing: run `python tools/make_cumulus.py` (or `make data`)", file=sys.stderr)
            return 2
        frame = int(float(when)) if when else 1
        if name == "storm.usda" and not (ROOT / "data" / "storm" / f"cloud.{frame:04d}.nvdb").exists():
            sys.path.insert(0, str(ROOT / "tools"))
            import make_storm

            make_storm.write_frames(ROOT / "data" / "storm", 48, res=64, only=[frame])  # the stage's resolution
        scenes.append((item, StageReader(ROOT / "usd_scenes" / name).scene_at(float(when) if when else None)))
    devices = bench_devices()
    rows = []
    for label, scene in scenes:
        for device in devices:
            Slicing(SlicingSettings(slice_count=2), device=device).render(scene, 8, 8)  # compile, not timed
            for config in args.configs.split(","):
                size, slices = (int(v) for v in config.split("x"))
                for mode in ("graph", "plain") if device.startswith("cuda") else ("plain",):
                    sweep.USE_GRAPHS = mode == "graph"
                    rows.append(timed(Slicing(SlicingSettings(slice_count=slices), device=device), scene, label,
                                      size, slices, mode, max(args.repeats, 2 if mode == "graph" else 1)))
    sweep.USE_GRAPHS = True
    print(f"slicing (defaults); best of {args.repeats} (graph: of the replays), excluding the first compile")
    print(f"{'stage':<16} {'device':<8} {'mode':<6} {'size':>6} {'slices':>7} {'ms':>9} {'first ms':>9} "
          f"{'M samples/s':>12} {'peak MiB':>9}")
    for r in rows:
        print(f"{r['stage']:<16} {r['device']:<8} {r['mode']:<6} {r['size']:>6} {r['slices']:>7} {r['ms']:>9.1f} "
              f"{r['first_ms']:>9.1f} {r['samples_per_s'] / 1e6:>12.1f} {r.get('peak_mib', float('nan')):>9.1f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"machine": platform.platform(), "rows": rows}, indent=2))
    print(f"wrote {args.json}")
    return 0


def timed(technique, scene, label: str, size: int, slices: int, mode: str, repeats: int) -> dict:
    """Frames of ``scene`` at ``size``² with ``slices`` slices: the first frame's ms and the best of the rest (graph
    mode: the first captures, the rest replay; plain: the best of all)."""
    import warp as wp

    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        technique.render(scene, size, size)
        times.append(time.perf_counter() - started)
    best = min(times[1:]) if mode == "graph" else min(times)
    row = {"stage": label, "device": technique.device, "mode": mode, "size": size, "slices": slices,
           "ms": 1e3 * best, "first_ms": 1e3 * times[0], "samples_per_s": size * size * slices / best}
    if technique.device.startswith("cuda"):
        try:  # the mempool's high-water mark, where this Warp has it
            row["peak_mib"] = wp.get_mempool_used_mem_high(technique.device) / 2**20
        except (AttributeError, RuntimeError):
            pass
    return row


def convergence() -> int:
    """Mean |I_2N - I_N| for N = 64 .. 512 on a Gaussian puff (the scene of tests/test_slicing.py), per update."""
    import numpy as np

    from warpsky.core.device import init_warp
    from warpsky.model.scene import Camera, PhaseKind, PhaseModel, Scene, Sun, VoxelMedium
    from warpsky.techniques.slicing.slicing import Slicing, SlicingSettings

    init_warp()
    x = (np.arange(16) + 0.5) / 16 * 2.0 - 1.0
    blob = np.exp(-4.0 * (x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2))
    blob[[0, -1]] = 0.0
    blob[:, [0, -1]] = 0.0
    blob[:, :, [0, -1]] = 0.0
    place = np.eye(4)
    place[:3, :3] *= 20.0 / 16
    place[:3, 3] = -10.0 + 0.5 * 20.0 / 16
    forward = np.array([-0.05, -0.06, -1.0]) / np.linalg.norm([-0.05, -0.06, -1.0])
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    camera = Camera("cam", (3.0, 4.0, 42.0), np.column_stack([right, np.cross(right, forward), -forward]), 50.0,
                    36.0, 36.0)
    medium = VoxelMedium("puff", blob, place, 0.3, 1.0, PhaseModel(PhaseKind.HG, 0.8))
    scene = Scene(camera, Sun((0.4, 0.8, 0.3), np.ones(3)), (medium,))
    counts = (64, 128, 256, 512, 1024)
    print("slice-count convergence, soft puff 16^3 at 12x12: mean |I_2N - I_N|")
    print(f"{'update':<8} " + " ".join(f"{a}->{b:<6}" for a, b in zip(counts, counts[1:], strict=False)) + " ratios")
    for equation in (0, 24, 25):
        images = [Slicing(SlicingSettings(slice_count=n, light_equation=equation)).render(scene, 12, 12).radiance
                  for n in counts]
        diffs = [float(np.abs(b - a).mean()) for a, b in zip(images, images[1:], strict=False)]
        ratios = [b / a for a, b in zip(diffs, diffs[1:], strict=False)]
        print(f"{equation:<8} " + " ".join(f"{d:<10.2e}" for d in diffs) + " " + " ".join(f"{r:.2f}" for r in ratios))
    return 0


if __name__ == "__main__":
    sys.exit(main())
