"""``warpsky prepare``: build every kernel and table a stage's frame needs, ahead of a render or a farm run, and say
how long each part took (:mod:`warpsky.render.prepare`)."""

from __future__ import annotations

from pathlib import Path

from warpsky.cli.options import add_render_options, explicit_options, options_from_args, with_res_scale


def add_parser(sub) -> None:
    prepare = sub.add_parser(
        "prepare", help="build the kernels and tables a stage's frame needs, without rendering it",
        description="Plan STAGE's frame as 'warpsky render' would with the same options, build the optics tables "
        "it needs and compile its Warp kernels (by rendering it at a few pixels, written nowhere), then print how "
        "long each part took. Renders of the frame afterwards, here or on workers sharing the caches (Warp's "
        "kernel cache and $WARPSKY_CACHE), start without compiling or building.")
    prepare.add_argument("stage", type=Path, help="USD stage")
    prepare.add_argument("--time", type=float, default=None, help="time code of the frame (default: earliest)")
    add_render_options(prepare)


def cmd_prepare(args) -> int:
    from warpsky.api import open_stage
    from warpsky.render.prepare import format_parts, prepare_frame

    reader, _, options = open_stage(args.stage, options_from_args(args), args.settings_prim,
                                    explicit=explicit_options(args))
    frame, parts = prepare_frame(reader, args.time, with_res_scale(options, args.res_scale))
    print(format_parts(args.stage, frame, parts))
    return 0
