"""The ``warpsky`` command: render USD stages to EXR frames, and show what a stage holds and how it will render.

Exit codes: 0 success, 2 bad input or usage (the message names the culprit), 1 internal error, 130 interrupted
(Ctrl-C).
"""

from __future__ import annotations

import argparse
import gc
import sys
import textwrap
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from warpsky.batch.frames import FramePattern, parse_frame_spec
from warpsky.cli.options import (
    add_quiet,
    add_render_options,
    explicit_options,
    join_dash_values,
    options_from_args,
    resolution_arg,
    with_res_scale,
)
from warpsky.cli.prepare import add_parser as add_prepare
from warpsky.cli.simulate import add_parser as add_simulate
from warpsky.cli.weather import add_parser as add_import_weather
from warpsky.core.errors import UsageError, WarpskyError
from warpsky.core.interrupt import Interrupted, exit_at_once, report_interrupt, sigint_stops_renders
from warpsky.core.version import __version__
from warpsky.optics.cli import add_parser as add_optics
from warpsky.optics.cli import run as run_optics
from warpsky.output.deep_bins import DEEP_SAMPLES, MAX_DEEP_SAMPLES
from warpsky.output.png import DEFAULT_VIEW, DISPLAY, check_view
from warpsky.render.registry import DEFAULT_TECHNIQUE, pass_classes, technique_classes

# Warp, pxr, OpenEXR and the renderer load in the commands that use them (inside the functions below), so that
# ``warpsky --help`` and the argument checks load none of them.
if TYPE_CHECKING:
    from warpsky.batch.run import FrameJob

EPILOG_RENDER = """\
frames: --frames 1 | 1:48 | 1:48x2 | 1.5:3x0.5 | 1,5,9:12 (usdrecord's grammar);
  without it, the stage's frames when OUT has a #### placeholder (a run of # is
  the zero-padded frame number), else one frame at the earliest time sample.

examples:
  warpsky render usd_scenes/cumulus.usda out/cumulus.####.exr --frames 1 --png
  warpsky render shot.usda out/shot.####.exr --frames 1:48x2 --res 1280x720
  warpsky render usd_scenes/cumulus.usda out/c.####.exr --time-budget 60
  warpsky render usd_scenes/storm.usda out/storm.####.exr --workers 2

RenderProducts, batches, farms and limits: docs/guide/ in the source tree.
Settings of a technique or pass: warpsky render --help-settings NAME (or all)
"""

SETTINGS_HEADER = ("settings (--set NAME=VALUE, repeatable; 'auto' restores a default; whole numbers for counts, "
                   "0/1 or\ntrue/false for switches; a pass's settings carry its prefix):\n")


def settings_sections() -> dict[str, list[str]]:
    """Each technique's settings (the default technique first) and then each pass's, name -> the table generated
    from the settings class's field metadata and its notes."""
    from warpsky.core.settings import settings_table

    sections: dict[str, list[str]] = {}
    for cls in technique_classes():
        title = f"{cls.name} (default)" if cls.name == DEFAULT_TECHNIQUE else cls.name
        sections[cls.name] = [f"  {title}:\n" + settings_table(cls.Settings, indent=4)]
        if cls.settings_notes:
            sections[cls.name].append(textwrap.fill(cls.settings_notes, 114, initial_indent="    ",
                                                    subsequent_indent="    "))
    for cls in pass_classes():
        if cls.Settings is not None:
            sections[cls.name] = [f"  {cls.name} pass (prefix {cls.Settings.prefix}; it runs where the stage has "
                                  f"what it draws):\n" + settings_table(cls.Settings, indent=4)]
    return sections


def settings_help(name: str = "all") -> str:
    """The settings of technique or pass ``name``, or of every one (``all``)."""
    sections = settings_sections()
    chosen = [piece for key, pieces in sections.items() if name in ("all", key) for piece in pieces]
    return SETTINGS_HEADER + "\n".join(chosen) + "\n"


