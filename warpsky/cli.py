"""The ``warpsky`` command: render USD stages to EXR frames, and show what a stage holds and how it will render.

Exit codes: 0 success, 2 bad input or usage (the message names the culprit), 1 internal error, 130 interrupted
(Ctrl-C).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import warpsky
from warpsky.api import open_stage, render_options, with_product
from warpsky.batch.frames import FramePattern, parse_frame_spec
from warpsky.batch.run import (
    DaskExecutor,
    FrameJob,
    InProcessExecutor,
    check_writable,
    format_summary,
    log_path_for,
    plan_first_frame,
    run_batch,
)
from warpsky.device import init_warp
from warpsky.errors import UsageError, WarpskyError
from warpsky.evaluation.cli import add_parser as add_bench
from warpsky.evaluation.cli import run as run_bench
from warpsky.interrupt import Interrupted, report_interrupt, sigint_stops_renders
from warpsky.optics.cli import add_parser as add_optics
from warpsky.optics.cli import run as run_optics
from warpsky.output.color import COLORSPACES
from warpsky.output.preview import contact_sheet, stage_preview
from warpsky.output.products import FULL_WINDOW
from warpsky.passes.stratiform.stratiform import StratiformSettings
from warpsky.render import plan_frame
from warpsky.resources import parse_size, resource_lines
from warpsky.scene.usd import StageReader
from warpsky.settings import settings_table
from warpsky.techniques.base import DEFAULT_TECHNIQUE, technique_class, technique_names

EPILOG_RENDER = """\
frames:
  --frames takes usdrecord's grammar: 1 | 1:48 | 1:48x2 | 1.5:3x0.5 | 1,5,9:12
  Without --frames: the stage's startTimeCode..endTimeCode when OUT has a #### placeholder,
  else one frame at the earliest time sample.
  OUT placeholders follow usdrecord: a run of # is the zero-padded frame number (####  -> 0012),
  ###.## adds decimals for subframes (-> 012.50).

