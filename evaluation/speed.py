"""Speed of every technique on every device: cold and warm frames, kernel vs wall time, peak memory, paths/s.

A row is one (device, CPU thread count, stage, technique) and runs in a fresh Python process (this module run as
``python -m evaluation.speed ROW_JSON``), for three reasons:

- "cold" is then really the first frame of a process: every kernel module is either compiled or loaded from
  Warp's kernel cache, and the row says which. The count is taken where Warp itself decides,
  ``Module._compile``, which returns whether it compiled or found the binary in the cache; if a later Warp
  drops that method the row says ``unknown`` rather than guessing.
- The peak memory is the row's own: on CUDA the mempool's high-water mark (``wp.get_mempool_used_mem_high``,
  which cannot be reset within a process), on the CPU the process's peak resident set size (Python, USD and Warp
  included, so it is an upper bound on what the frame needs).
- ``WARPSKY_CPU_THREADS`` is read by every CPU launch; a child per thread count sets it cleanly.

What is timed: ``render_layers`` (every pass the plan runs: the technique on the media, the sky, stratiform
layers) for a technique, ``StratiformPass.render`` for the stratiform pass; compositing and EXR writing are left
out. The cold frame also counts the plan (``make_plan``: settings resolved, technique built), not the stage read
or Warp's own start-up. Warm ms is the median of ``frames`` frames after the cold one, on the same plan.
On CUDA one more frame runs under ``wp.timing_begin``/``wp.timing_end`` (kernels, copies and memsets, each timed
by CUDA events), so the kernel/copy split comes from a frame of its own and the event overhead stays out of the
warm figure. The CPU cannot split kernel from host time: those columns are ``n/a``.

Monte Carlo techniques run fixed work (see :data:`FIXED_WORK`): the same paths every frame, so the time measures
speed, not the convergence of an error estimate.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from evaluation.speed_table import NOTE, format_table
from warpsky.core.device import is_cpu
from warpsky.core.errors import UsageError

#: The stratiform pass, measured on stages with stratiform layers next to the voxel techniques.
STRATIFORM = "stratiform"
#: Settings that make a Monte Carlo technique do the same work every frame (``{spp}`` is ``--spp``).
FIXED_WORK = {
    "path_tracer": {"spp": "{spp}", "seed": "0"},
    "hybrid": {"spp": "{spp}", "target_error": "0", "seed": "0"},
}
DEFAULT_SPP = 16
DEFAULT_STAGES = ("usd_scenes/cumulus.usda", "usd_scenes/stratocumulus.usda")
ROW_MARKER = "WARPSKY_SPEED_ROW "


@dataclass
class RowSpec:
    """One measurement: what a child process renders.

    Attributes:
        stage: Absolute path of the USD stage.
        technique: A registered technique, or :data:`STRATIFORM` for the stratiform pass alone.
        device: Warp device name (``cpu``, ``cuda:0``).
        threads: CPU threads (``WARPSKY_CPU_THREADS``) on the CPU; None on CUDA.
        width, height: Image size [pixels]; height None keeps the camera's aspect.
        frames: Warm frames timed after the cold one.
        settings: Technique settings (``--set`` form) for fixed work.
    """

    stage: str
    technique: str
    device: str
    threads: int | None
    width: int
    height: int | None
    frames: int
    settings: dict[str, str] = field(default_factory=dict)


def fixed_work(technique: str, spp: int) -> dict[str, str]:
    """The settings that fix a technique's work per frame (none for deterministic techniques)."""
    return {name: value.format(spp=spp) for name, value in FIXED_WORK.get(technique, {}).items()}


def check_techniques(techniques: list[str]) -> list[str]:
    """``techniques`` when each is registered or :data:`STRATIFORM`; a UsageError naming the first that is not."""
    from warpsky.render.registry import technique_names

    known = [*technique_names(), STRATIFORM]
    for name in techniques:
        if name not in known:
            raise UsageError(f"bench speed: unknown technique {name!r} in --techniques; available: {', '.join(known)}")
    if not techniques:
        raise UsageError("bench speed: --techniques names no technique")
    return techniques


