"""Tone-mapped PNG previews of linear radiance.

Tone map, per channel: ``x = radiance * exposure``; ``y = 1 - exp(-x)`` (linear near 0, a smooth shoulder that never
clips hard); then the sRGB transfer curve (12.92 y below 0.0031308, else 1.055 y^(1/2.4) - 0.055); 8 bits.
Non-finite or negative input counts as 0. The renderer picks ``exposure`` so that a white Lambertian surface facing
the sun maps to x = 1 (y = 0.63), times 2^EV from ``--exposure``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from warpsky.files import atomic_write


def tonemap(rgb: np.ndarray, *, exposure: float = 1.0) -> np.ndarray:
    """Linear radiance (H, W, 3) -> sRGB-encoded uint8 (H, W, 3)."""
    x = np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    x = np.maximum(x, 0.0) * exposure
    y = -np.expm1(-x)
    encoded = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1.0 / 2.4) - 0.055)
    return np.clip(np.round(encoded * 255.0), 0, 255).astype(np.uint8)


def write_png(path: str | os.PathLike, rgb: np.ndarray, *, exposure: float = 1.0) -> Path:
    """Write the tone-mapped preview of ``rgb`` atomically."""
    from PIL import Image

    image = Image.fromarray(tonemap(rgb, exposure=exposure), mode="RGB")
    return atomic_write(path, lambda tmp: image.save(tmp, format="PNG"))