class HelpSettings(argparse.Action):
    """``--help-settings NAME``: print the settings of technique or pass NAME (``all``: every one) and exit; an
    unknown NAME exits 2 with one line listing the valid names."""

    def __call__(self, parser, namespace, values, option_string=None):
        valid = [*settings_sections(), "all"]
        if values not in valid:
            parser.exit(2, f"warpsky: error: {option_string}: unknown technique or pass {values!r}; valid: "
                        f"{', '.join(valid)}\n")
        print(settings_help(values), end="")
        parser.exit(0)


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: the reason first, then where --help explains it (not a usage block)."""

    def error(self, message: str):
        self.exit(2, f"warpsky: error: {message} (see '{self.prog} --help')\n")


def add_output_files(render) -> None:
    """The render options for what is written beside each EXR and in what precision."""
    render.add_argument("--png", action="store_true", help="also write a tone-mapped PNG preview per frame")
    render.add_argument("--exposure", type=float, default=None, metavar="EV",
                        help="preview exposure in stops over a white surface facing the sun mapped to 1 "
                        "(default: from the frame)")
    render.add_argument("--view", default=DEFAULT_VIEW, metavar="VIEW",
                        help=f"the preview's OpenColorIO view (default {DEFAULT_VIEW!r}; or 'simple')")
    render.add_argument("--float", dest="full_float", action="store_true", help="write RGBA as 32-bit float "
                        "instead of half")
    render.add_argument("--deep", action="store_true", help="also write NAME.deep.exr, a deep image of the "
                        "frame")
    render.add_argument("--deep-samples", type=int, default=None, metavar="N",
                        help=f"deep samples per pixel per volume (1..{MAX_DEEP_SAMPLES}, default {DEEP_SAMPLES})")


def build_parser(bench=None) -> argparse.ArgumentParser:
    """The command line; ``bench`` is the module of the ``bench`` commands, else a placeholder lists it."""
    parser = Parser(
        prog="warpsky",
        description="Render clouds, rain, ice, sky and fog from USD stages to EXR frames with NVIDIA Warp, "
        "on a CUDA GPU or the CPU.",
    )
    parser.add_argument("--version", action="version", version=f"warpsky {__version__}")
    parser.add_argument("--verbose", action="store_true", help="show Warp's own log (compiles, devices)")
    add_quiet(parser, command=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)

    render = sub.add_parser(
        "render", help="render a stage to EXR frames", usage="%(prog)s STAGE [OUT] [options]",
        description="Render STAGE to OUT (or to the stage's RenderProducts), one EXR per frame\n"
        "(RGBA, transmittance.RGB, depth.Z); no partial EXR is ever left behind.",
        epilog=EPILOG_RENDER, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    render.add_argument("--help-settings", action=HelpSettings, metavar="NAME",
                        help="print the settings of technique or pass NAME and exit")
    render.add_argument("stage", type=Path, help="USD stage (.usda, .usdc, .usd, .usdz)")
    render.add_argument("output", nargs="?", help="output EXR path, with a #### placeholder for several frames "
                        "(default: each RenderProduct's productName)")
    render.add_argument("--frames", metavar="SPEC", help="frames to render (usdrecord grammar, see below)")
    add_render_options(render)
    add_output_files(render)
    render.add_argument("--overwrite", action="store_true", help="render frames whose EXR is already up to date")
    render.add_argument("--retries", type=int, default=1, metavar="N",
                        help="retry a failed frame N times (default 1; input errors are not retried)")
    render.add_argument("--workers", type=int, metavar="N", help="render on a Dask LocalCluster of N processes")
    render.add_argument("--scheduler", metavar="ADDRESS", help="render on an existing Dask cluster "
                        "(tcp://HOST:PORT)")
    render.add_argument("--scheduler-timeout", type=float, default=10.0, metavar="S",
                        help="seconds to wait for --scheduler (default 10)")
    render.add_argument("--log", type=Path, metavar="PATH", help="JSON log of the runs (default: next to OUT, "
                        "out/name.####.exr -> out/name.log.json)")

    info = sub.add_parser("info", help="print what a stage holds and how it would render",
                          description="Print the stage's units, time range, cameras, sun, media and ground, "
                          "and the render plan (technique, settings, device, resolution, features).")
    info.add_argument("stage", type=Path, help="USD stage")
    info.add_argument("--time", type=float, default=None, help="time code to inspect (default: earliest)")
    add_render_options(info)

    preview = sub.add_parser(
        "preview", help="draw a stage in 3-D (volumes, camera frustum, sun, ground, layers) to a PNG",
        description="Draw the stage at one time code with pyvista, offscreen (EGL, no X server): density "
        "isosurfaces of every volume (per species colour), the camera frustum, an arrow towards the sun, the ground "
        "plane and stratiform layer extents. Needs the preview extra: pip install 'warpsky[preview]'.")
    preview.add_argument("stage", type=Path, help="USD stage")
    preview.add_argument("-o", "--output", type=Path, default=Path("preview.png"), help="PNG to write")
    preview.add_argument("--frame", type=float, default=None, help="time code (default: earliest)")
    preview.add_argument("--camera", metavar="PATH", help="camera prim path")
    preview.add_argument("--size", type=resolution_arg, default=(1024, 768), metavar="WxH", help="image size")
    preview.add_argument("--level", type=float, default=0.2,
                         help="isosurface at this fraction of each field's maximum (default 0.2)")

    sheet = sub.add_parser(
        "contact-sheet", help="tile rendered EXR frames into one PNG with frame numbers",
        description="Tone-map every EXR matching PATTERN (a #### placeholder) with one exposure and tile them in "
        "frame order, numbered; unreadable frames show as red tiles.")
    sheet.add_argument("pattern", help="frames, e.g. out/storm.####.exr")
    sheet.add_argument("-o", "--output", type=Path, default=Path("contact_sheet.png"), help="PNG to write")
    sheet.add_argument("--columns", type=int, default=None, help="tiles per row (default: about 1.5:1 overall)")
    sheet.add_argument("--tile-width", type=int, default=256, help="tile width in pixels (default 256)")
    sheet.add_argument("--exposure", type=float, default=None,
                       help="linear exposure (default: the first frame's preview exposure, else its own automatic "
                       "one)")
    sheet.add_argument("--view", default=DEFAULT_VIEW, metavar="VIEW",
                       help=f"the tiles' view of OpenColorIO's {DISPLAY!r} (default {DEFAULT_VIEW!r}, or 'simple')")

    for add_command in (add_prepare, add_optics, add_import_weather, add_simulate):
        add_command(sub)

    if bench is None:
        sub.add_parser("bench", add_help=False, help="measure techniques: error against a path-traced reference vs "
                       "time, speed (from a source checkout: its evaluation/ folder)")
    else:
        bench.add_parser(sub, resolution_arg)
    return parser


def bench_commands():
    """The ``bench`` commands: the source checkout's ``evaluation`` package beside ``warpsky/``, which is not part of
    the installed package and is imported only when ``warpsky bench`` runs."""
    import importlib

    checkout = Path(__file__).resolve().parents[2]
    if not (checkout / "evaluation" / "cli.py").is_file():
        raise UsageError(f"warpsky bench runs from a source checkout of warpsky: no evaluation/cli.py in {checkout}")
    if str(checkout) not in sys.path:
        sys.path.insert(0, str(checkout))
    return importlib.import_module("evaluation.cli")


def shots(args) -> tuple[object, list[tuple[str, object]]]:
    """(the reader, [(output pattern, options)]): one shot per RenderProduct of the stage's render settings, or
    the command line's OUT with the settings' camera and resolution when there are no products."""
    from warpsky.api import open_stage, with_product

    reader, spec, options = open_stage(args.stage, options_from_args(args), args.settings_prim,
                                       explicit=explicit_options(args))
    for note in spec.notes if spec else ():
        print(f"warpsky: note: {note}", file=sys.stderr)
    products = list(spec.products) if spec else []
    if args.products:
        known = {p.path: p for p in products}
        missing = [p for p in args.products if p not in known]
        if missing:
            raise UsageError(f"--product {missing[0]}: not a product of "
                             f"{spec.path if spec else 'the stage (it has no RenderSettings)'}; known: "
                             f"{', '.join(known) or 'none'}")
        products = [known[p] for p in args.products]
    if not products:
        if args.output is None:
            raise UsageError(f"OUT is required: {'render settings ' + spec.path if spec else 'the stage'} has no "
                             "RenderProduct to name the output")
        return reader, [(args.output, with_res_scale(options, args.res_scale))]
    if args.output is not None and len(products) > 1:
        raise UsageError(f"OUT {args.output!r} names one file but {len(products)} products are rendered "
                         f"({', '.join(p.path for p in products)}); leave OUT out to write each product's "
                         "productName, or pick one with --product")
    return reader, [(args.output or product.name,
                     with_res_scale(with_product(options, product, explicit=explicit_options(args)), args.res_scale))
                    for product in products]


def frame_list(reader, pattern, spec: str | None) -> list[float | None]:
    """Time codes to render, by the rules in ``warpsky render --help``."""
    if spec is not None:
        times = parse_frame_spec(spec)
        pattern.require_placeholder(len(times))
        return times
    if not pattern.has_placeholder:
        return [None]
    span = reader.time_range()
    if not span.authored or span.end < span.start:
        return [span.start]
    count = int(span.end - span.start) + 1
    return [span.start + i for i in range(count)]


def _same_render(planned: list) -> list[list]:
    """``planned`` (pattern, options) shots grouped by what their pixels depend on: shots that differ only in
    their channels (outputs) and data window are written from one render."""
    from warpsky.output.products import FULL_WINDOW

    groups: list[tuple[object, list]] = []
    for shot in planned:
        window = shot[1].data_window
        inside = min(window[:2]) >= 0.0 and max(window[2:]) <= 1.0  # no overscan: one render serves any window
        key = replace(shot[1], outputs=None, data_window=FULL_WINDOW if inside else window)
        for group_key, members in groups:
            if group_key == key:
                members.append(shot)
                break
        else:
            groups.append((key, [shot]))
    return [members for _, members in groups]


def _shot_jobs(args, reader, pattern_text: str, options) -> tuple[FramePattern, list[FrameJob]]:
    from warpsky.batch.run import FrameJob

    pattern = FramePattern(pattern_text)
    times = frame_list(reader, pattern, args.frames)
    span = reader.time_range()
    outside = [t for t in times if t is not None and span.authored and not span.start <= t <= span.end]
    if outside:
        print(f"warpsky: warning: frame(s) {', '.join(f'{t:g}' for t in outside[:8])}"
              f"{' ...' if len(outside) > 8 else ''} lie outside the stage's time range {span.start:g}..{span.end:g}; "
              "rendering them anyway (time samples hold their end values)", file=sys.stderr)
    outputs = [pattern.path_for(t) if t is not None and pattern.has_placeholder else Path(pattern_text)
               for t in times]
    return pattern, [FrameJob(str(args.stage), t, str(out), options, args.overwrite)
                     for t, out in zip(times, outputs, strict=True)]


def cmd_render(args) -> int:
    from warpsky.batch.run import check_writable, plan_first_frame, remove_empty, share_reader

    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    if args.retries < 0:
        raise UsageError(f"--retries must be >= 0, got {args.retries}")
    reader, planned = shots(args)
    batches = []
    for group in _same_render(planned):  # products that differ only in their vars and window: one render
        pattern, jobs = _shot_jobs(args, reader, *group[0])
        siblings = [_shot_jobs(args, reader, *shot)[1] for shot in group[1:]]
        jobs = [replace(job, siblings=tuple((other.out, other.options) for other in others))
                for job, *others in zip(jobs, *siblings, strict=True)]
        batches.append((pattern, jobs))
    far = bool(args.scheduler or args.workers)
    composed = batches[0][1][0].options.stage  # None: the reader's defaults
    if not far and composed in (None, reader.options):
        share_reader(str(args.stage), composed, reader)  # the stage is opened once
    for _, jobs in batches:  # input errors of any product: nothing written
        plan_first_frame(jobs[0], keep_reader=not far)
    created: list[Path] = []
    try:
        for directory in dict.fromkeys(Path(job.out).parent for _, jobs in batches for job in jobs):
            check_writable(directory, created)
        start_up_done()
        return _run_batches(args, batches, far)
    finally:  # an interrupted or failed run leaves no empty directory it made
        remove_empty(created)


def _run_batches(args, batches, far: bool) -> int:
    """Run each shot's frames (their directories made), print the summaries; the command's exit code."""
    from warpsky.batch.run import DaskExecutor, InProcessExecutor, format_summary, log_path_for, run_batch

    if args.scheduler:
        executor = DaskExecutor(address=args.scheduler, timeout=args.scheduler_timeout)
    elif args.workers:
        executor = DaskExecutor(workers=args.workers)
    else:
        executor = InProcessExecutor()
    results = []
    try:
        for pattern, jobs in batches:
            log = args.log if args.log and len(batches) == 1 else log_path_for(pattern.pattern)
            results.append(run_batch(str(args.stage), jobs, executor, retries=args.retries, log=log))
    finally:
        executor.close()
    for (_, jobs), result in zip(batches, results, strict=True):
        if len(jobs) > 1 or len(batches) > 1 or result.failed or executor.name != "in-process":
            print(format_summary(result), file=sys.stderr)
    failed = [r for result in results for r in result.failed]
    if failed:  # each failure was already reported as it happened
        return 1 if any(r.retryable for r in failed) else 2
    return 0


def cmd_preview(args) -> int:
    from warpsky.output.preview import stage_preview
    from warpsky.usd.stage import StageReader

    scene = StageReader(args.stage).scene_at(args.frame, camera_path=args.camera)
    print(stage_preview(scene, args.output, size=(args.size[0], args.size[1] or round(args.size[0] * 0.75)),
                        level=args.level))
    return 0


def cmd_contact_sheet(args) -> int:
    from warpsky.output.preview import contact_sheet

    print(contact_sheet(args.pattern, args.output, columns=args.columns, tile_width=args.tile_width,
                        exposure=args.exposure, view=check_view(args.view)))
    return 0


#: Allocations between two collections of the youngest generation in the ``warpsky`` program (Python's default: 700).
GC_ALLOCATIONS = 50_000


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (None: the program's own arguments) and return its exit code; the program itself
    exits at once when done (:func:`~warpsky.core.interrupt.exit_at_once`: unloading USD, Warp and numpy would add
    about 0.3 s after the work). The program collects no cyclic garbage while it starts: its start-up makes a few
    hundred thousand long-lived objects (Warp's builtins, USD, the kernels' code), which Python's default threshold
    had collected about 370 times (0.1 s of a small frame's command) and one of :data:`GC_ALLOCATIONS` 4 times
    (0.03-0.05 s); once the frames start (:func:`start_up_done`) it collects every GC_ALLOCATIONS allocations."""
    if argv is None:
        gc.set_threshold(GC_ALLOCATIONS, *gc.get_threshold()[1:])
        gc.disable()
    code = _run(argv)
    if argv is None:
        exit_at_once(code)
    return code


