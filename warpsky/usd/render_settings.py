"""UsdRender prims: what a stage asks to be rendered, the way ``husk`` reads it.

A ``UsdRenderSettings`` prim (``--settings PATH``, else the stage's ``renderSettingsPrimPath`` metadata, else the
first one) gives the camera, resolution (UsdRender's fallback 2048 x 1080 when unauthored), pixel aspect ratio,
data window and purposes, and its ``products`` relationship names ``UsdRenderProduct`` prims. Each product
writes one image per frame to its ``productName`` (``$F4``, ``$F`` and ``####`` mark the frame number), may
override the settings' camera, resolution, pixel aspect ratio and data window, and lists its channels as
``orderedVars``: ``UsdRenderVar`` prims whose ``sourceName`` names a warpsky output (:data:`SOURCES`) and whose
``dataType`` says how many components and what precision.
A var's name (``driver:parameters:aov:name``, else the prim's name) is its EXR layer (``depth`` -> ``depth.Z``),
except for the beauty, whose channels are plain ``R, G, B(, A)``, and the single-channel vars RenderMan names
``a`` and ``z``, written as ``A`` and ``Z`` (:data:`PLAIN_CHANNELS`).

A RenderVar warpsky cannot write (a light path expression other than the beauty's ``C.*``, a ``primvar`` or
``intrinsic`` source, an ``id`` or ``N`` that is no warpsky output) is left out of its product with one ``warning:``
line naming the RenderVar, as husk does; only a product left with no RenderVar at all is an error.

Attributes read here and not acted on (``materialBindingPurposes``: warpsky binds no materials;
``disableMotionBlur`` and friends: warpsky renders instants) are reported as notes, not errors.

pxr is imported inside the functions (a heavy import).
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass

from warpsky.core.errors import SceneError, UnsupportedVar
from warpsky.output.products import OutputVar

#: The outputs of every frame a RenderVar's ``sourceName`` may name, with their components; the AOVs some
#: techniques add (``Technique.aovs``) are given to :func:`read_render_spec` by the caller.
SOURCES = {"color": "RGBA", "alpha": "A", "transmittance": "RGB", "depth": "Z"}
#: Other spellings of the same sources: RenderMan's and Karma's beauty, light path expressions for the beauty.
ALIASES = {"ci": "color", "c": "color", "rgba": "color", "beauty": "color", "c.*": "color", "z": "depth",
           "a": "alpha"}
#: Single-channel RenderVars named so are written as the plain EXR channel, as RenderMan's EXR driver names them
#: (``Ci`` + ``a`` + ``z`` -> ``R, G, B, A, Z``), not as a layer (``a.A``); any other var's name is its layer.
PLAIN_CHANNELS = {"a": "A", "A": "A", "z": "Z", "Z": "Z"}
#: ``dataType`` tokens by component count, and which of them are half floats.
DATA_TYPES = {
    1: ("float", "half", "double"),
    3: ("color3f", "color3h", "color3d", "float3", "half3", "double3", "vector3f", "vector3h"),
    4: ("color4f", "color4h", "color4d", "float4", "half4", "double4"),
}
HALF_TYPES = frozenset({"half", "color3h", "half3", "vector3h", "color4h", "half4"})
SOURCE_TYPES = ("raw", "lpe")


CONFORM_POLICY = "expandAperture"
#: husk's frame tokens: $F, $F4, ${F4} (the frame, zero-padded to the digits) and $FF (the frame, unpadded); a
#: token ends where no letter or digit follows (an underscore separates), so $FPS is not a frame token.
FRAME_TOKEN = re.compile(r"\$F(\d*)(?![A-Za-z0-9])|\$\{F(\d*)\}|\$\{FF\}|\$FF(?![A-Za-z0-9])")
#: husk's frames-per-second token.
FPS_TOKEN = re.compile(r"\$\{FPS\}|\$FPS(?![A-Za-z0-9])")


@dataclass(frozen=True)
class ProductSpec:
    """One UsdRenderProduct with what it inherits from its settings already applied."""

    path: str
    name: str  # the output path, frame tokens rewritten as a #### placeholder
    camera: str | None
    resolution: tuple[int, int] | None
    pixel_aspect: float
    data_window: tuple[float, float, float, float]
    outputs: tuple[OutputVar, ...]
    deep: bool = False  # productType "deepRaster": the file is a deep EXR (R, G, B, A, Z, ZBack), no flat frame
    deep_samples: int | None = None  # int warpsky:deepSamples on a deepRaster product: volume samples per pixel


#: The RenderProduct types warpsky writes: a flat OpenEXR image, or a deep scanline one.
PRODUCT_TYPES = ("raster", "deepRaster")
#: The sources a deep product's samples carry; its other RenderVars are left out with a warning.
DEEP_SOURCES = ("color", "alpha", "depth")


@dataclass(frozen=True)
class RenderSpec:
    """A UsdRenderSettings prim and its products."""

    path: str
    camera: str | None
    resolution: tuple[int, int] | None
    pixel_aspect: float
    data_window: tuple[float, float, float, float]
    purposes: tuple[str, ...] | None  # None: not authored
    colorspace: str | None  # renderingColorSpace, when authored
    products: tuple[ProductSpec, ...]
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()  # RenderVars left out of their products, one line each
    resolution_authored: bool = True  # False: ``resolution`` is the schema's fallback


def frame_placeholder(name: str, fps: float | None = None) -> str:
    """``productName`` with husk's frame tokens as warpsky's placeholder (``$F4`` -> ``####``, ``$F`` and ``$FF``
    -> ``#``) and, given the stage's ``fps``, ``$FPS`` as that number (``24``)."""
    if fps is not None:
        name = FPS_TOKEN.sub(lambda m: f"{fps:g}", name)
    return FRAME_TOKEN.sub(lambda m: "#" * max(1, int(m.group(1) or m.group(2) or 1)), name)


def find_settings(stage, settings_path: str | None):
    """The UsdRenderSettings prim to use, or None when the stage has none (and none was asked for)."""
    from pxr import Sdf, UsdRender

    if settings_path is not None:
        if not Sdf.Path.IsValidPathString(settings_path) or not Sdf.Path(settings_path).IsAbsolutePath():
            raise SceneError(f"--settings {settings_path!r} is not an absolute prim path (e.g. /Render/Settings)")
        prim = stage.GetPrimAtPath(settings_path)
        if not prim:
            raise SceneError(f"--settings {settings_path}: the stage has no prim there")
        if not prim.IsA(UsdRender.Settings):
            raise SceneError(f"--settings {settings_path}: prim is a {prim.GetTypeName() or 'typeless prim'}, "
                             "not a RenderSettings")
        return prim
    metadata = stage.GetMetadata("renderSettingsPrimPath") or ""
    if metadata:
        prim = stage.GetPrimAtPath(metadata)
        if not prim or not prim.IsA(UsdRender.Settings):
            raise SceneError(f"the stage's renderSettingsPrimPath {metadata} is not a RenderSettings prim")
        return prim
    for prim in stage.Traverse():
        if prim.IsA(UsdRender.Settings):
            return prim
    return None


def read_render_spec(stage, settings_path: str | None, meters_per_unit: float = 1.0, *,
                     aovs: dict[str, str] | None = None) -> RenderSpec | None:
    """The render settings and products of ``stage`` (None when it has no RenderSettings prim); ``aovs``: the
    outputs RenderVars may name besides :data:`SOURCES`, name -> components (those some technique writes)."""
    from pxr import UsdRender

    prim = find_settings(stage, settings_path)
    if prim is None:
        return None
    settings = UsdRender.Settings(prim)
    base = base_values(settings, None)
    notes = []
    bindings = [str(p) for p in (settings.GetMaterialBindingPurposesAttr().Get() or []) if str(p)]
    if settings.GetMaterialBindingPurposesAttr().HasAuthoredValue():
        notes.append(f"{prim.GetPath()}.materialBindingPurposes {bindings} ignored: warpsky binds no materials")
    purposes_attr = settings.GetIncludedPurposesAttr()
    purposes = tuple(str(p) for p in purposes_attr.Get()) if purposes_attr.HasAuthoredValue() else None
    colorspace_attr = prim.GetAttribute("renderingColorSpace")
    colorspace = str(colorspace_attr.Get()) if colorspace_attr and colorspace_attr.HasAuthoredValue() else None
    products, warnings = [], []
    for target in settings.GetProductsRel().GetTargets():
        product_prim = stage.GetPrimAtPath(target)
        if not product_prim or not product_prim.IsA(UsdRender.Product):
            raise SceneError(f"{prim.GetPath()}.products targets {target}, which is not a RenderProduct prim")
        products.append(_product(stage, UsdRender.Product(product_prim), base, {**SOURCES, **(aovs or {})},
                                 warnings))
    for line in warnings:  # printed once every product is read: a later product's error is then the only line
        print(f"warpsky: warning: {line}", file=sys.stderr, flush=True)
    return RenderSpec(str(prim.GetPath()), *base, purposes, colorspace, tuple(products), tuple(notes),
                      tuple(warnings), settings.GetResolutionAttr().HasAuthoredValue())


def base_values(schema, inherited) -> tuple:
    """(camera, resolution, pixel aspect, data window) of a RenderSettingsBase prim; unauthored values come from
    ``inherited`` (a product inherits its settings'), else from the schema: a RenderSettings prim without a
    ``resolution`` renders UsdRender's fallback 2048 x 1080, as husk does."""
    prim = schema.GetPrim()
    path = prim.GetPath()
    camera, resolution, aspect, window = inherited if inherited is not None else (None, None, 1.0, (0.0, 0.0, 1.0, 1.0))
    targets = schema.GetCameraRel().GetTargets()
    if targets:
        camera = str(targets[0])
    attr = schema.GetResolutionAttr()
    if attr.HasAuthoredValue() or inherited is None:  # unauthored on the settings: the schema's 2048 x 1080
        res = attr.Get()
        if res[0] <= 0 or res[1] <= 0:
            raise SceneError(f"{path}.resolution must be two positive integers, got {tuple(res)}")
        resolution = (int(res[0]), int(res[1]))
    attr = schema.GetPixelAspectRatioAttr()
    if attr.HasAuthoredValue():
        aspect = float(attr.Get())
        if not 0.0 < aspect < float("inf"):
            raise SceneError(f"{path}.pixelAspectRatio must be positive, got {aspect}")
    attr = schema.GetDataWindowNDCAttr()
    if attr.HasAuthoredValue():
        window = tuple(float(v) for v in attr.Get())
        if not (window[0] < window[2] and window[1] < window[3]):
            raise SceneError(f"{path}.dataWindowNDC must be (xmin, ymin, xmax, ymax) with min < max, got {window}")
    policy = schema.GetAspectRatioConformPolicyAttr()
    if policy.HasAuthoredValue() and str(policy.Get()) != CONFORM_POLICY:
        raise SceneError(f"{path}.aspectRatioConformPolicy {str(policy.Get())!r} is not supported; warpsky "
                         f"conforms cameras by {CONFORM_POLICY!r} (the film back grows to the image's aspect)")
    return camera, resolution, aspect, window


def sampled_name(attr, times, path: str) -> str:
    """A time-sampled ``productName`` (Houdini Solaris writes one literal file name per frame) as one pattern:
    the samples' common value, else the name at the first sample with the run of digits that spells its frame
    number replaced by as many ``#``, provided that pattern gives every sample's name at its time (husk's tokens
    are left for :func:`frame_placeholder`)."""
    names = {float(t): str(attr.Get(t) or "") for t in times}
    distinct = set(names.values())
    if len(distinct) == 1:
        return distinct.pop()
    first_time, first = next(iter(names.items()))
    candidates = [m for m in re.finditer(r"\d+", first) if float(m.group()) == first_time]
    for match in reversed(candidates):  # the last run that spells the frame, as in shot_v002.0001.exr
        width = len(match.group())
        pattern = first[:match.start()] + "#" * width + first[match.end():]
        if all(t == int(t) and name == pattern.replace("#" * width, f"{int(t):0{width}d}")
               for t, name in names.items()):
            return pattern
    raise SceneError(f"{path}.productName has {len(names)} time samples that do not follow one frame pattern "
                     f"(e.g. {first!r} at {first_time:g}); author one name with $F4 or ####, or samples that differ "
                     "only in the frame number")


def _product(stage, product, base, sources: dict[str, str], warnings: list[str]) -> ProductSpec:
    """One RenderProduct; the RenderVars it leaves out are appended to ``warnings``."""
    from pxr import UsdRender

    prim = product.GetPrim()
    path = str(prim.GetPath())
    kind = str(product.GetProductTypeAttr().Get() or "raster")
    if kind not in PRODUCT_TYPES:
        raise SceneError(f"{path}.productType {kind!r} is not supported; warpsky writes 'raster' (flat EXR) and "
                         "'deepRaster' (deep scanline EXR) products")
    attr = product.GetProductNameAttr()
    times = attr.GetTimeSamples()
    name = sampled_name(attr, times, path) if times else str(attr.Get() or "")
    if not name:
        raise SceneError(f"{path}.productName is not authored; expected the output file, e.g. out/shot.$F4.exr")
    name = frame_placeholder(name, stage.GetFramesPerSecond())
    if not name.lower().endswith(".exr"):
        raise SceneError(f"{path}.productName {name!r} must end in .exr (warpsky writes OpenEXR products)")
    values = base_values(product, base)
    targets = product.GetOrderedVarsRel().GetTargets()
    if not targets:
        raise SceneError(f"{path}.orderedVars names no RenderVar; expected at least one (e.g. sourceName color)")
    outputs, skipped = [], []
    for target in targets:
        var_prim = stage.GetPrimAtPath(target)
        if not var_prim or not var_prim.IsA(UsdRender.Var):
            raise SceneError(f"{path}.orderedVars targets {target}, which is not a RenderVar prim")
        try:
            outputs.append(read_var(UsdRender.Var(var_prim), sources))
        except UnsupportedVar as exc:
            skipped.append(str(exc))
    if not outputs:
        raise SceneError(f"{skipped[0]}; {path}.orderedVars names no other RenderVar warpsky writes"
                         if len(skipped) == 1 else f"{path}: none of its {len(skipped)} RenderVars is one warpsky "
                         f"writes (first: {skipped[0]})")
    warnings += [f"{reason}; left out of product {path}" for reason in skipped]
    seen: dict[str, str] = {}
    for output in outputs:
        for channel in output.channels:
            if channel in seen:
                raise SceneError(f"{path}: RenderVars {seen[channel]} and {output.prim} both write channel "
                                 f"{channel!r}; give one of them another name")
            seen[channel] = output.prim
    deep = kind == "deepRaster"
    if deep:
        warnings += [f"RenderVar {o.prim} ({o.source}): a deep product holds R, G, B, A, Z and ZBack only; left out "
                     f"of product {path}" for o in outputs if o.source not in DEEP_SOURCES]
    return ProductSpec(path, name, *values, tuple(outputs), deep, deep_samples(prim) if deep else None)


def deep_samples(prim) -> int | None:
    """A deepRaster product's ``int warpsky:deepSamples`` (volume samples per pixel of each volume layer), or None
    when unauthored; a SceneError names the attribute when it is not a whole number in 1..64."""
    from warpsky.output.deep_bins import MAX_DEEP_SAMPLES

    attr = prim.GetAttribute("warpsky:deepSamples")
    if not attr or not attr.HasAuthoredValue():
        return None
    value = attr.Get()
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_DEEP_SAMPLES:
        raise SceneError(f"{prim.GetPath()}.warpsky:deepSamples must be an int in 1..{MAX_DEEP_SAMPLES} (volume "
                         f"samples per pixel of each volume layer), got {value!r}")
    return int(value)


def read_var(var, sources: dict[str, str] = SOURCES) -> OutputVar:
    """A RenderVar as an :class:`OutputVar`: its source (a key of ``sources``, name -> components), layer name
    and channel types checked; :class:`UnsupportedVar` for a source warpsky does not write."""
    prim = var.GetPrim()
    path = str(prim.GetPath())
    known = ", ".join(sources)
    source_type = str(var.GetSourceTypeAttr().Get() or "raw")
    raw_name = str(var.GetSourceNameAttr().Get() or "")
    if source_type not in SOURCE_TYPES:
        raise UnsupportedVar(f"RenderVar {path}.sourceType {source_type!r} is not supported; warpsky outputs raw "
                             f"sources ({known}) and the beauty as lpe 'C.*'")
    name = raw_name.strip().lower()
    name = ALIASES.get(name, name)
    if source_type == "lpe" and name != "color":
        raise UnsupportedVar(f"RenderVar {path}: light path expression {raw_name!r} is not supported; warpsky "
                             "writes the beauty for 'C.*' and these raw sources: " + known)
    if name not in sources:
        raise UnsupportedVar(f"RenderVar {path}.sourceName {raw_name!r} is not a warpsky output; known: {known}")
    components = sources[name]
    data_type = str(var.GetDataTypeAttr().Get() or "")
    count = next((n for n, types in DATA_TYPES.items() if data_type in types), None)
    allowed = (3, 4) if name == "color" else (len(components),)
    if count not in allowed:
        expected = " or ".join(DATA_TYPES[n][0] for n in allowed)
        raise SceneError(f"RenderVar {path}.dataType {data_type!r} does not fit source {name} ({components}); "
                         f"expected {expected} (or their half/double forms)")
    if name == "color" and count == 3:
        components = "RGB"
    layer_attr = prim.GetAttribute("driver:parameters:aov:name")
    layer = str(layer_attr.Get()) if layer_attr and layer_attr.HasAuthoredValue() else prim.GetName()
    if name == "color":
        layer = ""  # the beauty (Ci, C.*, color): unprefixed R, G, B, A
    elif len(components) == 1 and layer in PLAIN_CHANNELS:
        layer, components = "", PLAIN_CHANNELS[layer]
    return OutputVar(layer, name, components, data_type in HALF_TYPES, path)
