"""Frames per hour for the storm sequence in-process and on a Dask LocalCluster, and one frame's breakdown.

Renders the 48-frame storm (``usd_scenes/storm.usda``; its fields from ``data/storm``, written first by
``tools/make_storm.py`` when missing) at 256 wide with slicing, once in this process and
once with ``--workers N`` (a Dask LocalCluster of N single-threaded processes), every frame rendered afresh
(``overwrite``). Wall time includes the cluster's start and each worker's first kernel load. Then times one frame's
stages separately: stage load + plan, optics tables (cached load), media upload, the slicing sweep, sky and
composite, EXR write.

Run:  python evaluation/benchmarks/bench_farm.py [--frames 48] [--res 256] [--workers 2] [--device auto] [--json
out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))


def ensure_storm(frames: int) -> Path:
    import make_storm

    data = ROOT / "data" / "storm"
    if not all((data / make_storm.file_name(f, frames)).is_file() for f in ("cloud", "rain", "snow", "ice")):
        make_storm.write_frames(data, 48)
    return ROOT / "usd_scenes" / "storm.usda"


def batch(stage: Path, frames: int, options, out: Path, executor) -> dict:
    from warpsky.batch.run import FrameJob, run_batch

    jobs = [FrameJob(str(stage), float(f), str(out / f"storm.{f:04d}.exr"), options, True)
            for f in range(1, frames + 1)]
    started = time.perf_counter()
    try:
        result = run_batch(str(stage), jobs, executor, log=out / "storm.log.json")
    finally:
        executor.close()
    wall = time.perf_counter() - started
    done = [r for r in result.records if r.status == "done"]
    if len(done) != frames:
        raise SystemExit(f"{frames - len(done)} frame(s) failed: {[r.error for r in result.failed][:3]}")
    return {"executor": executor.name, "frames": frames, "wall_s": wall, "frames_per_hour": 3600.0 * frames / wall,
            "mean_frame_s": sum(r.seconds for r in done) / len(done)}


def breakdown(stage: Path, frame: float, options) -> dict:
    """One frame, stage by stage (after a warm-up render, so compile time is excluded)."""
    import warp as wp

    from warpsky.media.voxels.voxel import VoxelMediaBuffers
    from warpsky.optics.tables import ams_table
    from warpsky.output.exr import write_exr
    from warpsky.passes.composite import composite
    from warpsky.passes.frame import render_layers
    from warpsky.render.frame import render_frame
    from warpsky.render.planned import plan_frame
    from warpsky.usd.stage import StageReader

    reader = StageReader(stage)
    with tempfile.TemporaryDirectory() as tmp:
        render_frame(reader, frame, Path(tmp) / "warm.exr", options)
        times = {}
        t0 = time.perf_counter()
        scene, plan = plan_frame(StageReader(stage), frame, options)
        times["stage load + plan"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for species in scene.species:
            ams_table(species, int(plan.settings.orders))
        times["optics tables (cached)"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        VoxelMediaBuffers.upload(scene.media, scene.camera.position, plan.device, scene.species)
        wp.synchronize_device(plan.device)
        times["media upload"] = time.perf_counter() - t0
        technique = plan.renderer
        sweeps = []
        for _ in range(2):
            t0 = time.perf_counter()
            technique.render(scene, plan.width, plan.height)
            sweeps.append(time.perf_counter() - t0)
        times["slicing sweep (best of 2; its own table load + upload)"] = min(sweeps)
        t0 = time.perf_counter()
        _, layers = render_layers(plan, scene, technique)
        image = composite(layers, far=scene.camera.far)
        times["sky pass + slicing + composite"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        write_exr(Path(tmp) / "frame.exr", image.rgba, transmittance=image.transmittance, depth=image.depth,
                  aovs=image.aovs, metadata={"bench": "farm"})
        times["EXR write"] = time.perf_counter() - t0
    return times


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    from warpsky.batch.run import DaskExecutor, InProcessExecutor
    from warpsky.core.device import init_warp, resolve_device
    from warpsky.render.options import RenderOptions

    init_warp()
    stage = ensure_storm(args.frames)
    options = RenderOptions(technique="slicing", resolution=(args.res, None), device=resolve_device(args.device))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        rows.append(batch(stage, args.frames, options, Path(tmp) / "a", InProcessExecutor()))
        rows.append(batch(stage, args.frames, options, Path(tmp) / "b", DaskExecutor(workers=args.workers)))
    speedup = rows[1]["frames_per_hour"] / rows[0]["frames_per_hour"]
    parts = breakdown(stage, float(args.frames * 3 // 4), options)
    print(f"storm, {args.frames} frames at {args.res} wide, device {options.device}")
    print(f"| {'executor':<58} | wall s | frames/hour | mean s/frame (worker) |")
    print(f"|{'-' * 60}|--------|-------------|-----------------------|")
    for row in rows:
        print(f"| {row['executor']:<58} | {row['wall_s']:6.1f} | {row['frames_per_hour']:11.0f} | "
              f"{row['mean_frame_s']:21.2f} |")
    print(f"speed-up with {args.workers} workers: {speedup:.2f}x")
    print("one frame (warm), seconds:")
    for name, seconds in parts.items():
        print(f"  {name:<56} {seconds:7.3f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "speedup": speedup, "breakdown_s": parts,
                                         "device": options.device, "res": args.res}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