def start_up_done() -> None:
    """Collect cyclic garbage from here on where :func:`main` held it off, start-up's objects frozen out of every
    collection (they live until the program exits)."""
    if not gc.isenabled():
        gc.freeze()
        gc.enable()


def _run(argv: list[str] | None) -> int:
    given = sys.argv[1:] if argv is None else [str(a) for a in argv]
    bench = None
    if next((a for a in given if not a.startswith("-")), None) == "bench":
        try:
            bench = bench_commands()
        except WarpskyError as exc:
            print(f"warpsky: error: {exc}", file=sys.stderr)
            return exc.exit_code
    parser = build_parser(bench)
    args = parser.parse_args(join_dash_values(given))
    if args.command is None:
        parser.print_help()
        return 2
    try:
        from warpsky.cli.info import cmd_info
        from warpsky.cli.prepare import cmd_prepare
        from warpsky.cli.simulate import cmd_simulate
        from warpsky.cli.weather import cmd_import_weather
        from warpsky.core.device import init_warp
        from warpsky.core.progress import quieted
        from warpsky.render.compile_progress import install as announce_compiles

        init_warp(verbose=args.verbose)
        announce_compiles()
        if args.command == "optics":
            with quieted(args.quiet):
                return run_optics(args)
        commands = {"render": cmd_render, "info": cmd_info, "bench": bench.run if bench else None,
                    "preview": cmd_preview, "contact-sheet": cmd_contact_sheet, "prepare": cmd_prepare,
                    "import-weather": cmd_import_weather, "simulate": cmd_simulate}
        if args.command != "render":
            start_up_done()
        with sigint_stops_renders(), quieted(args.quiet):
            return commands[args.command](args)
    except WarpskyError as exc:
        print(f"warpsky: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except (KeyboardInterrupt, Interrupted):
        return report_interrupt(exit_now=argv is None)  # the program itself, not a caller in Python: exit at once
    except Exception:  # noqa: BLE001 - anything else is our bug: show it, exit 1
        import traceback

        traceback.print_exc()
        print("warpsky: internal error (please report it with the traceback above)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
