"""The render options ``warpsky render`` and ``warpsky info`` share: their arguments, the ``--set`` pairs with the
technique shorthands, and the :class:`~warpsky.render.options.RenderOptions` they make."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

from warpsky.core.errors import UsageError, did_you_mean
from warpsky.core.settings import field_kinds
from warpsky.output.color import colorspace_argument
from warpsky.output.deep_bins import DEEP_SAMPLES, check_deep_samples
from warpsky.output.png import DEFAULT_VIEW, check_view
from warpsky.render.motion import DEFAULT_SAMPLES
from warpsky.render.registry import DEFAULT_TECHNIQUE, technique_class, technique_classes, technique_names

#: Command-line shorthands for technique settings: ``--spp N`` is ``--set spp=N``.
SHORTHANDS = ("spp", "seed", "target_error", "time_budget")


def resolution_arg(text: str) -> tuple[int, int | None]:
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


#: Options whose value may begin with a minus that is not a plain number (``--res -96x64``): argparse would take the
#: value for an option and answer "expected one argument" instead of the option's own check.
DASH_VALUE_OPTIONS = ("--res",)


def join_dash_values(argv: list[str]) -> list[str]:
    """``argv`` with ``--res -96x64`` written ``--res=-96x64`` (for each of :data:`DASH_VALUE_OPTIONS`), so that
    the value reaches :func:`resolution_arg` and its one-line message; nothing after a ``--`` changes."""
    out: list[str] = []
    pending = False
    for i, arg in enumerate(argv):
        if arg == "--":
            return out + argv[i:]
        if pending and arg[:1] == "-" and arg[1:2].isdigit():
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
        pending = arg in DASH_VALUE_OPTIONS and out[-1] == arg
    return out


def technique_arg(text: str) -> str:
    """``--technique``: a registered technique's name; a misspelt one is answered with the closest names."""
    if text in technique_names():
        return text
    raise argparse.ArgumentTypeError(f"unknown technique {text!r}; {did_you_mean(text, technique_names())}"
                                     f"available: {', '.join(technique_names())}")


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


