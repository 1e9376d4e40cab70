"""Output colour spaces: the primaries an EXR's RGB are written in, and the matrices between them.

warpsky renders in linear Rec.709 primaries with a D65 white (``lin_rec709``, the primaries of sRGB). ``ACEScg``
(ACES AP1 primaries, the ACES white near D60) is reached with the matrix OpenColorIO's built-in CG config gives
for ``lin_rec709`` -> ``ACEScg`` (its Bradford-adapted standard matrix), so the file agrees with every OCIO-based
compositor. Which quantities are converted:

- radiance (``R, G, B``, ``single_scatter``, ``multiple_scatter``): by the matrix M;
- ``variance`` of a pixel mean: by M with its entries squared, which is exact when the three channels' errors are
  uncorrelated (they are correlated in a path tracer, so this is an estimate of the converted variance);
- ``transmittance``, alpha and depth: unchanged. Transmittance multiplies whatever lies behind; it is a per-band
  factor, not a colour, and keeps the rendering primaries' bands.

The PNG preview is always sRGB (from the lin_rec709 frame).
"""

from __future__ import annotations

import functools

import numpy as np

from warpsky.core.errors import UsageError

#: Colour spaces an EXR may be written in, with their CIE xy chromaticities (R, G, B, white) as OpenEXR's
#: ``chromaticities`` attribute holds them, and the OCIO colour space name.
COLORSPACES = {
    "lin_rec709": ((0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290), "lin_rec709"),
    "ACEScg": ((0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767), "ACEScg"),
}
DEFAULT_COLORSPACE = "lin_rec709"
#: AOVs whose name ends so hold variances (converted by M squared); every other AOV is a colour (converted by M).
VARIANCE_SUFFIX = "variance"


#: Names USD and OpenColorIO give these spaces without a config at hand (lower case), the rest resolved through
#: OpenColorIO's built-in CG config (:func:`resolve_colorspace`).
KNOWN_NAMES = {"lin_rec709": "lin_rec709", "lin_rec709_scene": "lin_rec709", "linear rec.709 (srgb)": "lin_rec709",
               "lin_srgb": "lin_rec709", "acescg": "ACEScg", "lin_ap1": "ACEScg", "lin_ap1_scene": "ACEScg",
               "aces - acescg": "ACEScg"}


def check_colorspace(name: str) -> str:
    if name not in COLORSPACES:
        raise UsageError(f"--colorspace {name!r}: expected one of {', '.join(COLORSPACES)}")
    return name


@functools.cache
def _builtin_config():
    import PyOpenColorIO as ocio

    return ocio.Config.CreateFromBuiltinConfig("cg-config-latest")


def resolve_colorspace(name: str) -> tuple[str | None, str | None]:
    """(the output colour space ``name`` selects, None) for any of its names or OpenColorIO aliases and roles in
    the built-in CG config (``ACES - ACEScg``, ``Utility - Linear - sRGB``, ``scene_linear``, ...), case and
    surrounding blanks ignored; (None, the config's name for it) for a colour space OpenColorIO knows that
    warpsky does not write; (None, None) for a name nobody knows."""
    key = name.strip().lower()
    if key in KNOWN_NAMES:
        return KNOWN_NAMES[key], None
    try:
        config = _builtin_config()
    except ImportError:
        return None, None
    space = config.getColorSpace(name.strip())
    if space is None:
        return None, None
    canonical = space.getName()
    for ours, (_, ocio_name) in COLORSPACES.items():
        if config.getColorSpace(ocio_name).getName() == canonical:
            return ours, None
    return None, canonical


def colorspace_argument(text: str) -> str:
    """argparse type of ``--colorspace``: any name :func:`resolve_colorspace` maps to an output colour space."""
    import argparse

    ours, other = resolve_colorspace(text)
    if ours is not None:
        return ours
    known = f" (OpenColorIO's {other!r}, which warpsky does not write)" if other else ""
    raise argparse.ArgumentTypeError(f"{text!r}{known}: expected {' or '.join(COLORSPACES)} or one of their "
                                     "OpenColorIO names, e.g. 'ACES - ACEScg', 'Utility - Linear - sRGB'")


@functools.cache
def matrix_from_rec709(name: str) -> np.ndarray:
    """3x3 matrix taking linear Rec.709 RGB (column vectors) to the colour space ``name``, from OpenColorIO."""
    check_colorspace(name)
    if name == DEFAULT_COLORSPACE:
        return np.eye(3)
    try:
        config = _builtin_config()
    except ImportError:
        raise UsageError(f"--colorspace {name} needs OpenColorIO: pip install 'warpsky[color]'") from None
    processor = config.getProcessor(COLORSPACES[DEFAULT_COLORSPACE][1], COLORSPACES[name][1])
    cpu = processor.getDefaultCPUProcessor()
    return np.array([cpu.applyRGB([float(v) for v in column]) for column in np.eye(3)], dtype=np.float64).T


def convert_frame(frame, name: str):
    """A copy of a composited :class:`~warpsky.passes.composite.Frame` with its colours in ``name`` (see the module
    docstring for what is converted); the frame itself when ``name`` is lin_rec709."""
    from dataclasses import replace

    if name == DEFAULT_COLORSPACE:
        return frame
    m = matrix_from_rec709(name).astype(np.float32)
    rgba = frame.rgba.copy()
    rgba[..., :3] = frame.rgba[..., :3] @ m.T
    aovs = {}
    for key, values in frame.aovs.items():
        aovs[key] = values @ ((m * m) if key.endswith(VARIANCE_SUFFIX) else m).T
    return replace(frame, rgba=rgba, aovs=aovs)


def colour_attributes(name: str) -> dict:
    """OpenEXR's standard colour attributes for a frame written in ``name``: ``chromaticities`` and
    ``whiteLuminance`` (1: a pixel value of 1 is 1 cd/m^2 when the stage's lights follow UsdLux's photometric
    units, intensity in nits and distant-light intensity in lux)."""
    return {"chromaticities": tuple(float(v) for v in COLORSPACES[check_colorspace(name)][0]),
            "whiteLuminance": 1.0}