USD render settings and products:
  A UsdRenderSettings prim (--settings PATH, else the stage's renderSettingsPrimPath, else the first one) gives
  the camera, resolution, pixelAspectRatio, dataWindowNDC, includedPurposes and renderingColorSpace; each of its
  UsdRenderProducts (all, or those named by --product) is written to its productName ($F4, $F or #### for the
  frame) with the channels its orderedVars name (sourceName color, alpha, transmittance, depth, variance,
  single_scatter, multiple_scatter). OUT replaces the name of a single product; --camera, --res, --purpose and
  --colorspace win over the stage. Without RenderProducts, OUT is required and gets warpsky's default channels.

batches, resume and farms:
  A frame whose EXR exists, opens, has every channel and carries the same settings hash is skipped (--overwrite
  renders it again). Failed frames are retried (--retries, default 1) unless the input is at fault, and never cost
  finished ones; every run is appended to OUT's log (out/storm.####.exr -> out/storm.log.json) and summarised.
  --workers N starts a Dask LocalCluster of N single-threaded worker processes on this machine; --scheduler
  tcp://HOST:PORT uses an existing Dask cluster: its workers open the stage and the optics cache themselves
  (put stage, data, $WARPSKY_CACHE and OUT on shared storage) and return paths, never pixels. Pixels are
  identical whatever the executor. GPU farms: start one worker per GPU with dask-cuda
  (`dask cuda worker tcp://HOST:PORT`, or LocalCUDACluster in Python), which sets CUDA_VISIBLE_DEVICES per
  worker, and render with --device cuda.

memory, work and Ctrl-C:
  A frame estimated above the free memory (--max-memory SIZE) or above 1e8 kernel iterations per pixel or 1e13 per
  frame (--no-work-limit) is refused with exit code 2 before anything is allocated; `warpsky info` prints the
  estimates. Ctrl-C stops a render within about a second, writes no EXR and exits with 130.

{settings}
examples:
  warpsky render usd_scenes/cumulus.usda out/cumulus.####.exr --frames 1 --png
  warpsky render shot.usda out/shot.####.exr --frames 1:48x2 --res 1280x720 --device cuda
  warpsky render usd_scenes/cumulus.usda out/fine.####.exr --frames 1 --target-error 0.02 --time-budget 60
  warpsky render usd_scenes/cumulus.usda out/fast.####.exr --frames 1 --technique slicing
  warpsky render usd_scenes/cumulus.usda out/ref.####.exr --frames 1 --technique path_tracer --spp 256 --seed 7
  warpsky render shot.usda --frames 1:48 --variant weather=storm --load all
  warpsky render shot.usda out/beauty.####.exr --product /Render/Beauty --colorspace ACEScg
  warpsky render usd_scenes/storm.usda out/storm.####.exr --res 256 --workers 2
  warpsky render usd_scenes/storm.usda /shared/storm.####.exr --scheduler tcp://farm:8786
"""


#: What the settings tables leave out: the shorthands of the command line and what a technique adds to the EXR.
SETTINGS_NOTES = {
    "hybrid": "--target-error E, --time-budget S, --spp N and --seed S are shorthands for --set target_error=E / "
              "time_budget=S / spp=N / seed=S. Writes single_scatter.RGB, multiple_scatter.RGB and variance.RGB AOVs; "
              "the header holds errorEstimate, spp, passes, stoppedBy, targetError, paths and cappedPaths (a warning "
              "above 0.1%).",
    "path_tracer": "--spp N and --seed S are shorthands for --set spp=N / seed=S. Writes a variance.RGB AOV "
                   "(variance of each pixel's mean); the header holds spp, paths and cappedPaths (a warning above "
                   "0.1%).",
}


def settings_help() -> str:
    """Every technique's settings (the default technique first, then the stratiform pass's, then the others) as
    tables generated from the settings classes' field metadata."""
    names = [DEFAULT_TECHNIQUE] + [n for n in technique_names() if n != DEFAULT_TECHNIQUE]
    sections = []
    for name in names:
        cls = technique_class(name)
        title = f"{name} (default)" if name == DEFAULT_TECHNIQUE else name
        sections.append(f"  {title}:\n" + settings_table(cls.Settings, indent=4))
        if name in SETTINGS_NOTES:
            sections.append(textwrap.fill(SETTINGS_NOTES[name], 114, initial_indent="    ", subsequent_indent="    "))
        if name == DEFAULT_TECHNIQUE:
            sections.append("  stratiform layers (prefix stratiform., also with slicing and single_scatter):\n"
                            + settings_table(StratiformSettings, indent=4))
    sections.append("  terrain scenery passes (any technique but path_tracer):\n"
                    "    heightfield.mode            exact | max | sexp (default exact): the sunlight reaching a point "
                    "of the deck or the haze\n"
                    "                                by the exact sun-ray optical depth, Max's thickness rule, or "
                    "Max's sexp\n"
                    "    heightfield.step_length, heightfield.haze_step_length [m], heightfield.max_steps, "
                    "heightfield.min_transmittance\n"
                    "    fog.nodes (4), fog.min_pieces (4), fog.max_pieces (64): Gauss-Legendre nodes and pieces of "
                    "the fog's sunlight integral\n"
                    "    fog.cut_depth (40): optical depth after which the rest of a ray is dropped")
    return ("technique settings (--set NAME=VALUE, repeatable; 'auto' restores a default; whole numbers for\n"
            "counts, 0/1 or true/false for switches):\n" + "\n".join(sections) + "\n")


def _resolution(text: str) -> tuple[int, int | None]:
    try:
        if "x" in text.lower():
            w, h = text.lower().split("x", 1)
            width, height = int(w), int(h)
        else:
            width, height = int(text), None
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT or WIDTH, got {text!r}") from None
    if width <= 0 or (height is not None and height <= 0):
        raise argparse.ArgumentTypeError(f"resolution must be positive, got {text!r}")
    return width, height


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"expected a relative error between 0 and 1 (0.05 = 5%), got {text!r}")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _size(text: str) -> int:
    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _setting(text: str) -> tuple[str, str]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    return key.strip(), value.strip()