def plan_rows(stages: list[Path], techniques: list[str], devices: list[str], *, cpu_res, gpu_res, threads: list[int],
              frames: int, spp: int, log=None) -> list[RowSpec]:
    """Every row to measure: each device (each thread count on the CPU) x stage x technique that applies to the
    stage (a voxel technique needs voxel media and, next to stratiform layers, the ability to render beside
    them; the stratiform pass needs layers). Skipped pairs are logged."""
    from warpsky.render.registry import technique_class
    from warpsky.usd.stage import StageReader

    applicable, skipped = [], {}
    for stage in stages:
        scene = StageReader(stage).scene_at(None)
        for technique in techniques:
            if technique == STRATIFORM:
                why = None if scene.stratiform_layers else "no stratiform layers"
            elif not scene.media:
                why = "no voxel media"
            elif scene.stratiform_layers and not technique_class(technique).renders_layers:
                why = "it does not render next to stratiform layers"
            else:
                why = None
            if why is None:
                applicable.append((str(Path(stage).resolve()), technique))
            else:
                skipped.setdefault((Path(stage).name, why), []).append(technique)
    for (name, why), names in skipped.items():
        if log is not None:
            log(f"speed: skipping {', '.join(names)} on {name}: {why}")
    rows = []
    for device in devices:
        cpu = is_cpu(device)
        width, height = cpu_res if cpu else gpu_res
        for count in (threads if cpu else [None]):
            rows += [RowSpec(stage, technique, device, count, width, height, frames, fixed_work(technique, spp))
                     for stage, technique in applicable]
    if not rows:
        raise UsageError("bench speed: no technique applies to the given stages (see the skipped pairs above)")
    return rows


