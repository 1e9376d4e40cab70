"""Benchmark: what a small frame's ``warpsky render`` spends outside its own render time, and ``warpsky --help``.

A frame's EXR header records ``warpsky/renderSeconds``, the technique's own time; the rest of the command is the
program's start-up (Python, the imports of Warp, USD, OpenEXR and warpsky's kernel modules), reading the stage and
its cloud, planning, the sky pass, compositing and writing. This runs the command ``--repeats`` times (kernels and
tables cached: a warm start) and prints the median of the whole command's wall time, of renderSeconds and of their
difference; then one run's phases, timed inside the process, and the largest imports of one ``python -X importtime``
run (which itself slows imports down by about a third). With ``--compare DIR`` every repeat also runs the warpsky
tree in DIR (a checkout or ``git archive`` of another commit), interleaved, so that both see the same load on a
shared machine: ``uptime``'s load is printed with the figures. Each tree's bytecode is compiled first
(``compileall``), as an installed package's is.

Run:  python evaluation/benchmarks/bench_startup.py [--repeats 5] [--compare /tmp/before] [--json out/startup.json]
(about 30 s on 2 CPU cores; data/cumulus.nvdb from ``make data``). No pass/fail: goals are read by people.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STAGE = ROOT / "usd_scenes" / "cumulus.usda"

#: Functions timed inside one command (module, attribute path, label): each includes what it imports first.
PHASES = (
    ("warpsky.api", "open_stage", "open the stage (pxr)"),
    ("warpsky.render.planned", "planned_frame", "read the scene and plan the frame"),
    ("warpsky.media.voxels.fields", "load_field", "  of which: read the cloud's grid"),
    ("warpsky.passes.media", "media_scene", "the media's sunlight through the air"),
    ("warpsky.passes.sky.sky", "SkyPass.render", "sky pass"),
    ("warpsky.passes.sky.round_sky", "round_front_inputs", "  of which: the view table"),
    ("warpsky.render.frame", "write_frame", "render and write the frame"),
    ("warpsky.output.exr", "write_channels", "  of which: write the EXR"),
)


def _command(args) -> list[str]:
    return ["-m", "warpsky", "render", str(args.stage), str(args.out), "--res", args.res, "--technique",
            args.technique, "--overwrite", "-q", *args.extra]


def render_once(tree: Path, args) -> dict:
    """Whole command wall time, renderSeconds and their difference [s] for one run in ``tree``."""
    import OpenEXR

    started = time.perf_counter()
    subprocess.run([sys.executable, *_command(args)], cwd=tree, check=True, capture_output=True)
    whole = time.perf_counter() - started
    render = float(OpenEXR.File(str(args.out)).header()["warpsky/renderSeconds"])
    return {"whole": whole, "render": render, "outside": whole - render}


def help_once(tree: Path) -> float:
    """Wall time [s] of ``warpsky --help`` in ``tree``."""
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "warpsky", "--help"], cwd=tree, check=True, capture_output=True)
    return time.perf_counter() - started


def child_phases(argv: list[str]) -> None:
    """In a fresh process: run the command with :data:`PHASES` wrapped by timers; print them as JSON."""
    import functools
    import gc
    import importlib

    started = time.perf_counter()
    sys.path.insert(0, os.getcwd())  # the warpsky of the tree this runs in, before the installed one
    gc.set_threshold(50_000, *gc.get_threshold()[1:])  # as the warpsky program does
    from warpsky.cli.main import main

    seconds = {"import warpsky.cli.main": time.perf_counter() - started}
    for module_name, path, label in PHASES:
        owner = importlib.import_module(module_name)
        *outer, name = path.split(".")
        for part in outer:
            owner = getattr(owner, part)
        original = getattr(owner, name)

        def timed(*a, _original=original, _label=label, **k):
            t = time.perf_counter()
            try:
                return _original(*a, **k)
            finally:
                seconds[_label] = seconds.get(_label, 0.0) + time.perf_counter() - t

        setattr(owner, name, functools.wraps(original)(timed))
        for module in list(sys.modules.values()):  # modules that imported the function by name
            if module is not owner and getattr(module, name, None) is original:
                setattr(module, name, timed)
    from warpsky.render.registry import DEFAULT_TECHNIQUE, technique_class

    technique = technique_class(argv[argv.index("--technique") + 1] if "--technique" in argv else DEFAULT_TECHNIQUE)
    render, cpu = technique.render, {"technique": 0.0}

    def cpu_timed(*a, **k):
        t = time.process_time()
        try:
            return render(*a, **k)
        finally:
            cpu["technique"] += time.process_time() - t

    technique.render = cpu_timed
    code = main(argv)
    seconds["whole (in process)"] = time.perf_counter() - started
    # CPU time hardly grows with other processes' load, unlike wall time; outside the technique the command runs
    # on one thread, so there it is what an idle machine's wall time would be
    seconds["CPU: the whole process"] = time.process_time()
    seconds["CPU: the technique's render (all threads)"] = cpu["technique"]
    seconds["CPU: outside the technique"] = time.process_time() - cpu["technique"]
    print(json.dumps({"code": code, "seconds": seconds}))


def phases(tree: Path, args) -> dict[str, float]:
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", *_command(args)[2:]], cwd=tree,
                          check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])["seconds"]


def largest_imports(tree: Path, args, count: int) -> list[tuple[float, str]]:
    """(cumulative seconds, module) of the ``count`` slowest imports that the program or a function imported
    directly (top level of ``-X importtime``'s tree), and the total of those top-level imports."""
    done = subprocess.run([sys.executable, "-X", "importtime", *_command(args)], cwd=tree, check=True,
                          capture_output=True, text=True)
    top = []
    for line in done.stderr.splitlines():
        if line.startswith("import time:") and "self [us]" not in line:
            _, cumulative, name = line.split("|")
            if not name.startswith("  "):
                top.append((int(cumulative) * 1e-6, name.strip()))
    top.sort(reverse=True)
    return [(sum(s for s, _ in top), "all top-level imports")] + top[:count]


def main(argv=None) -> int:
    if argv is None and sys.argv[1:2] == ["--child"]:
        child_phases(sys.argv[2:])
        return 0
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", type=Path, default=STAGE)
    parser.add_argument("--res", default="128x128")
    parser.add_argument("--technique", default="single_scatter")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--compare", type=Path, default=None, help="another warpsky tree, run interleaved")
    parser.add_argument("--imports", type=int, default=12, help="how many of the largest imports to list")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args, args.extra = parser.parse_known_args(argv)
    if args.stage == STAGE and not (ROOT / "data" / "cumulus.nvdb").is_file():
        print("data/cumulus.nvdb is missing: run `make data`", file=sys.stderr)
        return 1
    trees = {"this tree": ROOT, **({"compared": args.compare.resolve()} if args.compare else {})}
    args.stage = args.stage.resolve()
    with tempfile.TemporaryDirectory(prefix="warpsky-startup-") as folder:
        args.out = Path(folder) / "frame.exr"
        for tree in trees.values():  # a first run each: kernels and tables cached before timing
            # bytecode written as an installed package has it (PYTHONDONTWRITEBYTECODE would leave every edited
            # module to be compiled again at each start, about 4 ms each)
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / "warpsky")], check=True)
            render_once(tree, args)
        load_before = os.getloadavg()
        runs = {label: [] for label in trees}
        helps = {label: [] for label in trees}
        for _ in range(args.repeats):
            for label, tree in trees.items():
                runs[label].append(render_once(tree, args))
                helps[label].append(help_once(tree))
        load_after = os.getloadavg()
        report = {"stage": str(args.stage), "res": args.res, "technique": args.technique, "repeats": args.repeats,
                  "load_1min": [load_before[0], load_after[0]], "trees": {}}
        for label, tree in trees.items():
            median = {key: statistics.median(r[key] for r in runs[label]) for key in ("whole", "render", "outside")}
            report["trees"][label] = {
                "path": str(tree), "median": median, "runs": runs[label],
                "help_median": statistics.median(helps[label]), "phases": phases(tree, args),
                "imports": largest_imports(tree, args, args.imports)}
    print(f"warpsky render {args.stage.name} --res {args.res} --technique {args.technique}: median of "
          f"{args.repeats} (load {load_before[0]:.2f} -> {load_after[0]:.2f})")
    for label, tree_report in report["trees"].items():
        m = tree_report["median"]
        print(f"\n{label} ({tree_report['path']})\n  whole {m['whole']:.3f} s   renderSeconds {m['render']:.3f} s   "
              f"whole - renderSeconds {m['outside']:.3f} s   warpsky --help {tree_report['help_median']:.3f} s")
        print("  phases of one run (in process):")
        order = ["import warpsky.cli.main", *(label for _, _, label in PHASES), "whole (in process)",
                 "CPU: the whole process", "CPU: the technique's render (all threads)", "CPU: outside the technique"]
        for name in order:
            if name in tree_report["phases"]:
                print(f"    {tree_report['phases'][name]:7.3f} s  {name}")
        print("  largest imports of one run (python -X importtime, cumulative):")
        for seconds, name in tree_report["imports"]:
            print(f"    {seconds:7.3f} s  {name}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
