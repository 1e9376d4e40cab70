"""Denoising the Monte Carlo part of a frame with Intel Open Image Denoise (``pyoidn``), keeping its mean.

Only light scattered at least twice goes through the denoiser: it is smooth inside a cloud, and its noise-free
guide is the media's coverage 1 - T (T: the exact transmittance of the single-scattering march), which marks every
silhouette. Open Image Denoise reads an "albedo" guide in [0, 1]; coverage is one, grey where the media are
partly transparent and 1 on opaque surfaces.

A neural denoiser is not unbiased: on path-traced clouds it shifts the image's mean by several per cent. The
denoised image is therefore rescaled so that its local means, over a box of ``(2 r + 1)^2`` pixels, equal those
of the noisy input, which are unbiased: the denoiser keeps the fine structure, the noisy
image the level. ``r`` is a trade between that bias and the noise of the local means (the noise of a mean over
n pixels falls as 1/sqrt(n)).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from warpsky.core.device import is_cpu
from warpsky.core.errors import UsageError

#: The extra that installs the denoiser.
DENOISE_EXTRA = "pip install 'warpsky[denoise]' (or pip install pyoidn)"


@dataclass
class Denoised:
    image: np.ndarray  # (H, W, 3) float32
    seconds: float
    sanitised: int  # non-finite or negative input values replaced by 0


def require_denoiser():
    """The ``pyoidn`` module, or a UsageError naming the extra that installs it."""
    try:
        import pyoidn
    except ImportError as exc:
        raise UsageError(f"denoising needs Intel Open Image Denoise through pyoidn, which is not installed "
                         f"({exc}); {DENOISE_EXTRA}, or render with --set denoise=0") from None
    return pyoidn


def sanitise(image: np.ndarray) -> tuple[np.ndarray, int]:
    """(``image`` with NaN, infinite and negative values set to 0, as float32; how many were replaced)."""
    bad = ~np.isfinite(image) | (image < 0.0)
    count = int(bad.sum())
    out = np.where(bad, 0.0, image).astype(np.float32)
    return out, count


def box_sum(image: np.ndarray, radius: int) -> np.ndarray:
    """Sum over a (2 radius + 1)^2 box around every pixel (clipped at the image's edges), for (H, W[, C])."""
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        padded = np.concatenate([np.zeros_like(np.take(out, [0], axis=axis)), np.cumsum(out, axis=axis)], axis=axis)
        hi = np.minimum(np.arange(n) + radius + 1, n)
        lo = np.maximum(np.arange(n) - radius, 0)
        out = np.take(padded, hi, axis=axis) - np.take(padded, lo, axis=axis)
    return out


def keep_local_mean(denoised: np.ndarray, noisy: np.ndarray, weight: np.ndarray, radius: int) -> np.ndarray:
    """``denoised`` rescaled per channel so that its ``weight``-weighted local means over boxes of ``radius``
    pixels equal those of ``noisy`` (where the denoised local mean is zero, the noisy one is taken as it is).
    ``radius`` < 0 returns ``denoised`` unchanged."""
    if radius < 0:
        return denoised
    w = weight[..., None]
    target = box_sum(noisy * w, radius)
    got = box_sum(denoised * w, radius)
    scale = np.where(got > 1e-30, target / np.maximum(got, 1e-30), 1.0)
    out = np.where(got > 1e-30, denoised * scale, noisy)
    return np.maximum(out, 0.0).astype(np.float32)


def denoise(image: np.ndarray, coverage: np.ndarray, *, radius: int, quality: str = "high",
            device: str = "cpu") -> Denoised:
    """Denoise the (H, W, 3) radiance ``image`` guided by ``coverage`` (H, W, 3) in [0, 1], then restore its local
    means (see :func:`keep_local_mean`). Radiance is scaled to a mean of about 1 for the network and back. On a CUDA
    ``device`` Open Image Denoise runs there (:mod:`~warpsky.techniques.hybrid.oidn_device`, ``quality`` high),
    where it has a device; elsewhere on the CPU."""
    pyoidn = require_denoiser()
    started = time.perf_counter()
    color, count = sanitise(image)
    guide = np.clip(np.nan_to_num(coverage, nan=0.0), 0.0, 1.0).astype(np.float32)
    level = float(color.mean())
    if level <= 0.0:
        return Denoised(color, time.perf_counter() - started, count)
    scaled = np.ascontiguousarray(color / level, dtype=np.float32)
    out = None
    if not is_cpu(device):
        from warpsky.techniques.hybrid.oidn_device import denoise_on_device

        out = denoise_on_device(scaled, guide, device)
    if out is None:
        out = pyoidn.denoise(scaled, np.ascontiguousarray(guide), hdr=True, clean_aux=True, quality=quality)
    out = out * level
    out, _ = sanitise(out)
    out = keep_local_mean(out, color, np.ones(color.shape[:2]), radius)
    return Denoised(out, time.perf_counter() - started, count)


def block_mean(image: np.ndarray, scale: int) -> np.ndarray:
    """Mean over ``scale`` x ``scale`` blocks of (H, W, C) ``image``; blocks past the edge average what is inside."""
    height, width = image.shape[:2]
    rows, cols = -(-height // scale), -(-width // scale)
    padded = np.zeros((rows * scale, cols * scale, image.shape[2]), np.float64)
    count = np.zeros((rows * scale, cols * scale, 1), np.float64)
    padded[:height, :width] = image
    count[:height, :width] = 1.0
    sums = padded.reshape(rows, scale, cols, scale, -1).sum(axis=(1, 3))
    counts = count.reshape(rows, scale, cols, scale, 1).sum(axis=(1, 3))
    return (sums / counts).astype(np.float32)


def bilinear_upsample(image: np.ndarray, scale: int, height: int, width: int) -> np.ndarray:
    """(H, W, C) from the coarse (h, w, C) ``image`` whose pixel (r, c) covers fine pixels [r s, r s + s)^2:
    bilinear between coarse pixel centres, clamped at the edges."""
    def weights(n_fine, n_coarse):
        x = (np.arange(n_fine) + 0.5) / scale - 0.5
        x = np.clip(x, 0.0, n_coarse - 1.0)
        lo = np.minimum(np.floor(x).astype(np.int64), max(n_coarse - 2, 0))
        hi = np.minimum(lo + 1, n_coarse - 1)
        return lo, hi, (x - lo)[:, None]

    r0, r1, fr = weights(height, image.shape[0])
    c0, c1, fc = weights(width, image.shape[1])
    rows = image[r0] * (1.0 - fr[..., None]) + image[r1] * fr[..., None]
    return (rows[:, c0] * (1.0 - fc) + rows[:, c1] * fc).astype(np.float32)


def guided_upsample(coarse: np.ndarray, coverage: np.ndarray, scale: int) -> np.ndarray:
    """Fine radiance from ``coarse`` (each pixel the mean over a ``scale``-pixel block): the ratio of radiance to
    coverage is interpolated, then multiplied by the fine coverage, so silhouettes stay as sharp as the exact
    transmittance and each block keeps its mean where the ratio is smooth."""
    if scale == 1:
        return coarse
    height, width = coverage.shape[:2]
    coarse_coverage = block_mean(coverage, scale)
    ratio = np.where(coarse_coverage > 1e-4, coarse / np.maximum(coarse_coverage, 1e-4), 0.0)
    return np.maximum(bilinear_upsample(ratio, scale, height, width) * coverage, 0.0).astype(np.float32)
