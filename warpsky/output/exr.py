"""EXR frames through the OpenEXR Python bindings: RGBA plus AOVs and metadata, written atomically.

:func:`write_exr` writes warpsky's default channels: ``R, G, B, A`` (half by default, float32 with ``half=False``),
``transmittance.R/G/B`` and ``depth.Z`` (always float32); :func:`write_channels` writes any named channels (a
RenderProduct's vars), a data window inside a larger display window and OpenEXR's standard attributes. Metadata goes
into header attributes named ``warpsky/<key>`` (str, int or float). A frame is written to a temporary file in the
target directory and renamed into place, so readers never see a partial file.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpsky.core.errors import OutputError
from warpsky.core.files import atomic_write

__all__ = ["ExrImage", "read_exr", "validate_exr", "write_channels", "write_exr"]

METADATA_PREFIX = "warpsky/"
COMPRESSIONS = ("none", "zip", "piz", "dwaa", "zstd")


def _check(name: str, array: np.ndarray | None, shape: tuple) -> np.ndarray | None:
    if array is None:
        return None
    array = np.asarray(array)
    if array.shape != shape:
        raise OutputError(f"channel {name}: expected shape {shape}, got {array.shape}")
    bad = int(np.count_nonzero(~np.isfinite(array)))
    if bad:
        raise OutputError(f"channel {name}: {bad} NaN/Inf values; refusing to write them")
    return array


#: Half float's largest finite value.
HALF_MAX = 65504.0


def as_half(name: str, values: np.ndarray) -> np.ndarray:
    """``values`` as float16, finite values beyond +-65504 (half float's largest) clamped to it instead of
    becoming Inf, with one ``warning:`` line on stderr naming the channel and the count (a frame looking into the
    sun holds such values; 32-bit float keeps them)."""
    values = np.asarray(values)
    over = np.isfinite(values) & (np.abs(values) > HALF_MAX)
    count = int(np.count_nonzero(over))
    if count:
        print(f"warpsky: warning: channel {name}: {count} value(s) beyond {HALF_MAX:g}, half float's largest "
              f"(max {float(np.abs(values[over]).max()):.4g}), written as {HALF_MAX:g}; --float writes 32-bit "
              "float", file=sys.stderr, flush=True)
        values = np.clip(values, -HALF_MAX, HALF_MAX)
    return np.ascontiguousarray(values, dtype=np.float16)


def write_exr(
    path: str | os.PathLike,
    rgba: np.ndarray,
    *,
    transmittance: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    aovs: dict | None = None,
    metadata: dict | None = None,
    half: bool = True,
    compression: str = "zip",
) -> Path:
    """Write one frame. Nothing is written if any channel holds NaN/Inf or has the wrong shape."""
    rgba = np.asarray(rgba)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise OutputError(f"channel RGBA: expected shape (H, W, 4), got {rgba.shape}")
    height, width = rgba.shape[:2]
    _check("RGBA", rgba, rgba.shape)
    transmittance = _check("transmittance", transmittance, (height, width, 3))
    depth = _check("depth.Z", depth, (height, width))
    channels = {"RGBA": as_half("RGBA", rgba) if half else np.ascontiguousarray(rgba, dtype=np.float32)}
    if transmittance is not None:
        for i, c in enumerate("RGB"):
            channels[f"transmittance.{c}"] = np.ascontiguousarray(transmittance[..., i], dtype=np.float32)
    if depth is not None:
        channels["depth.Z"] = np.ascontiguousarray(depth, dtype=np.float32)
    for name, values in (aovs or {}).items():
        values = _check(name, values, (height, width, 3))
        for i, c in enumerate("RGB"):
            channels[f"{name}.{c}"] = np.ascontiguousarray(values[..., i], dtype=np.float32)
    return write_channels(path, channels, metadata=metadata, compression=compression)


def header_attributes(metadata: dict | None, standard: dict | None = None) -> dict:
    """OpenEXR header attributes: ``standard`` as given, then ``metadata`` under ``warpsky/<key>`` (str, int or
    float; bools as 0/1; an integer beyond the 32 bits of an EXR int, a 1080p frame's grid lookups say, as a float
    to 7 digits rather than wrapped)."""
    header = dict(standard or {})
    for key, value in (metadata or {}).items():
        if isinstance(value, (bool, np.bool_)):
            value = int(value)
        elif isinstance(value, (np.integer, np.floating)):
            value = value.item()
        if not isinstance(value, (str, int, float)):
            raise OutputError(f"metadata {key!r}: expected str, int or float, got {type(value).__name__}")
        if isinstance(value, int) and not -2**31 <= value < 2**31:
            value = float(value)
        header[METADATA_PREFIX + key] = value
    return header


def write_channels(
    path: str | os.PathLike,
    channels: dict[str, np.ndarray],
    *,
    metadata: dict | None = None,
    standard: dict | None = None,
    compression: str = "zip",
    display: tuple[int, int] | None = None,
    origin: tuple[int, int] = (0, 0),
) -> Path:
    """Write named channels ((H, W) arrays, or the (H, W, 4) ``RGBA`` shorthand), in the given order, atomically.

    ``metadata`` goes into ``warpsky/<key>`` attributes; ``standard`` holds OpenEXR's own attributes
    (``chromaticities``, ``whiteLuminance``, ``worldToCamera``, ``pixelAspectRatio``, ...) as the bindings take
    them. ``display`` (width, height) is the whole image when the channels cover only the data window starting
    at pixel ``origin`` (x, y from the top left)."""
    import OpenEXR

    if compression not in COMPRESSIONS:
        raise OutputError(f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
    shapes = {name: np.shape(values)[:2] for name, values in channels.items()}
    if len(set(shapes.values())) > 1:
        raise OutputError(f"channels differ in size: {shapes}")
    for name, values in channels.items():
        _check(name, values, np.shape(values))
    header = {
        "compression": getattr(OpenEXR, f"{'NO' if compression == 'none' else compression.upper()}_COMPRESSION"),
        "type": OpenEXR.scanlineimage,
    }
    if display is not None:
        height, width = next(iter(shapes.values()))
        x0, y0 = origin
        header["dataWindow"] = (np.array([x0, y0], np.int32), np.array([x0 + width - 1, y0 + height - 1], np.int32))
        header["displayWindow"] = (np.array([0, 0], np.int32), np.array([display[0] - 1, display[1] - 1], np.int32))
    header.update(header_attributes(metadata, standard))
    channels = {name: np.ascontiguousarray(values) for name, values in channels.items()}
    return atomic_write(path, lambda tmp: OpenEXR.File(header, channels).write(str(tmp)))


@dataclass
class ExrImage:
    """A frame read back: channels by name (H, W arrays), the ``warpsky/`` metadata without its prefix, and the
    whole header (OpenEXR's standard attributes included)."""

    channels: dict[str, np.ndarray]
    metadata: dict
    width: int
    height: int
    header: dict = field(default_factory=dict)

    def rgba(self) -> np.ndarray:
        return np.stack([self.channels[c].astype(np.float32) for c in "RGBA"], axis=-1)

    def transmittance(self) -> np.ndarray:
        return np.stack([self.channels[f"transmittance.{c}"] for c in "RGB"], axis=-1)

    def depth(self) -> np.ndarray:
        return self.channels["depth.Z"]


def read_exr(path: str | os.PathLike) -> ExrImage:
    """Read every channel and the warpsky metadata; a missing, truncated or corrupt file is an OutputError."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
            header = dict(exr.header())
    except Exception as exc:  # the bindings raise RuntimeError, but also other types on damaged data
        raise OutputError(f"cannot read EXR {path}: {exc}") from None
    if not channels:
        raise OutputError(f"EXR {path} has no channels")
    height, width = next(iter(channels.values())).shape
    metadata = {k[len(METADATA_PREFIX):]: v for k, v in header.items() if k.startswith(METADATA_PREFIX)}
    return ExrImage(channels, metadata, width, height, header)


def validate_exr(path: str | os.PathLike, *, required_channels, metadata_expect: dict | None = None) -> bool:
    """True when ``path`` opens, holds ``required_channels`` and its metadata has ``metadata_expect``'s values."""
    if not Path(path).is_file():
        return False
    try:
        image = read_exr(path)
    except OutputError:
        return False
    if any(name not in image.channels for name in required_channels):
        return False
    return all(image.metadata.get(k) == v for k, v in (metadata_expect or {}).items())
