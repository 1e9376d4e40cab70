"""``warpsky info``: what a stage holds and how it would render (the plan, its passes, features and costs)."""

from __future__ import annotations

import numpy as np

from warpsky.api import open_stage, with_product
from warpsky.cli.options import explicit_options, options_from_args, with_res_scale
from warpsky.core.resources import resource_lines
from warpsky.light.dome import mean_radiance, upper_hemisphere
from warpsky.light.sun import has_horizon, sun_sunlight
from warpsky.render.planned import planned_frame


def _fmt3(values) -> str:
    """RGB triples as short numbers; one number when all three agree."""
    values = [float(v) for v in values]
    if max(values) == min(values):
        return f"{values[0]:.6g}"
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


def _light_lines(scene) -> list[str]:
    """``warpsky info``'s lines on the lights: each DistantLight's irradiance (intensity x 2^exposure x colour) and
    what reaches a horizontal surface above the horizon (the visible part of the disk, at its elevation); the
    dome's mean radiance and its irradiance on a horizontal surface."""


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
    res = "x".join(map(str, spec.resolution)) + ("" if spec.resolution_authored else " (not authored: the "
                                                  "UsdRender fallback)")
    lines = [f"render      {spec.path}: camera {spec.camera or 'not set'}, resolution {res}, pixel aspect "
             f"{spec.pixel_aspect:g}, dataWindowNDC {list(spec.data_window)}"
             + (f", purposes {', '.join(spec.purposes)}" if spec.purposes is not None else "")
             + (f", renderingColorSpace {spec.colorspace}" if spec.colorspace else "")]
    lines += [f"            note: {note}" for note in spec.notes]
    for product in products:
        res = "x".join(map(str, product.resolution)) if product.resolution else "default"
        lines.append(f"product     {product.path} -> {product.name}: camera {product.camera or 'default'}, "
                     f"resolution {res}" + (f", deep scanline EXR (R, G, B, A, Z, ZBack), {deep_samples(product)} "
                                            "volume samples per volume" if product.deep else ""))
        for var in (() if product.deep else product.outputs):
            precision = "half" if var.half else "float"
            lines.append(f"  var       {var.prim}: {var.source} -> {', '.join(var.channels)} ({precision})")
    return lines


def deep_samples(product) -> int:
    """Volume samples per volume a deep product gets: its ``warpsky:deepSamples``, else the default."""
    from warpsky.output.deep_bins import DEEP_SAMPLES

    return DEEP_SAMPLES if product.deep_samples is None else product.deep_samples


def cmd_info(args) -> int:

    options = options_from_args(args)
    reader, spec, options = open_stage(args.stage, options, args.settings_prim, explicit=explicit_options(args))
    products = list(spec.products) if spec else []
    if args.products:
        products = [p for p in products if p.path in args.products]
    if products:  # the plan of the first product
        options = with_product(options, products[0], explicit=explicit_options(args))
    options = with_res_scale(options, args.res_scale)
    span = reader.time_range()
    frame = planned_frame(reader, args.time, options, check=False)
    scene, plan = frame.scene, frame.plan
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
    out.append("motion blur off (shutter closed)" if frame.motion is None else
               f"motion blur shutter {frame.motion[0]:g} .. {frame.motion[1]:g} frames, {options.motion_samples} "
               f"sub-frames (a frame costs {options.motion_samples})")
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
        if medium.water is not None:
            peak, total = medium.water
            out.append(f"            water content: peak {peak * 1e3:.3g} g/m³, {total / 1e3:.4g} t in all (as its "
                       "writer recorded it)")
        if medium.ice is not None and medium.ice.orientation != "random":
            ice = medium.ice
            out.append(f"            oriented ice: {ice.fraction:.3g} of the crystals {ice.habit}s falling as "
                       f"{ice.orientation}s (tilt {ice.tilt_deg:g}°), the rest random columns; a phase table per "
                       "frame at the sun's elevation")
        if medium.has_detail:
            d = medium.detail
            out.append(f"            advected detail: amplitude {d.amplitude:g}, scale {d.scale:g} m, wind "
                       f"{np.round(np.asarray(d.wind), 3).tolist()} m/s, curl {d.curl_speed:g} m/s, "
                       f"period {d.period:g} s" + (f", edge {d.edge:g} 1/m" if d.edge > 0.0 else ""))
    out += _light_lines(scene)
    out += _render_spec_lines(spec, products)
    out += [f"composition {line}" for line in reader.composition_summary()]
    out += [f"warning     {line}" for line in (*(spec.warnings if spec else ()), *reader.warnings)]
    out.append("plan:" + (f" (of product {products[0].path})" if products else ""))
    out += ["  " + line for line in plan.describe().splitlines()]
    out += ["  " + line for line in resource_lines(plan, options.max_memory)]
    print("\n".join(out))
    return 0