def _percent(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < float("inf"):  # NaN fails too
        raise argparse.ArgumentTypeError(f"expected a positive percentage of the resolution (50 = half the width "
                                         f"and height), got {text!r}")
    return value


def with_res_scale(options, percent: float | None):
    """``options`` with their resolution (``--res``, the stage's, else warpsky's default width) scaled by
    ``percent`` (husk's ``--res-scale``: 50 renders half the width and height), each side rounded to the nearest
    pixel and at least 1; a width-only resolution stays width-only (the height follows the camera)."""
    if percent is None or percent == 100.0:
        return options
    from warpsky.render.plan import DEFAULT_WIDTH

    width, height = options.resolution or (DEFAULT_WIDTH, None)

    def scaled(pixels: int) -> int:
        return max(1, int(pixels * percent / 100.0 + 0.5))

    return replace(options, resolution=(scaled(width), None if height is None else scaled(height)))


def _size(text: str) -> int:
    from warpsky.core.resources import parse_size  # loads Warp: only for --max-memory

    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def setting_arg(text: str) -> tuple[str, str]:
    """argparse type of ``--set NAME=VALUE``: the (name, value) pair, both stripped."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    return key.strip(), value.strip()


def shutter_arg(text: str) -> tuple[float, float]:
    """argparse type of ``--shutter OPEN:CLOSE``: frames relative to the frame, close at or after open."""
    try:
        open_, close = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected OPEN:CLOSE in frames, e.g. --shutter=-0.25:0.25, got "
                                         f"{text!r}") from None
    if not (math.isfinite(open_) and math.isfinite(close) and close >= open_):
        raise argparse.ArgumentTypeError(f"expected finite OPEN:CLOSE with CLOSE >= OPEN, got {text!r}")
    return open_, close


def motion_samples_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 256:
        raise argparse.ArgumentTypeError(f"expected a whole number of sub-frames from 1 to 256, got {text!r}")
    return value


def add_render_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", metavar="PATH", help="camera prim path (default: render settings' camera, "
                        "else the first camera)")
    parser.add_argument("--res", type=resolution_arg, metavar="WxH",
                        help="image size; WIDTH alone keeps the camera's aspect (default: the stage's "
                        "RenderSettings or RenderProduct resolution, 2048x1080 where a RenderSettings prim leaves it "
                        "unauthored; 512 wide without RenderSettings)")
    parser.add_argument("--res-scale", type=_percent, metavar="PERCENT",
                        help="scale the resolution (--res, else the stage's, else the default) by PERCENT, as husk's "
                        "--res-scale: 50 renders half the width and height (default 100)")
    parser.add_argument("--device", default="auto", help="auto (cuda when present), cpu, cuda or cuda:N")
    parser.add_argument("--technique", default=DEFAULT_TECHNIQUE, type=technique_arg, choices=technique_names(),
                        help=f"rendering technique (default: {DEFAULT_TECHNIQUE})")
    parser.add_argument("--set", dest="settings", type=setting_arg, action="append", default=[], metavar="NAME=VALUE",
                        help="technique or pass setting, repeatable (see --help-settings)")
    parser.add_argument("--spp", type=int, metavar="N", help="path_tracer: samples per pixel; hybrid: most "
                        "multiple-scattering paths per pixel (= --set spp=N)")
    parser.add_argument("--seed", type=int, metavar="S", help="path_tracer, hybrid: random seed (= --set seed=S)")
    parser.add_argument("--target-error", type=_fraction, metavar="E",
                        help="hybrid: add paths until the frame's estimated relative RMSE is below E, in (0, 1) "
                        "(= --set target_error=E; default 0.05)")
    parser.add_argument("--time-budget", type=_seconds, metavar="S",
                        help="hybrid: stop adding paths after S seconds per frame (= --set time_budget=S)")
    parser.add_argument("--shutter", type=shutter_arg, metavar="OPEN:CLOSE", help="motion blur over this "
                        "shutter, in frames relative to each frame (e.g. --shutter=-0.25:0.25; default: the camera's "
                        "shutter:open/close; 0:0 renders without blur)")
    parser.add_argument("--motion-samples", type=motion_samples_arg, default=DEFAULT_SAMPLES, metavar="N",
                        help=f"sub-frames averaged over an open shutter (default {DEFAULT_SAMPLES}; a blurred frame "
                        "costs N frames)")
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
    usd.add_argument("--colorspace", type=colorspace_argument, default=None, metavar="NAME", help="the EXR's "
                     "primaries: lin_rec709 or ACEScg, or an OpenColorIO name of either (default: the settings' "
                     "renderingColorSpace, else lin_rec709)")
    add_quiet(parser)


def add_quiet(parser: argparse.ArgumentParser, *, command: bool = True) -> None:
    """``-q``/``--quiet``: no progress lines (:mod:`warpsky.core.progress`); before the command or after it."""
    parser.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS if command else False,
                        help="no progress lines (kernel compiles, table builds)")


def settings_from_args(args) -> dict[str, str]:
    """--set pairs plus the --spp / --seed / --target-error / --time-budget shorthands."""
    settings = dict(args.settings)
    own = field_kinds(technique_class(args.technique).Settings)
    for name in SHORTHANDS:
        value = getattr(args, name, None)
        if value is None:
            continue
        if name not in own:
            flag = "--" + name.replace("_", "-")
            takers = [cls.name for cls in technique_classes() if name in field_kinds(cls.Settings)]
            raise UsageError(f"{flag} applies to technique {' or '.join(takers)} only (this render uses "
                             f"{args.technique})")
        settings[name] = repr(value) if isinstance(value, float) else str(value)
    return settings


def options_from_args(args) -> object:
    """The render's options as the Python API builds them (:func:`warpsky.api.render_options`)."""
    from warpsky.api import render_options

    return render_options(
        technique=args.technique,
        settings=settings_from_args(args),
        resolution=args.res,
        device=args.device,
        camera=args.camera,
        colorspace=args.colorspace,
        load=args.load,
        variants=tuple(args.variants),
        purposes=("default", *args.purposes) if args.purposes else None,
        half=not getattr(args, "full_float", False),
        png=getattr(args, "png", False),
        deep=getattr(args, "deep", False),
        deep_samples=check_deep_samples(DEEP_SAMPLES if getattr(args, "deep_samples", None) is None
                                        else args.deep_samples),
        exposure=getattr(args, "exposure", None),
        view=check_view(getattr(args, "view", DEFAULT_VIEW)),
        max_memory=args.max_memory,
        shutter=args.shutter,
        motion_samples=args.motion_samples,
        work_limit=args.work_limit,
    )


def explicit_options(args) -> set[str]:
    """Options given on the command line, which win over the stage's render settings and products."""
    given = {"camera": args.camera, "resolution": args.res, "purposes": args.purposes, "colorspace": args.colorspace,
             "deep_samples": getattr(args, "deep_samples", None)}
    return {name for name, value in given.items() if value}
