"""The part of the hybrid's error that its two-halves estimate cannot see: the denoiser's own bias.

The paths run in two independent halves A and B. Their denoised images D(A) and D(B) differ by their noise alone,
so RMS(D(A) - D(B)) / 2 measures the denoised whole's noise, but not what both share: the denoiser's blur of the
clouds' structure. That bias does not fall with more paths the way the noise does, so at high path counts it is
most of the error (on the demo's cloud under its sun, 128 x 128 at 4,096 paths per pixel: an estimate of 3.3 % where
the measured error was 6.1 %).

The raw half B is an unbiased estimate of the light L, independent of D(A), with a per-pixel variance V(B) known
from its paths. Hence E |D(A) - B|^2 - V(B) = E |D(A) - L|^2, the mean squared error of a denoised half, measured
without a reference. Less the denoised half's noise, E |D(A) - D(B)|^2 / 2, it leaves the squared bias. Where the
raw halves are noisy this difference of large numbers is itself noisy, so only the part of the squared bias above
two standard errors of its mean over the covered pixels (a one-sided 97.7 % bound, for Gaussian means) is counted;
below that it is zero and the calibrated estimate stands. A half's bias is at least the whole's (the denoiser blurs
noisier input more), so the bound leans high.
"""

from __future__ import annotations

import math

import numpy as np

#: Standard errors of the mean below which a measured squared bias is not counted.
BIAS_STANDARD_ERRORS = 2.0


def relative_rms(spread: np.ndarray, covered: np.ndarray, level: float) -> float:
    """RMS of ``spread`` (H, W, C) over the ``covered`` (H, W) pixels, relative to ``level``."""
    return float(np.sqrt(np.mean(spread[covered].astype(np.float64) ** 2)) / level)


def with_denoiser_bias(raw: tuple[np.ndarray, np.ndarray], variance: tuple[np.ndarray, np.ndarray],
                       denoised: tuple[np.ndarray, np.ndarray], covered: np.ndarray, level: float) -> float:
    """Relative RMSE of the denoised whole (noise and the denoiser's bias, see the module docstring) over the
    ``covered`` (H, W) pixels, relative to ``level``, from the two halves' raw means, the variances of those means
    and their denoised images (each (H, W, C))."""
    if level <= 0.0 or not covered.any():
        return 0.0
    a, b = (np.asarray(x, np.float64)[covered] for x in raw)
    va, vb = (np.asarray(x, np.float64)[covered] for x in variance)
    da, db = (np.asarray(x, np.float64)[covered] for x in denoised)
    half_noise = float(np.mean((da - db) ** 2)) / 2.0  # the variance of one denoised half
    terms = (0.5 * (((da - b) ** 2 - vb) + ((db - a) ** 2 - va))).mean(axis=-1)  # per pixel: a half's squared error
    squared_bias = float(terms.mean()) - half_noise
    standard_error = float(terms.std()) / math.sqrt(terms.size)
    counted = max(squared_bias - BIAS_STANDARD_ERRORS * standard_error, 0.0)
    return math.sqrt(half_noise / 2.0 + counted) / level


def denoised_estimate(halves: list, denoised: tuple, single: np.ndarray, covered: np.ndarray, counts: list) -> float:
    """:func:`with_denoiser_bias` on the paths' film: ``halves`` each half's (raw mean, variance of that mean),
    ``denoised`` their denoised images, ``single`` the single scattering on the film (the frame's level),
    ``covered`` the film pixels measured and ``counts`` each half's paths per film pixel; 0 until every measured
    pixel has two paths in each half (a variance needs two)."""
    if not covered.any() or min(float(count[covered].min()) for count in counts) < 2.0:
        return 0.0
    level = float((single + 0.5 * (denoised[0] + denoised[1]))[covered].mean())
    raw, variances = zip(*halves, strict=True)
    return with_denoiser_bias(raw, variances, denoised, covered, level)
