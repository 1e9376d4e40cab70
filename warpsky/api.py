"""warpsky from Python: render a stage into arrays, or into an EXR, without the command line.

    import warpsky
    image = warpsky.render_stage("usd_scenes/cumulus.usda", time=1, resolution=(256, 170))
    rgba = image.frame.rgba                      # (H, W, 4) float32, linear
    print(image.metadata["technique"], image.channels.keys())
    warpsky.render_to_exr("usd_scenes/cumulus.usda", "out/cumulus.exr", time=1, png=True)

Both read the stage the way ``warpsky render`` does (the same stage reader, plan, passes and composite; the command
line builds its options with :func:`render_options`), so they return the pixels the command line writes. A
``product`` (a UsdRenderProduct prim path) applies that product's camera, resolution, pixel aspect, data window and
vars; ``settings_prim`` picks the UsdRenderSettings prim whose camera and resolution are the defaults.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from warpsky.core.errors import SceneError, UsageError
from warpsky.output.color import DEFAULT_COLORSPACE, check_colorspace, resolve_colorspace
from warpsky.output.products import FULL_WINDOW
from warpsky.render.frame import render_planned, write_frame
from warpsky.render.image import RenderedImage
from warpsky.render.options import RenderOptions
from warpsky.render.planned import planned_frame
from warpsky.render.registry import DEFAULT_TECHNIQUE, AovComponents
from warpsky.usd.render_settings import ProductSpec, RenderSpec, read_render_spec


def render_options(*, technique: str = DEFAULT_TECHNIQUE, resolution=None, camera: str | None = None,
                   device: str = "auto", settings: dict | None = None, colorspace: str | None = None,
                   load: str = "all", variants=(), purposes=None, **more) -> RenderOptions:
    """:class:`~warpsky.render.options.RenderOptions` from keyword arguments; ``resolution`` is (width, height), (width,
    None) or a width; ``variants`` are (set, selection) pairs or ``"SET=SELECTION"`` strings; the rest
    (``half``, ``png``, ``exposure``, ``max_memory``, ``work_limit``, ``deep``, ``deep_samples``) pass through."""
    from warpsky.core.device import resolve_device
    from warpsky.usd.composition import StageOptions, parse_variant

    if isinstance(resolution, int):
        resolution = (resolution, None)
    variants = tuple(parse_variant(v) if isinstance(v, str) else tuple(v) for v in variants)
    stage = StageOptions(load=load, variants=variants, **({} if purposes is None else {"purposes": tuple(purposes)}))
    if more.get("deep_samples") is not None:
        from warpsky.output.deep_bins import check_deep_samples

        more["deep_samples"] = check_deep_samples(more["deep_samples"], "deep_samples")
    else:
        more.pop("deep_samples", None)
    return RenderOptions(technique=technique, settings=dict(settings or {}),
                         resolution=None if resolution is None else tuple(resolution), device=resolve_device(device),
                         camera=camera, colorspace=check_colorspace(colorspace or DEFAULT_COLORSPACE), stage=stage,
                         **more)


def with_render_settings(options: RenderOptions, spec: RenderSpec | None, *, explicit: set[str] = frozenset()
                         ) -> RenderOptions:
    """``options`` with the UsdRenderSettings' camera, resolution, pixel aspect, data window, purposes and colour
    space filled in where ``explicit`` (the option names given by the caller) does not set them."""
    if spec is None:
        return options
    changes = {name: getattr(spec, name) for name in ("pixel_aspect", "data_window") if name not in explicit}
    if "camera" not in explicit and spec.camera is not None:
        changes["camera"] = spec.camera
    if "resolution" not in explicit and spec.resolution is not None:
        changes["resolution"] = spec.resolution
    if "purposes" not in explicit and spec.purposes is not None and options.stage is not None:
        changes["stage"] = replace(options.stage, purposes=spec.purposes)
    if "colorspace" not in explicit and spec.colorspace is not None:
        token, other = resolve_colorspace(spec.colorspace)
        if token is None:
            known = f" (OpenColorIO's {other!r}: warpsky does not write it)" if other else " is not supported"
            raise SceneError(f"{spec.path}.renderingColorSpace {spec.colorspace!r}{known}; expected lin_rec709 or "
                             "ACEScg, by any of their USD or OpenColorIO names (e.g. 'ACES - ACEScg', 'lin_ap1', "
                             "'Utility - Linear - sRGB')")
        changes["colorspace"] = token
    return replace(options, **changes)


def with_product(options: RenderOptions, product: ProductSpec, *, explicit: set[str] = frozenset()
                 ) -> RenderOptions:
    """``options`` with a RenderProduct's camera, resolution, pixel aspect, data window, vars, type and deep samples
    (its own values or those it inherits from its settings), except what ``explicit`` names."""
    changes = {"outputs": product.outputs, "deep_product": product.deep}
    changes |= {name: getattr(product, name) for name in ("pixel_aspect", "data_window") if name not in explicit}
    if "deep_samples" not in explicit and product.deep_samples is not None:
        changes["deep_samples"] = product.deep_samples
    if "camera" not in explicit and product.camera is not None:
        changes["camera"] = product.camera
    if "resolution" not in explicit and product.resolution is not None:
        changes["resolution"] = product.resolution
    return replace(options, **changes)


def open_stage(stage, options: RenderOptions, settings_prim: str | None, *, explicit: set[str] = frozenset()):
    """(reader, render spec or None, options with the render settings applied): the stage opened with the options'
    composition, reopened when the settings' ``includedPurposes`` change what renders."""
    from warpsky.usd.stage import StageReader

    reader = StageReader(stage, options.stage)
    spec = read_render_spec(reader.stage, settings_prim, reader.meters_per_unit, aovs=AovComponents())
    options = with_render_settings(options, spec, explicit=explicit)
    if options.stage != reader.options:  # the settings' includedPurposes
        reader = StageReader(stage, options.stage)
    return reader, spec, options