def measure(spec: RowSpec, *, log=None) -> dict:
    """Run one row in a fresh process; its result dict (with ``error`` set when the child failed)."""
    import warpsky

    env = dict(os.environ)
    package_root = str(Path(warpsky.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
    if spec.threads is not None:
        env["WARPSKY_CPU_THREADS"] = str(spec.threads)
    command = [sys.executable, "-m", "evaluation.speed", json.dumps(dataclasses.asdict(spec))]
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith(ROW_MARKER)]
    if done.returncode == 0 and lines:
        row = json.loads(lines[-1][len(ROW_MARKER):])
    else:
        tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
        row = {**dataclasses.asdict(spec), "error": f"exit {done.returncode}: {tail}"}
    if log is not None:
        log(_progress_line(row))
    return row


def _progress_line(row: dict) -> str:
    where = row["device"] + ("" if row.get("threads") is None else f" x{row['threads']}")
    head = f"speed: {where} {Path(row['stage']).stem} {row['technique']}"
    if "error" in row:
        return f"{head}: failed ({row['error']})"
    return f"{head} {row['width']}x{row['height']}: cold {row['cold_ms']:.0f} ms, warm {row['warm_ms']:.1f} ms"


# ------------------------------------------------------------------------------------------------ child process
class CompileLog:
    """Counts, while active, the kernel modules Warp compiles and those it loads from its kernel cache."""

    def __init__(self):
        self.compiled: list[str] = []
        self.cached: list[str] = []
        self.available = False

    def __enter__(self) -> CompileLog:
        try:
            from warp._src.context import Module
        except ImportError:
            return self
        original = getattr(Module, "_compile", None)
        if original is None:
            return self
        log = self

        def counting(module, *args, **kwargs):
            compiled = original(module, *args, **kwargs)
            (log.compiled if compiled else log.cached).append(module.name)
            return compiled

        self._restore = (Module, original)
        Module._compile = counting
        self.available = True
        return self

    def __exit__(self, *exc) -> None:
        if self.available:
            module_class, original = self._restore
            module_class._compile = original

    def describe(self) -> str:
        """``compiled 3 of 5 modules``, ``cache: 5 modules``, or ``unknown``."""
        if not self.available:
            return "unknown"
        total = len(self.compiled) + len(self.cached)
        noun = "module" if total == 1 else "modules"
        if self.compiled:
            return f"compiled {len(self.compiled)} of {total} {noun}"
        return f"cache: {total} {noun}" if total else "no module loaded"


def _frame(scene, spec: RowSpec):
    """(a function rendering one frame and returning its main layer or None, the plan)."""
    from warpsky.passes.frame import render_layers, render_pass
    from warpsky.render.plan import make_plan
    from warpsky.render.registry import DEFAULT_TECHNIQUE

    technique = DEFAULT_TECHNIQUE if spec.technique == STRATIFORM else spec.technique
    plan = make_plan(scene, technique=technique, settings=spec.settings, resolution=(spec.width, spec.height),
                     device=spec.device)
    if spec.technique == STRATIFORM:
        return (lambda: render_pass(plan, scene, STRATIFORM)[0]), plan
    return (lambda: render_layers(plan, scene)[0]), plan


def _timed(render) -> tuple[float, object, float]:
    """(wall ms, the frame's layer, process CPU ms: every thread's, so CPU / wall is the cores the frame kept busy)."""
    import warp as wp

    started, cpu_started = time.perf_counter(), time.process_time()
    layer = render()
    wp.synchronize()
    return 1e3 * (time.perf_counter() - started), layer, 1e3 * (time.process_time() - cpu_started)


def path_stats(layer) -> dict | None:
    """The stats of the part of a frame's layer that traced paths (the layer's own or one of its ``parts``), or None
    when it traced none."""
    if layer is None:
        return None
    stats = next((s for s in [layer.stats, *layer.stats.get("parts", [])] if isinstance(s, dict) and "paths" in s),
                 None)
    if stats is None or not stats.get("paths"):
        return None
    return stats


def monte_carlo(layer) -> tuple[int, float] | None:
    """(paths, seconds spent tracing them) of a frame's layer, or None when it traced no paths. For hybrid the
    tracing time is the frame's less its single-scattering march and denoising."""
    stats = path_stats(layer)
    if stats is None:
        return None
    seconds = stats["seconds"] - stats.get("single_scatter_seconds", 0.0) - stats.get("denoise_seconds", 0.0)
    return int(stats["paths"]), float(seconds)


def path_breakdown(layer) -> dict | None:
    """Per path of a frame's layer: tentative collisions and segment crossings (``steps``), those of shadow rays
    (``shadow_steps``) and scattering ``events``; None when it traced no paths."""
    stats = path_stats(layer)
    if stats is None or "scatter_events" not in stats:
        return None
    paths = float(stats["paths"])
    return {"steps": stats["tracking_steps"] / paths, "shadow_steps": stats["shadow_steps"] / paths,
            "events": stats["scatter_events"] / paths}


def cuda_activity(render, device: str) -> dict:
    """Kernel and copy time [ms] of one frame on ``device`` by CUDA events, with that frame's wall time."""
    import warp as wp

    kernels = (wp.TIMING_KERNEL, wp.TIMING_KERNEL_BUILTIN)
    copies = (wp.TIMING_MEMCPY, wp.TIMING_MEMSET)
    wp.timing_begin(cuda_filter=kernels[0] | kernels[1] | copies[0] | copies[1])
    started = time.perf_counter()
    try:
        render()
    finally:
        results = wp.timing_end()
    wall = 1e3 * (time.perf_counter() - started)
    mine = [r for r in results if r.device is not None and str(r.device) == device]
    return {"kernel_ms": sum(r.elapsed for r in mine if r.filter in kernels),
            "copy_ms": sum(r.elapsed for r in mine if r.filter in copies),
            "kernel_launches": sum(1 for r in mine if r.filter == kernels[0]),
            "activities": len(mine), "timed_frame_wall_ms": wall}


def peak_memory(device: str) -> tuple[float | None, str]:
    """(peak memory [MiB], what it is) of this process on ``device``."""
    import warp as wp

    if device.startswith("cuda"):
        if wp.is_mempool_enabled(device):
            return wp.get_mempool_used_mem_high(device) / 2**20, "cuda mempool high-water mark"
        return None, "unknown: the device's mempool is off"
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "process peak RSS"


def measure_row(spec: RowSpec) -> dict:
    """Measure one row in this (fresh) process: cold frame, ``spec.frames`` warm frames, CUDA activity, memory."""
    import warp as wp

    from warpsky.core.device import cpu_thread_count, init_warp
    from warpsky.usd.stage import StageReader

    init_warp()
    scene = StageReader(spec.stage).scene_at(None)
    with wp.ScopedDevice(spec.device):
        with CompileLog() as compiles:
            started = time.perf_counter()
            render, plan = _frame(scene, spec)
            plan_ms = 1e3 * (time.perf_counter() - started)
            cold_ms = plan_ms + _timed(render)[0]
        warm = [_timed(render) for _ in range(max(1, spec.frames))]
        activity = cuda_activity(render, spec.device) if spec.device.startswith("cuda") else {}
        peak, peak_kind = peak_memory(spec.device)
    traced = [mc for mc in (monte_carlo(layer) for _, layer, _ in warm) if mc is not None and mc[1] > 0.0]
    warm_frames_ms = [ms for ms, _, _ in warm]
    warm_ms = statistics.median(warm_frames_ms)
    cores_busy = sum(cpu for _, _, cpu in warm) / sum(warm_frames_ms)
    return {
        **dataclasses.asdict(spec),
        "width": plan.width,
        "height": plan.height,
        "threads": cpu_thread_count() if is_cpu(spec.device) else None,
        "passes": [STRATIFORM] if spec.technique == STRATIFORM else list(plan.passes),
        "cold_ms": cold_ms,
        "plan_ms": plan_ms,
        "cold_kernels": compiles.describe(),
        "compiled_modules": compiles.compiled,
        "cached_modules": compiles.cached,
        "warm_ms": warm_ms,
        "warm_frames_ms": warm_frames_ms,
        "fps": 1e3 / warm_ms,
        "cores_busy": cores_busy,
        "kernel_ms": activity.get("kernel_ms"),
        "copy_ms": activity.get("copy_ms"),
        "cuda_activity": activity or None,
        "peak_mib": peak,
        "peak_memory": peak_kind,
        "paths_per_frame": traced[0][0] if traced else None,
        "paths_per_s": statistics.median(p / s for p, s in traced) if traced else None,
        "per_path": path_breakdown(warm[-1][1]),
        "resolved_settings": json.loads(json.dumps(plan.settings_dict(), default=str)),
    }


def report(rows: list[dict], *, command: list[str], spp: int, started: float, load_before) -> dict:
    """The JSON document: machine, Warp, the command, the fixed-work settings and every row."""
    import warp as wp

    cuda = [{"name": str(d), "model": getattr(d, "name", "")} for d in wp.get_cuda_devices()]
    return {
        "command": command, "date": time.strftime("%Y-%m-%d %H:%M:%S %z"), "seconds": time.time() - started,
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "cpu_cores": os.cpu_count(), "cuda_devices": cuda},
        "warp": wp.config.version, "load_average_before": load_before,
        "load_average_after": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "fixed_work": {name: fixed_work(name, spp) for name in FIXED_WORK},
        "note": NOTE, "rows": rows,
    }