def _add_render_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", metavar="PATH", help="camera prim path (default: render settings' camera, "
                        "else the first camera)")
    parser.add_argument("--res", type=_resolution, metavar="WxH",
                        help="image size; WIDTH alone keeps the camera's aspect (default: the stage's "
                        "RenderSettings resolution, else 512 wide)")
    parser.add_argument("--device", default="auto", help="auto (cuda when present), cpu, cuda or cuda:N")
    parser.add_argument("--technique", default=DEFAULT_TECHNIQUE, choices=technique_names(),
                        help=f"rendering technique (default: {DEFAULT_TECHNIQUE})")
    parser.add_argument("--set", dest="settings", type=_setting, action="append", default=[], metavar="NAME=VALUE",
                        help="technique setting, repeatable (see below)")
    parser.add_argument("--spp", type=int, metavar="N", help="path_tracer: samples per pixel; hybrid: most "
                        "multiple-scattering paths per pixel (= --set spp=N)")
    parser.add_argument("--seed", type=int, metavar="S", help="path_tracer, hybrid: random seed (= --set seed=S)")
    parser.add_argument("--target-error", type=_fraction, metavar="E",
                        help="hybrid: add paths until the frame's estimated relative RMSE is below E, in (0, 1) "
                        "(= --set target_error=E; default 0.05)")
    parser.add_argument("--time-budget", type=_seconds, metavar="S",
                        help="hybrid: stop adding paths after S seconds per frame (= --set time_budget=S)")
    parser.add_argument("--max-memory", type=_size, metavar="SIZE", help="most memory a frame may use on the "
                        "host and on a GPU each, e.g. 8G or 512M (default: what is free)")
    parser.add_argument("--no-work-limit", dest="work_limit", action="store_false", help="render frames whose "
                        "worst-case work exceeds 1e8 kernel iterations per pixel or 1e13 per frame")
    usd = parser.add_argument_group("USD pipeline")
    usd.add_argument("--settings", dest="settings_prim", metavar="PATH", help="UsdRenderSettings prim (default: "
                     "the stage's renderSettingsPrimPath, else the first RenderSettings prim)")
    usd.add_argument("--product", dest="products", action="append", metavar="PATH", help="render only this "
                     "RenderProduct of the settings (repeatable; default: all of them)")
    usd.add_argument("--load", choices=("all", "none"), default="all", help="load payloads (all, the default) or "
                     "leave them unloaded (none), as usdview's --unloaded")
    usd.add_argument("--variant", dest="variants", action="append", default=[], metavar="SET=SELECTION",
                     help="variant selection applied on the session layer (repeatable)")
    usd.add_argument("--purpose", dest="purposes", action="append", metavar="PURPOSE", help="render prims of "
                     "this purpose (repeatable: render, proxy, guide; prims of purpose default always render; "
                     "default: the settings' includedPurposes, else default and render)")
    usd.add_argument("--colorspace", choices=tuple(COLORSPACES), default=None, help="primaries of the EXR's "
                     "colours: lin_rec709 (default; sRGB primaries, D65) or ACEScg (AP1); written into the "
                     "header's chromaticities (default: the settings' renderingColorSpace, else lin_rec709)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="warpsky",
        description="Render clouds, rain, ice, sky and fog from USD stages to EXR frames with NVIDIA Warp, "
        "on a CUDA GPU or the CPU.",
    )
    parser.add_argument("--version", action="version", version=f"warpsky {warpsky.__version__}")
    parser.add_argument("--verbose", action="store_true", help="show Warp's own log (compiles, devices)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    render = sub.add_parser(
        "render", help="render a stage to EXR frames", description="Render STAGE to OUT (or to its "
        "RenderProducts), one EXR per frame (RGBA radiance + transmittance.RGB + depth.Z, or the products' vars; "
        "metadata in the header). Files are written to a temporary "
        "name and renamed, so no partial EXR is ever left behind.",
        epilog=EPILOG_RENDER.format(settings=settings_help()), formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    render.add_argument("stage", type=Path, help="USD stage (.usda, .usdc, .usd, .usdz)")
    render.add_argument("output", nargs="?", help="output EXR path, with a #### placeholder for several frames "
                        "(default: each RenderProduct's productName)")
    render.add_argument("--frames", metavar="SPEC", help="frames to render (usdrecord grammar, see below)")
    _add_render_options(render)
    render.add_argument("--png", action="store_true", help="also write a tone-mapped PNG preview per frame")
    render.add_argument("--exposure", type=float, default=0.0, metavar="EV",
                        help="preview exposure in stops (default 0: a white surface facing the sun maps to ~0.63)")
    render.add_argument("--float", dest="full_float", action="store_true", help="write RGBA as 32-bit float "
                        "instead of half")
    render.add_argument("--overwrite", action="store_true", help="render frames whose EXR is already up to date")
    render.add_argument("--retries", type=int, default=1, metavar="N",
                        help="retry a failed frame N times (default 1; input errors are not retried)")
    render.add_argument("--workers", type=int, metavar="N", help="render on a Dask LocalCluster of N processes")
    render.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="render on an existing Dask cluster")
    render.add_argument("--scheduler-timeout", type=float, default=10.0, metavar="S",
                        help="seconds to wait for --scheduler before giving up (default 10)")
    render.add_argument("--log", type=Path, metavar="PATH", help="JSON log of the runs (default: next to OUT, "
                        "out/name.####.exr -> out/name.log.json)")

    info = sub.add_parser("info", help="print what a stage holds and how it would render",
                          description="Print the stage's units, time range, cameras, sun, media and ground, "
                          "and the render plan (technique, settings, device, resolution, features).")
    info.add_argument("stage", type=Path, help="USD stage")
    info.add_argument("--time", type=float, default=None, help="time code to inspect (default: earliest)")
    _add_render_options(info)

    preview = sub.add_parser(
        "preview", help="draw a stage in 3-D (volumes, camera frustum, sun, ground, layers) to a PNG",
        description="Draw the stage at one time code with pyvista, offscreen (EGL, no X server): density "
        "isosurfaces of every volume (per species colour), the camera frustum, an arrow towards the sun, the ground "
        "plane and stratiform layer extents. Needs the preview extra: pip install 'warpsky[preview]'.")
    preview.add_argument("stage", type=Path, help="USD stage")
    preview.add_argument("-o", "--output", type=Path, default=Path("preview.png"), help="PNG to write")
    preview.add_argument("--frame", type=float, default=None, help="time code (default: earliest)")
    preview.add_argument("--camera", metavar="PATH", help="camera prim path")
    preview.add_argument("--size", type=_resolution, default=(1024, 768), metavar="WxH", help="image size")
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
                       help="linear exposure (default: the frames' preview exposure, else their 99th percentile)")

    add_optics(sub)

    add_bench(sub, _resolution)
    return parser


