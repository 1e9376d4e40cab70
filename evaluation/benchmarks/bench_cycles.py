"""Benchmark: warpsky's default technique (``hybrid``) against Blender Cycles 5, error against time, on one cloud.

The scene is a stage's voxel cloud under its sun alone (default ``usd_scenes/cumulus.usda``): a derived stage
without the air, the ground or anything else is written to ``data/cycles/`` and read by both sides; Cycles gets it
through :mod:`evaluation.cycles_scene` (same camera, sun, extinction, albedo, Henyey-Greenstein g; black world; box
pixel filter; 1024 bounces), run in bpy's Python (``make cycles-env`` makes ``.venv-cycles``).

1. Reference: warpsky's unbiased ``path_tracer`` at ``--reference-spp`` (1024 bounces, Cycles' cap too), cached
   under ``$WARPSKY_CACHE/reference`` (:func:`evaluation.error_vs_time.reference_image`). Errors are the family
   benchmarks' (:func:`evaluation.error_vs_time.error_metrics` over :func:`evaluation.family.covered_pixels`): the
   *net* relative RMSE, with the reference's own noise taken out.
2. Mean check: plain Cycles path tracing at ``--check-samples``: the covered mean against the reference's, and
   the per-pixel bias seen through 8 x 8 pixel blocks (the blocks' relative RMS difference, which more samples
   shrink unless one side is biased), and net RMSE x sqrt(samples) (constant for an unbiased estimator).
3. Time to each ``--targets`` net error: ``hybrid`` along doubling ``--spp`` (``target_error=0``) and each Cycles
   variant (plain path tracing, + OIDN, + volume path guiding + OIDN) along doubling samples; the rungs of all
   renderers interleaved, each run a fresh process (``warpsky render`` / ``python cycles_scene.py render``) so the
   whole command's wall time is known beside the render phase (warpsky: the EXR header's ``renderSeconds``; Cycles:
   its render call, scene sync and denoising included). A renderer stops climbing once it reaches the smallest
   target or its error levels off (a bias more samples do not remove). Every command runs once untimed first
   (compiled kernels, warm file caches).

Writes the table to ``--out`` (Markdown, the command that made it on top) and the rows to the same name ``.json``.

Run:  python evaluation/benchmarks/bench_cycles.py [--targets 0.10,0.05] [--repeats 1] [--out docs/validation/cycles.md]
          [--reference-spp 4096] [--variants path,oidn,guided_oidn] [--max-samples 16384] [--max-seconds 900]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from evaluation.benchmarks.bench_memory import warpsky_command  # noqa: E402

#: Prim types the derived stage keeps: the camera, the sun, the volume and its fields, the render settings.
KEPT_TYPES = {"Xform", "Camera", "DistantLight", "Volume", "OpenVDBAsset", "RenderSettings", "RenderProduct",
              "RenderVar"}
CYCLES_SCRIPT = ROOT / "evaluation" / "cycles_scene.py"
BLOCK = 8  # pixels per side of the mean check's blocks
#: A renderer stops climbing when a rung's net error is above this fraction of the error two rungs (4x) before.
PLATEAU = 0.9
#: ... from this rung on: below it a denoised image's error can stay flat before it falls (hybrid on the demo cloud:
#: 0.22 net at 4 and 16 paths per pixel, 0.17 at 64).
PLATEAU_FROM = 256


def sun_only_stage(stage: Path, out: Path, size: int) -> Path:
    """``stage`` without air, ground or any prim but the camera, sun and volumes, at ``size`` x ``size``, flattened
    (asset paths made absolute) to ``out``."""
    from pxr import Gf, Usd, UsdRender

    source = Usd.Stage.Open(str(stage))
    drop = []
    for prim in source.Traverse():
        path = prim.GetPath()
        if (prim.GetTypeName() not in KEPT_TYPES and str(path) != "/Render"
                and not any(path.HasPrefix(dropped) for dropped in drop)):
            drop.append(path)
    for path in drop:
        source.RemovePrim(path)
    for prim in source.Traverse():
        if prim.IsA(UsdRender.Settings):
            UsdRender.Settings(prim).GetResolutionAttr().Set(Gf.Vec2i(size, size))
    layer = source.Flatten()
    layer.documentation = f"{stage.name}'s cloud and sun alone (no air, ground or other prims), {size}x{size}"
    out.parent.mkdir(parents=True, exist_ok=True)
    layer.Export(str(out))
    return out


def prepare(stage: Path, folder: Path, size: int, python: Path):
    """(derived stage, its scene, the Cycles description's path): the sun-only stage, its Cycles description and
    OpenVDB grid, all under ``folder``."""
    from evaluation.cycles_scene import write_description
    from warpsky.usd.stage import StageReader

    derived = sun_only_stage(stage, folder / f"{stage.stem}_sun_only.usda", size)
    scene = StageReader(derived).scene_at(None)
    description = write_description(scene, size, size, folder)
    subprocess.run([str(python), str(CYCLES_SCRIPT), "write-vdb", str(description)], check=True,
                   capture_output=True, text=True)
    return derived, scene, description


def radiance_of(path: Path) -> np.ndarray:
    """(H, W, 3) float64 RGB of an EXR."""
    from warpsky.output.exr import read_exr

    channels = read_exr(path).channels
    return np.stack([channels[c] for c in "RGB"], axis=-1).astype(np.float64)


def run_warpsky(stage: Path, out: Path, size: int, spp: int, seed: int) -> dict:
    """One ``warpsky render`` of ``hybrid`` at ``spp`` multiple-scattering paths per pixel (no error target)."""
    command = [*warpsky_command(), "render", str(stage), str(out), "--technique", "hybrid", "--res",
               f"{size}x{size}", "--spp", str(spp), "--set", "target_error=0", "--seed", str(seed), "--device",
               "cpu", "--float", "-q", "--overwrite"]
    started = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, text=True)
    command_seconds = time.perf_counter() - started
    from warpsky.output.exr import read_exr

    render_seconds = float(read_exr(out).metadata["renderSeconds"])
    return {"command_seconds": command_seconds, "render_seconds": render_seconds, "image": radiance_of(out)}


def run_cycles(python: Path, description: Path, out: Path, samples: int, variant: str, seed: int) -> dict:
    """One Cycles render of ``variant`` at ``samples`` per pixel in bpy's Python."""
    command = [str(python), str(CYCLES_SCRIPT), "render", str(description), str(out), "--samples", str(samples),
               "--variant", variant, "--seed", str(seed)]
    started = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, text=True)
    command_seconds = time.perf_counter() - started
    record = json.loads(out.with_suffix(".json").read_text())
    return {"command_seconds": command_seconds, "render_seconds": record["render_seconds"],
            "first_sample_seconds": record["first_sample_seconds"], "image": radiance_of(out)}