def _planned(stage, time, product: str | None, settings_prim: str | None, kwargs: dict):
    """(reader, planned frame) of one frame of ``stage``, with ``product``'s outputs when given."""
    from warpsky.core.device import init_warp

    init_warp()
    explicit = {k for k, v in kwargs.items() if v is not None}
    reader, spec, options = open_stage(stage, render_options(**kwargs), settings_prim, explicit=explicit)
    if product is not None:
        products = {p.path: p for p in (spec.products if spec else ())}
        if product not in products:
            known = ", ".join(products) or "none"
            raise SceneError(f"product {product} is not among the render settings' products (known: {known})")
        options = with_product(options, products[product], explicit=explicit)
    return reader, planned_frame(reader, time, options)


def render_stage(stage: str | os.PathLike, time: float | None = None, *, product: str | None = None,
                 settings_prim: str | None = None, **kwargs) -> RenderedImage:
    """Render ``stage`` at ``time`` (None: its earliest time sample) into memory; nothing is written.

    Keyword arguments are :func:`render_options`' (``technique``, ``resolution``, ``camera``, ``device``,
    ``settings``, ``colorspace``, ``load``, ``variants``, ``purposes``, ...). Returns a
    :class:`~warpsky.render.image.RenderedImage`: ``frame.rgba`` / ``frame.transmittance`` / ``frame.depth`` /
    ``frame.aovs``, the output's ``channels``, its ``metadata`` and OpenEXR ``attributes``.
    """
    reader, frame = _planned(stage, time, product, settings_prim, kwargs)
    return render_planned(frame, reader=reader)


def render_to_exr(stage: str | os.PathLike, out: str | os.PathLike, time: float | None = None, *,
                  product: str | None = None, settings_prim: str | None = None, **kwargs) -> Path:
    """Render ``stage`` at ``time`` and write ``out`` atomically (plus a PNG preview with ``png=True``); returns
    the EXR's path. Arguments as :func:`render_stage`."""
    if not str(out).lower().endswith(".exr"):
        raise UsageError(f"output {str(out)!r} must end in .exr")
    reader, frame = _planned(stage, time, product, settings_prim, kwargs)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    return write_frame(frame, Path(out), reader=reader).exr


__all__ = ["FULL_WINDOW", "open_stage", "render_options", "render_stage", "render_to_exr", "with_product",
           "with_render_settings"]