def _settings(args) -> dict[str, str]:
    """--set pairs plus the --spp / --seed / --target-error / --time-budget shorthands."""
    settings = dict(args.settings)
    for name in ("spp", "seed", "target_error", "time_budget"):
        value = getattr(args, name, None)
        if value is None:
            continue
        if name in ("target_error", "time_budget") and args.technique != "hybrid":
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag} applies to technique hybrid only (this render uses {args.technique})")
        settings[name] = repr(value) if isinstance(value, float) else str(value)
    return settings


def _render_options(args) -> object:
    """The render's options as the Python API builds them (:func:`warpsky.api.render_options`)."""
    return render_options(
        technique=args.technique,
        settings=_settings(args),
        resolution=args.res,
        device=args.device,
        camera=args.camera,
        colorspace=args.colorspace,
        load=args.load,
        variants=tuple(args.variants),
        purposes=("default", *args.purposes) if args.purposes else None,
        half=not getattr(args, "full_float", False),
        png=getattr(args, "png", False),
        exposure=getattr(args, "exposure", 0.0),
        max_memory=args.max_memory,
        work_limit=args.work_limit,
    )


def _explicit(args) -> set[str]:
    """Options given on the command line, which win over the stage's render settings and products."""
    given = {"camera": args.camera, "resolution": args.res, "purposes": args.purposes, "colorspace": args.colorspace}
    return {name for name, value in given.items() if value}