class Judge:
    """The reference and what errors are measured over: :func:`error_metrics` over the covered pixels, and the
    mean check's block bias."""

    def __init__(self, scene, size: int, spp: int, seed: int, log):
        from evaluation.error_vs_time import reference_image
        from evaluation.family import covered_pixels

        started = time.perf_counter()
        self.radiance, _, self.variance, seconds, cached = reference_image(scene, size, size, "cpu", spp=spp,
                                                                           seed=seed)
        self.covered = covered_pixels(scene, size, size, "cpu")
        mean = float(self.radiance[self.covered].mean())
        self.info = {"spp": spp, "seed": seed, "render_seconds": seconds, "cached": cached,
                     "covered_pixels": int(self.covered.sum()), "mean_radiance": mean,
                     "rel_noise_per_pixel": float(np.sqrt(self.variance[self.covered].mean()) / mean)}
        log(f"reference: path_tracer {spp} spp, {'cached' if cached else f'{time.perf_counter() - started:.0f} s'}, "
            f"{self.info['covered_pixels']} covered pixels, per-pixel noise {self.info['rel_noise_per_pixel']:.4f}")

    def metrics(self, image: np.ndarray) -> dict:
        from evaluation.error_vs_time import error_metrics

        return error_metrics(image, self.radiance, self.covered, self.variance)

    def block_bias(self, image: np.ndarray) -> float:
        """Relative RMS difference of 8 x 8 pixel block means (luminance-free: channels averaged) over the blocks
        that hold a covered pixel, against the covered mean; the reference's block noise taken out."""
        h, w = self.radiance.shape[:2]
        shape = (h // BLOCK, BLOCK, w // BLOCK, BLOCK)
        x = image.mean(-1)[: shape[0] * BLOCK, : shape[2] * BLOCK].reshape(shape).mean((1, 3))
        r = self.radiance.mean(-1)[: shape[0] * BLOCK, : shape[2] * BLOCK].reshape(shape).mean((1, 3))
        v = self.variance.mean(-1)[: shape[0] * BLOCK, : shape[2] * BLOCK].reshape(shape).mean((1, 3)) / BLOCK ** 2
        seen = self.covered[: shape[0] * BLOCK, : shape[2] * BLOCK].reshape(shape).any((1, 3))
        mse = float(np.mean((x - r)[seen] ** 2) - np.mean(v[seen]))
        return math.sqrt(max(mse, 0.0)) / self.info["mean_radiance"]


def mean_check(judge: Judge, python: Path, description: Path, folder: Path, samples: list[int], log) -> list[dict]:
    """Plain Cycles path tracing at each sample count against the reference (section 2 of the module docstring)."""
    rows = []
    for n in samples:
        run = run_cycles(python, description, folder / f"check_{n}.exr", n, "path", seed=11)
        metrics = judge.metrics(run["image"])
        row = {"samples": n, "mean_ratio": 1.0 + metrics["bias"], "net_rmse": metrics["net_rmse"],
               "net_rmse_sqrt_n": metrics["net_rmse"] * math.sqrt(n), "block_bias": judge.block_bias(run["image"]),
               "render_seconds": run["render_seconds"]}
        rows.append(row)
        log(f"mean check: cycles path {n:5d} spp  mean ratio {row['mean_ratio']:.4f}  net {row['net_rmse']:.4f}  "
            f"net*sqrt(n) {row['net_rmse_sqrt_n']:.3f}  block bias {row['block_bias']:.4f}  "
            f"{row['render_seconds']:.1f} s")
    return rows


def renderers(variants: list[str]) -> list[dict]:
    """The measured renderers: warpsky's hybrid and each Cycles variant."""
    return [{"name": "warpsky hybrid", "kind": "warpsky", "unit": "spp"}] + [
        {"name": f"cycles {v}", "kind": "cycles", "variant": v, "unit": "samples"} for v in variants]


def render_once(renderer: dict, n: int, seed: int, setup: dict, out: Path) -> dict:
    if renderer["kind"] == "warpsky":
        return run_warpsky(setup["stage"], out, setup["size"], n, seed)
    return run_cycles(setup["python"], setup["description"], out, n, renderer["variant"], seed)


def ladders(judge: Judge, setup: dict, targets: list[float], args, log, rows: list[dict], progress) -> bool:
    """Every renderer's rungs (doubling from 1), interleaved: rung k of each renderer still climbing, then rung
    k + 1, appended to ``rows`` (``progress(rows)`` after each). A renderer stops once its median net error is at
    most the smallest target, its rung passes ``--max-samples``, its median render time ``--max-seconds``, or its
    error has levelled off (:data:`PLATEAU`: a bias, such as a denoiser's, that more samples do not remove). No rung
    starts after ``--max-minutes``. Returns whether every renderer stopped by those rules (False: out of time)."""
    folder, deadline = setup["folder"], time.perf_counter() + 60.0 * (args.max_minutes or math.inf)
    climbing = renderers(args.variants)
    for renderer in climbing:  # untimed: compiles, file caches
        render_once(renderer, 1, 0, setup, folder / "warm.exr")
    k = 0
    while climbing:
        n = 2 ** k
        for renderer in list(climbing):
            if time.perf_counter() > deadline:
                log(f"--max-minutes {args.max_minutes:g} passed: {', '.join(r['name'] for r in climbing)} stopped")
                return False
            runs = []
            for repeat in range(args.repeats):
                run = render_once(renderer, n, 1 + repeat, setup, folder / "run.exr")
                runs.append({**judge.metrics(run.pop("image")), **run})
            row = {"renderer": renderer["name"], "n": n, "unit": renderer["unit"], "repeats": args.repeats,
                   **{key: float(np.median([r[key] for r in runs]))
                      for key in ("net_rmse", "rel_rmse", "bias", "render_seconds", "command_seconds")},
                   "first_sample_seconds": float(np.median([r.get("first_sample_seconds", math.nan) for r in runs])),
                   "load": os.getloadavg()[0]}
            rows.append(row)
            progress(rows)
            log(f"{row['renderer']:20s} {n:5d} {row['unit']:7s} net {row['net_rmse']:.4f}  bias {row['bias']:+.4f}"
                f"  render {row['render_seconds']:7.2f} s  command {row['command_seconds']:7.2f} s  "
                f"load {row['load']:.2f}")
            own = [r["net_rmse"] for r in rows if r["renderer"] == renderer["name"]]
            plateau = n >= PLATEAU_FROM and own[-1] > PLATEAU * own[-3]  # four times the work, under 10 % gained
            if (row["net_rmse"] <= min(targets) or 2 * n > args.max_samples
                    or row["render_seconds"] > args.max_seconds or plateau):
                climbing.remove(renderer)
        k += 1
    return True


def time_to_target(rows: list[dict], renderer: str, target: float) -> dict:
    """The first rung of ``renderer`` at or under ``target``, with the render time interpolated log-log between
    it and the rung before (errors fall as a power of the time); ``reached`` False with the best rung if none."""
    own = [r for r in rows if r["renderer"] == renderer]
    for i, row in enumerate(own):
        if row["net_rmse"] <= target:
            interpolated = row["render_seconds"]
            if i > 0 and own[i - 1]["net_rmse"] > target and row["net_rmse"] > 0:
                before = own[i - 1]
                slope = math.log(row["render_seconds"] / before["render_seconds"]) / math.log(
                    before["net_rmse"] / row["net_rmse"])
                interpolated = before["render_seconds"] * (before["net_rmse"] / target) ** slope
            return {"reached": True, **row, "interpolated_seconds": interpolated}
    best = min(own, key=lambda r: r["net_rmse"])
    return {"reached": False, **best, "interpolated_seconds": math.nan}


def markdown(report: dict) -> str:
    """The page ``--out`` holds: settings, the mean check and time to each target per renderer."""
    ref, lines = report["reference"], []
    lines += ["# warpsky against Blender Cycles 5: error against time", "",
              *([] if report["finished"] else [
                  "**Partial**: written while (or after) the ladders stopped short of their rules (`--max-minutes`"
                  " or an interrupted run); a renderer still climbing shows *not reached*.", ""]),
              f"Written by `{report['command']}` at commit {report['commit']} on {report['date']} "
              f"({report['machine']}; load average "
              f"{report['load_before']:.2f} before, {report['load_after']:.2f} after: the CPU was shared).", "",
              f"Scene: {report['stage']}'s cloud and sun alone (no air, no ground, black background), "
              f"{report['size']}x{report['size']}, box pixel filter, 1024 bounces; Cycles {report['blender']} on the "
              "CPU (unbiased null-scattering volumes, no clamping, no adaptive sampling) gets the same camera, sun, "
              "extinction, albedo and Henyey-Greenstein g through `evaluation/cycles_scene.py`. Reference: warpsky's "
              f"path_tracer at {ref['spp']} spp ({ref['covered_pixels']} covered pixels, per-pixel relative noise "
              f"{ref['rel_noise_per_pixel']:.4f}). Error: net relative RMSE over the covered pixels (the reference's "
              "noise taken out), as the family benchmarks measure it.", "",
              "## Cycles' mean against the reference (plain path tracing)", "",
              "| samples | mean / reference | net rel. RMSE | net × √samples | 8×8-block bias | render s |",
              "|---:|---:|---:|---:|---:|---:|"]
    for row in report["mean_check"]:
        lines.append(f"| {row['samples']} | {row['mean_ratio']:.4f} | {row['net_rmse']:.4f} | "
                     f"{row['net_rmse_sqrt_n']:.3f} | {row['block_bias']:.4f} | {row['render_seconds']:.1f} |")
    lines += ["", "## Time to each net error target", "",
              "Render: warpsky's `renderSeconds` (EXR header), Cycles' render call (sync, BVH, volume, sampling, "
              "denoising); command: the whole process, start-up and EXR write included. *Interp.*: the render time "
              "interpolated log-log between the rung that reached the target and the one before (rungs double).", "",
              "| target | renderer | reached at | net | render s | interp. render s | command s |",
              "|---:|---|---:|---:|---:|---:|---:|"]
    for t in report["time_to_target"]:
        reached = f"{t['n']} {t['unit']}" if t["reached"] else f"not reached (best {t['n']} {t['unit']})"
        interpolated = "–" if math.isnan(t["interpolated_seconds"]) else f"{t['interpolated_seconds']:.2f}"
        lines.append(f"| {t['target']:.3f} | {t['renderer']} | {reached} | {t['net_rmse']:.4f} | "
                     f"{t['render_seconds']:.2f} | {interpolated} | {t['command_seconds']:.2f} |")
    lines += ["", "## Every rung", "", "Cycles' *first sample*: seconds into its render call when the first sample "
              "started (scene sync and the volume's density octree before it).", "",
              "| renderer | n | net | bias | render s | first sample s | command s | load |",
              "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in report["rows"]:
        first = "" if math.isnan(row["first_sample_seconds"]) else f"{row['first_sample_seconds']:.2f}"
        lines.append(f"| {row['renderer']} | {row['n']} {row['unit']} | {row['net_rmse']:.4f} | {row['bias']:+.4f} | "
                     f"{row['render_seconds']:.2f} | {first} | {row['command_seconds']:.2f} | {row['load']:.2f} |")
    return "\n".join(lines + [""])


def parse(argv):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", type=Path, default=ROOT / "usd_scenes" / "cumulus.usda")
    parser.add_argument("--size", type=int, default=128, help="square image size [px] (default 128)")
    parser.add_argument("--targets", default="0.10,0.05", help="net relative errors (default 0.10,0.05)")
    parser.add_argument("--repeats", type=int, default=1, help="runs per rung (seeds 1..N), medians kept")
    parser.add_argument("--variants", default="path,oidn,guided_oidn", help="Cycles variants, comma-separated")
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--check-samples", default="16,64,256,1024", help="the mean check's Cycles samples")
    parser.add_argument("--max-samples", type=int, default=16384, help="highest rung of any renderer")
    parser.add_argument("--max-seconds", type=float, default=900.0, help="a renderer stops after a rung this long")
    parser.add_argument("--max-minutes", type=float, default=0.0,
                        help="start no rung after this many minutes of ladders (default 0: no limit)")
    parser.add_argument("--python", type=Path, default=ROOT / ".venv-cycles" / "bin" / "python",
                        help="bpy's Python (make cycles-env)")
    parser.add_argument("--work", type=Path, default=ROOT / "data" / "cycles", help="derived stage, VDB, EXRs")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "validation" / "cycles.md")
    args = parser.parse_args(argv)
    args.variants = [v for v in args.variants.split(",") if v]
    return args


def run_facts(args) -> dict:
    """What the page says about the run: the command, commit, Blender, machine and load."""
    def output(*command):
        return subprocess.run(command, capture_output=True, text=True).stdout.strip()

    dirty = output("git", "-C", str(ROOT), "status", "--porcelain", "--", "warpsky", "evaluation")
    return {"command": " ".join(["python", str(Path(sys.argv[0]).resolve().relative_to(ROOT)), *sys.argv[1:]]),
            "commit": output("git", "-C", str(ROOT), "rev-parse", "--short", "HEAD")
            + (" with uncommitted changes" if dirty else ""),
            "blender": output(str(args.python), "-c", "import bpy; print(bpy.app.version_string)"),
            "machine": f"{os.cpu_count()}-core CPU, no GPU used", "load_before": os.getloadavg()[0],
            "stage": args.stage.name, "size": args.size}


def finite(value):
    """``value`` with every NaN float replaced by None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [finite(v) for v in value]
    return None if isinstance(value, float) and math.isnan(value) else value


def write_report(facts: dict, judge: Judge, check: list[dict], rows: list[dict], args, finished: bool) -> dict:
    """Write the page and its JSON (also while the ladders climb: ``finished`` False marks it partial)."""
    targets = [float(t) for t in args.targets.split(",")]
    report = {**facts, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "finished": finished,
              "load_after": os.getloadavg()[0], "reference": judge.info, "mean_check": check, "rows": rows,
              "time_to_target": [{"target": t, **time_to_target(rows, r["name"], t)}
                                 for t in targets for r in renderers(args.variants)
                                 if any(row["renderer"] == r["name"] for row in rows)]}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(report))
    args.out.with_suffix(".json").write_text(json.dumps(finite(report), indent=1))
    return report


def main(argv=None) -> int:
    args = parse(argv)
    from warpsky.core.device import init_warp

    init_warp()

    def log(text):
        print(text, file=sys.stderr, flush=True)

    if not args.python.is_file():
        log(f"{args.python} is missing: run `make cycles-env` (bpy 5.0 in its own Python 3.11 environment)")
        return 2
    facts = run_facts(args)
    stage, scene, description = prepare(args.stage, args.work, args.size, args.python)
    setup = {"stage": stage, "size": args.size, "python": args.python, "description": description,
             "folder": args.work}
    judge = Judge(scene, args.size, args.reference_spp, seed=9001, log=log)
    check = mean_check(judge, args.python, description, args.work,
                       [int(n) for n in args.check_samples.split(",") if n], log)
    targets = [float(t) for t in args.targets.split(",")]
    rows: list[dict] = []
    finished = ladders(judge, setup, targets, args, log, rows,
                       lambda so_far: write_report(facts, judge, check, so_far, args, finished=False))
    print(markdown(write_report(facts, judge, check, rows, args, finished)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
