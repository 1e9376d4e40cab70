"""``warpsky bench``: error against a path-traced reference vs time (one stage or a validation family), and
speed."""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

from evaluation.error_vs_time import format_table, run_report, write_outputs
from evaluation.family import FAMILY_HELP, format_family_table, run_family, write_family_outputs
from evaluation.family_stages import load_family
from evaluation.speed import add_speed_parser, run_speed_command
from warpsky.core.device import resolve_device
from warpsky.core.errors import UsageError
from warpsky.render.plan import resolve_resolution
from warpsky.usd.stage import StageReader


def add_parser(sub, resolution_type) -> None:
    """``warpsky bench error-vs-time`` (one STAGE or a validation family) and ``warpsky bench speed``."""
    bench = sub.add_parser("bench", help="measure techniques: error against a path-traced reference vs time, speed",
                           description="Benchmarks that read a stage.")
    bench_verbs = bench.add_subparsers(dest="bench_command", metavar="VERB", required=True)
    evt = bench_verbs.add_parser(
        "error-vs-time", help="each technique's error against a converged path-traced reference, and its time",
        description=textwrap.fill(
            "Render a converged path-traced reference of STAGE (cached under $WARPSKY_CACHE/reference), then each "
            "technique along its quality ladder (march steps 4..0.25 voxels, spp 1..256), and report relative "
            "RMSE, mean and 95th-percentile relative error over covered pixels, and bias, against the render time "
            "(first compiles excluded). Writes CSV, JSON and a log-log PNG. With --family DIR instead of STAGE: the "
            "same on every stage of a validation family, aggregated (see below).", 112),
        epilog=FAMILY_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    evt.add_argument("stage", type=Path, nargs="?", help="USD stage (or give --family)")
    evt.add_argument("--family", type=Path, metavar="DIR", help="a validation family directory (family.json, "
                     "written by evaluation/scripts/make_validation_family.py or "
                     "evaluation/scripts/make_scenery_family.py) instead of STAGE")
    evt.add_argument("--half", choices=("tune", "test", "all"), default="test",
                     help="--family: which half to measure (default test)")
    evt.add_argument("--references-only", action="store_true",
                     help="--family: only render and cache the references, one line per stage")
    evt.add_argument("--techniques", default="single_scatter,path_tracer",
                     help="comma-separated techniques (default: single_scatter,path_tracer)")
    evt.add_argument("--budget", type=float, default=60.0, metavar="SECONDS",
                     help="seconds for the ladders, shared between techniques (default 60); with --family, per "
                     "stage")
    evt.add_argument("--reference-spp", type=int, default=1024, metavar="N", help="reference samples per pixel")
    evt.add_argument("--time", type=float, default=None, help="time code (default: earliest; STAGE only)")
    evt.add_argument("--camera", metavar="PATH", help="camera prim path (STAGE only)")
    evt.add_argument("--res", type=resolution_type, default=None, metavar="WxH",
                     help="image size (default 128 wide: the camera's aspect for STAGE; for --family the family's "
                     "own, family.json image_size: 128x128 thin, 64x64 thick, 96x64 scenery)")
    evt.add_argument("--device", default="auto", help="auto (cuda when present), cpu, cuda or cuda:N")
    evt.add_argument("--no-cache", action="store_true", help="render the reference even if it is cached")
    evt.add_argument("-o", "--output-dir", type=Path, default=Path("out"), help="where the CSV/JSON/PNG go")
    add_speed_parser(bench_verbs, resolution_type)


def _log_progress(text: str) -> None:
    print(text, file=sys.stderr)


def run(args) -> int:
    if args.bench_command == "speed":
        return run_speed_command(args, log=_log_progress)
    if (args.stage is None) == (args.family is None):
        given = f"both STAGE ({args.stage}) and --family ({args.family})" if args.stage else "neither"
        raise UsageError(f"bench error-vs-time measures exactly one of STAGE or --family DIR; got {given}")
    techniques = [t.strip() for t in args.techniques.split(",") if t.strip()]
    device = resolve_device(args.device)
    log = _log_progress  # progress to stderr, tables to stdout
    if args.family is not None:
        return _bench_family(args, techniques, device, log)
    if args.references_only:
        raise UsageError("--references-only needs --family DIR")
    reader = StageReader(args.stage)
    scene = reader.scene_at(args.time, camera_path=args.camera)
    width, height = resolve_resolution(scene, args.res or (128, None))
    report = run_report(
        scene, techniques=techniques, width=width, height=height, device=device, budget=args.budget,
        reference_spp=args.reference_spp, use_cache=not args.no_cache, log=log,
    )
    print(format_table(report))
    for path in write_outputs(report, args.output_dir):
        print(path)
    return 0


def _bench_family(args, techniques: list[str], device: str, log) -> int:
    """``bench error-vs-time --family DIR``: the family report, or only its references."""
    if args.camera is not None or args.time is not None:
        raise UsageError("--camera and --time apply to a STAGE; a family's stages use their own camera and time")
    size = load_family(args.family).get("image_size", 128)  # the scenery family's is [width, height]
    width, height = args.res or ((int(size[0]), int(size[1])) if isinstance(size, list) else (int(size), int(size)))
    height = height or width
    report = run_family(
        args.family, techniques, width, height, device, half=args.half, reference_spp=args.reference_spp,
        budget_per_stage=args.budget, use_cache=not args.no_cache, references_only=args.references_only, log=log,
    )
    if args.references_only:
        for ref in report.references:
            state = "cached" if ref["cached"] else f"{ref['seconds']:.1f} s"
            print(f"{ref['stage']:<24} {ref['half']:<4} {state:>10}  {ref['key']}")
        return 0
    print(format_family_table(report))
    for path in write_family_outputs(report, args.output_dir):
        print(path)
    return 0