def shots(args) -> tuple[object, list[tuple[str, object]]]:
    """(the reader, [(output pattern, options)]): one shot per RenderProduct of the stage's render settings, or
    the command line's OUT with the settings' camera and resolution when there are no products."""
    reader, spec, options = open_stage(args.stage, _render_options(args), args.settings_prim,
                                       explicit=_explicit(args))
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
        return reader, [(args.output, options)]
    if args.output is not None and len(products) > 1:
        raise UsageError(f"OUT {args.output!r} names one file but {len(products)} products are rendered "
                         f"({', '.join(p.path for p in products)}); leave OUT out to write each product's "
                         "productName, or pick one with --product")
    return reader, [(args.output or product.name, with_product(options, product, explicit=_explicit(args)))
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
    groups: list[tuple[object, list]] = []
    for shot in planned:
        key = replace(shot[1], outputs=None, data_window=FULL_WINDOW)
        for group_key, members in groups:
            if group_key == key:
                members.append(shot)
                break
        else:
            groups.append((key, [shot]))
    return [members for _, members in groups]


def _shot_jobs(args, reader, pattern_text: str, options) -> tuple[FramePattern, list[FrameJob]]:
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
    for _, jobs in batches:  # input errors of any product: nothing written
        plan_first_frame(jobs[0], keep_reader=not far)
    for directory in dict.fromkeys(Path(job.out).parent for _, jobs in batches for job in jobs):
        check_writable(directory)
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


def _fmt3(values) -> str:
    """RGB triples as short numbers; one number when all three agree."""
    values = [float(v) for v in values]
    if max(values) == min(values):
        return f"{values[0]:.6g}"
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


def cmd_preview(args) -> int:
    scene = StageReader(args.stage).scene_at(args.frame, camera_path=args.camera)
    print(stage_preview(scene, args.output, size=(args.size[0], args.size[1] or round(args.size[0] * 0.75)),
                        level=args.level))
    return 0


def cmd_contact_sheet(args) -> int:
    print(contact_sheet(args.pattern, args.output, columns=args.columns, tile_width=args.tile_width,
                        exposure=args.exposure))
    return 0


def _light_lines(scene) -> list[str]:
    """``warpsky info``'s lines on the lights: each DistantLight's irradiance (intensity x 2^exposure x colour) and
    what reaches a horizontal surface above the horizon (the visible part of the disk, at its elevation); the
    dome's mean radiance and its irradiance on a horizontal surface."""
    import numpy as np

    from warpsky.light.dome import mean_radiance, upper_hemisphere
    from warpsky.light.sun import has_horizon, sun_sunlight

    lines = []
    for sun in [s for s in [scene.sun, *scene.extra_suns] if s is not None]:
        light = sun_sunlight(sun, horizon=has_horizon(scene))
        flat = light.irradiance * max(float(light.direction[1]), 0.0)
        lines.append(f"light       {sun.name}: distant, elevation {np.degrees(sun.elevation):.2f} deg, irradiance "
                     f"{_fmt3(sun.irradiance)} at normal incidence; visible disk {light.visible:.0%}, "
                     f"{_fmt3(flat)} on a horizontal surface (before the air)")
    if scene.dome is not None:
        dome = scene.dome
        kind = f"lat-long {dome.source}" if dome.texture is not None else "uniform"
        _, cosine_mean = upper_hemisphere(dome)
        lines.append(f"light       {dome.name}: dome, {kind}, mean radiance {_fmt3(mean_radiance(dome))}, "
                     f"{_fmt3(np.pi * cosine_mean)} on a horizontal surface")
    return lines or ["light       none: no visible DistantLight or DomeLight"]


def _render_spec_lines(spec, products) -> list[str]:
    """``warpsky info``'s lines on the render settings, their products and each product's vars."""
    if spec is None:
        return ["render      no RenderSettings prim: OUT, --camera and --res decide"]
    res = "x".join(map(str, spec.resolution)) if spec.resolution else "not authored"
    lines = [f"render      {spec.path}: camera {spec.camera or 'not set'}, resolution {res}, pixel aspect "
             f"{spec.pixel_aspect:g}, dataWindowNDC {list(spec.data_window)}"
             + (f", purposes {', '.join(spec.purposes)}" if spec.purposes is not None else "")
             + (f", renderingColorSpace {spec.colorspace}" if spec.colorspace else "")]
    lines += [f"            note: {note}" for note in spec.notes]
    for product in products:
        res = "x".join(map(str, product.resolution)) if product.resolution else "default"
        lines.append(f"product     {product.path} -> {product.name}: camera {product.camera or 'default'}, "
                     f"resolution {res}")
        for var in product.outputs:
            precision = "half" if var.half else "float"
            lines.append(f"  var       {var.prim}: {var.source} -> {', '.join(var.channels)} ({precision})")
    return lines


def cmd_info(args) -> int:
    import numpy as np

    options = _render_options(args)
    reader, spec, options = open_stage(args.stage, options, args.settings_prim, explicit=_explicit(args))
    products = list(spec.products) if spec else []
    if args.products:
        products = [p for p in products if p.path in args.products]
    if products:  # the plan of the first product
        options = with_product(options, products[0], explicit=_explicit(args))
    span = reader.time_range()
    scene, plan = plan_frame(reader, args.time, options, check=False)
    out = [
        f"stage       {reader.path}",
        f"units       upAxis {reader.up_axis}, metersPerUnit {reader.meters_per_unit:g}",
        f"time        {span.start:g} .. {span.end:g} at {span.time_codes_per_second:g} codes/s"
        + ("" if span.authored else " (not authored)"),
        f"cameras     {', '.join(reader.camera_paths()) or 'none'}",
    ]
    cam = scene.camera
    out.append(
        f"camera      {cam.name} ({cam.projection.value}) at {np.round(cam.position, 3).tolist()} m looking "
        f"{np.round(cam.forward, 4).tolist()}, clip {cam.near:g}..{cam.far:g} m"
    )
    for medium in scene.media:
        lo, hi = medium.world_corners().min(axis=0), medium.world_corners().max(axis=0)
        out.append(f"volume      {medium.name}: {medium.source}")
        out.append(
            f"            {medium.shape[0]}x{medium.shape[1]}x{medium.shape[2]} voxels of "
            f"{np.round(medium.voxel_size, 4).tolist()} m, bounds {np.round(lo, 2).tolist()} .. "
            f"{np.round(hi, 2).tolist()} m"
        )
        out.append(
            f"            extinction {_fmt3(medium.extinction_scale)} 1/m per unit, max field "
            f"{float(medium.density.max()):g}, albedo {_fmt3(medium.albedo)}, "
            + (f"{medium.species} phase table" if medium.species else repr(medium.phase))
        )
        if medium.ice is not None and medium.ice.orientation != "random":
            ice = medium.ice
            out.append(f"            oriented ice: {ice.fraction:.3g} of the crystals {ice.habit}s falling as "
                       f"{ice.orientation}s (tilt {ice.tilt_deg:g}°), the rest random columns; a phase table per "
                       "frame at the sun's elevation")
        if medium.detail is not None and medium.detail.amplitude > 0.0:
            d = medium.detail
            out.append(f"            advected detail: amplitude {d.amplitude:g}, scale {d.scale:g} m, wind "
                       f"{np.round(np.asarray(d.wind), 3).tolist()} m/s, curl {d.curl_speed:g} m/s, "
                       f"period {d.period:g} s")
    out += _light_lines(scene)
    out += _render_spec_lines(spec, products)
    out += [f"composition {line}" for line in reader.composition_summary()]
    out.append("plan:" + (f" (of product {products[0].path})" if products else ""))
    out += ["  " + line for line in plan.describe().splitlines()]
    out += ["  " + line for line in resource_lines(plan, options.max_memory)]
    print("\n".join(out))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        init_warp(verbose=args.verbose)
        if args.command == "optics":
            return run_optics(args)
        commands = {"render": cmd_render, "info": cmd_info, "bench": run_bench, "preview": cmd_preview,
                    "contact-sheet": cmd_contact_sheet}
        with sigint_stops_renders():
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
