"""EXR frames through the OpenEXR Python bindings: RGBA plus AOVs and metadata, written atomically.

Channels: ``R, G, B, A`` (half by default, float32 with ``half=False``), ``transmittance.R/G/B`` and ``depth.Z``
(always float32). Metadata goes into header attributes named ``warpsky/<key>`` (str, int or float). A frame is
written to a temporary file in the target directory and renamed into place, so readers never see a partial file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.files import OutputError, atomic_write

__all__ = ["OutputError", "ExrImage", "read_exr", "validate_exr", "write_exr"]

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
    import OpenEXR

    rgba = np.asarray(rgba)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise OutputError(f"channel RGBA: expected shape (H, W, 4), got {rgba.shape}")
    height, width = rgba.shape[:2]
    _check("RGBA", rgba, rgba.shape)
    transmittance = _check("transmittance", transmittance, (height, width, 3))
    depth = _check("depth.Z", depth, (height, width))
    if compression not in COMPRESSIONS:
        raise OutputError(f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
    channels = {"RGBA": np.ascontiguousarray(rgba, dtype=np.float16 if half else np.float32)}
    if transmittance is not None:
        for i, c in enumerate("RGB"):
            channels[f"transmittance.{c}"] = np.ascontiguousarray(transmittance[..., i], dtype=np.float32)
    if depth is not None:
        channels["depth.Z"] = np.ascontiguousarray(depth, dtype=np.float32)
    for name, values in (aovs or {}).items():
        values = _check(name, values, (height, width, 3))
        for i, c in enumerate("RGB"):
            channels[f"{name}.{c}"] = np.ascontiguousarray(values[..., i], dtype=np.float32)
    header = {
        "compression": getattr(OpenEXR, f"{'NO' if compression == 'none' else compression.upper()}_COMPRESSION"),
        "type": OpenEXR.scanlineimage,
    }
    for key, value in (metadata or {}).items():
        if isinstance(value, (bool, np.bool_)):
            value = int(value)
        elif isinstance(value, (np.integer, np.floating)):
            value = value.item()
        if not isinstance(value, (str, int, float)):
            raise OutputError(f"metadata {key!r}: expected str, int or float, got {type(value).__name__}")
        header[METADATA_PREFIX + key] = value
    return atomic_write(path, lambda tmp: OpenEXR.File(header, channels).write(str(tmp)))


@dataclass
class ExrImage:
    """A frame read back: channels by name (H, W arrays), and the ``warpsky/`` metadata without its prefix."""

    channels: dict[str, np.ndarray]
    metadata: dict
    width: int
    height: int

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
    return ExrImage(channels, metadata, width, height)


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