def write_report(document: dict, path: Path) -> Path:
    from warpsky.core.files import atomic_write

    text = json.dumps(document, indent=2)
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


# --------------------------------------------------------------------------------------------------------- CLI
SPEED_EPILOG = """\
fixed work:
  path_tracer: spp = --spp (default 16), seed 0. hybrid: spp = --spp, target_error = 0 (no early stop, every
  frame traces exactly spp paths per pixel), seed 0, denoising on. slicing, single_scatter and the stratiform pass
  run their defaults (deterministic). Each row's resolved settings are in the JSON.

examples:
  warpsky bench speed                                   # cpu and every cuda device, demo cumulus + stratocumulus
  warpsky bench speed --stages usd_scenes/cumulus.usda --devices cpu --threads 1,2 --frames 3
  warpsky bench speed --devices cuda:0 --gpu-res 1024 --techniques slicing,path_tracer
"""


def add_speed_parser(verbs, resolution) -> None:
    """``warpsky bench speed`` under the ``bench`` verbs; ``resolution`` parses ``WxH`` or ``W``."""
    import argparse
    import textwrap

    speed = verbs.add_parser(
        "speed", help="cold and warm ms per frame of every technique on every device, kernel time, memory",
        description=textwrap.fill(
            "Render each technique (and the stratiform pass on stages with layers) on each device, one fresh "
            "process per row: the cold first frame (kernels compiled or loaded from Warp's cache, as the row "
            "says), the median of --frames warm frames, on CUDA the kernel and copy time of one more frame "
            "and the mempool's peak, on the CPU the process's peak RSS, and paths/s of the Monte Carlo part. "
            "Prints a table and writes JSON.", 112),
        epilog=SPEED_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    speed.add_argument("--stages", default=",".join(DEFAULT_STAGES), metavar="A,B",
                       help=f"comma-separated USD stages (default: {','.join(DEFAULT_STAGES)})")
    speed.add_argument("--techniques", default=None, metavar="A,B",
                       help=f"comma-separated techniques and/or {STRATIFORM} (default: all of them)")
    speed.add_argument("--devices", default=None, metavar="A,B",
                       help="comma-separated: cpu, cuda, cuda:N (default: cpu and every CUDA device present)")
    speed.add_argument("--res", type=resolution, default=(128, None), metavar="WxH",
                       help="image size on the CPU; WIDTH alone keeps the camera's aspect (default 128 wide)")
    speed.add_argument("--gpu-res", type=resolution, default=(512, None), metavar="WxH",
                       help="image size on GPUs (default 512 wide)")
    speed.add_argument("--frames", type=int, default=3, metavar="N", help="warm frames per row (default 3)")
    speed.add_argument("--threads", default=None, metavar="N,M", help="CPU thread counts, one row each, set "
                       "through WARPSKY_CPU_THREADS (default: $WARPSKY_CPU_THREADS, else every core)")
    speed.add_argument("--spp", type=int, default=DEFAULT_SPP, metavar="N",
                       help=f"paths per pixel of path_tracer and hybrid (default {DEFAULT_SPP})")
    speed.add_argument("--json", type=Path, default=Path("out/bench_speed.json"), metavar="PATH",
                       help="where the JSON goes (default out/bench_speed.json)")


def _names(text: str | None) -> list[str]:
    return [part.strip() for part in (text or "").split(",") if part.strip()]


def _counts(text: str, flag: str) -> list[int]:
    try:
        counts = [int(part) for part in _names(text)]
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        raise UsageError(f"bench speed: {flag} takes whole numbers >= 1 separated by commas, got {text!r}")
    return counts


def run_speed_command(args, *, log=None) -> int:
    """``warpsky bench speed``: validate, measure every row, print the table, write the JSON; 1 if a row failed."""
    import warp as wp

    from warpsky.core.device import cpu_thread_count, resolve_device
    from warpsky.render.registry import technique_names

    started, load = time.time(), list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    techniques = check_techniques(_names(args.techniques) or [*technique_names(), STRATIFORM])
    cuda = [f"cuda:{i}" for i in range(wp.get_cuda_device_count())]
    devices = list(dict.fromkeys(resolve_device(name) for name in _names(args.devices) or ["cpu", *cuda]))
    threads = _counts(args.threads, "--threads") if args.threads else [cpu_thread_count()]
    frames, spp = _counts(str(args.frames), "--frames")[0], _counts(str(args.spp), "--spp")[0]
    stages = [Path(name) for name in _names(args.stages)]
    specs = plan_rows(stages, techniques, devices, cpu_res=args.res, gpu_res=args.gpu_res, threads=threads,
                      frames=frames, spp=spp, log=log)
    rows = [measure(spec, log=log) for spec in specs]
    print(format_table(rows))
    document = report(rows, command=list(sys.argv), spp=spp, started=started, load_before=load)
    print(write_report(document, args.json))
    return 1 if any("error" in row for row in rows) else 0


if __name__ == "__main__":
    _spec = RowSpec(**json.loads(sys.argv[1]))
    print(ROW_MARKER + json.dumps(measure_row(_spec)), flush=True)
