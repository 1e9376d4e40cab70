"""Temporal reuse of the multiple-scattering paths between consecutive frames of one shot.

Frames of an animation rendered one after another in one process (the batch executors do) see nearly the same
multiple scattering where the scene moved little: light scattered many times is smooth, and it changes with the
density only. With ``temporal`` = lambda > 0 the hybrid keeps each frame's two halves of path sums on the host and
starts the next frame of the same shot (same camera, image size, film and settings) from them, every pixel's sums
and path counts multiplied by lambda, so a frame carries an exponentially weighted history of lambda^k of the paths
of the frame k before it (at most 1 / (1 - lambda) frames' worth). The new paths continue the shot's path indices,
so their random streams never repeat the history's.

The history is dropped per pixel where the frame changed: where the noise-free single scattering or the coverage
1 - T of the march differ by more than the setting ``temporal_tolerance`` (relative) or :data:`COVERAGE_TOLERANCE`
from those of the frames the history holds (their mean, each frame weighted as its paths are, so a slow drift is
caught once it adds up), widened by :data:`CHANGE_MARGIN` film pixels (multiple scattering reaches past the pixels
whose density changed). What it keeps is a lag: the light of the last frames where their single scattering differed
by less than that. The error estimate sees the halves' noise (history included), not the lag. A different camera,
size, film, light or device starts afresh, and a frame rendered first or alone is exactly the frame without reuse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpsky.core import device_buffers
from warpsky.core.numerics import LUMINANCE_WEIGHTS

#: Change of a pixel's coverage (luminance) above which its history is dropped.
COVERAGE_TOLERANCE = 0.02
#: Film pixels around a changed pixel whose history is dropped too.
CHANGE_MARGIN = 2
#: Host bytes of a kept history per film pixel and per frame pixel, counting the previous frame's still held while
#: the next is kept: 2 x (both halves' sums, 2 x 44, and counts, 2 x 4) and 2 x (single scattering and coverage,
#: float32 RGB).
HISTORY_FILM_BYTES = 192
HISTORY_PIXEL_BYTES = 48


@dataclass
class ShotHistory:
    """What one frame leaves to the next frame of its shot."""

    key: tuple
    sums: list[dict[str, np.ndarray]]  # per half: the path sums' fields (host copies)
    counts: list[np.ndarray]  # per half: paths per film pixel (weighted)
    single: np.ndarray  # (H, W, 3) the single scattering of the frames in the sums, weighted as their paths
    coverage: np.ndarray  # (H, W, 3) their coverage 1 - T, weighted alike
    paths: int  # path indices per pixel the shot has used: the next frame's paths start here


_last: ShotHistory | None = None


def shot_key(scene, width: int, height: int, scale: int, device: str, settings) -> tuple:
    """What must be equal for one frame to reuse another's paths: the camera, the image and its film, the device,
    the lights and the settings (the seed, the stopping rule and the reuse weight aside)."""
    fixed = {k: v for k, v in vars(settings).items()
             if k not in ("seed", "spp", "target_error", "time_budget", "temporal", "temporal_tolerance")}
    lights = (repr(scene.sun), repr(scene.extra_suns), repr(scene.dome))
    return (repr(scene.camera), lights, width, height, scale, str(device), repr(sorted(fixed.items())))


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """``mask`` (H, W, bool) grown by ``radius`` pixels (a square; nothing wraps around the edges)."""
    height, width = mask.shape
    padded = np.zeros((height + 2 * radius, width + 2 * radius), bool)
    padded[radius:radius + height, radius:radius + width] = mask
    out = np.zeros_like(mask)
    for dy in range(2 * radius + 1):
        for dx in range(2 * radius + 1):
            out |= padded[dy:dy + height, dx:dx + width]
    return out


def kept_weights(history: ShotHistory, single: np.ndarray, coverage: np.ndarray, scale: int, weight: float,
                 tolerance: float) -> np.ndarray:
    """Per film pixel, the factor on the history's sums: ``weight`` where the frame did not change, 0 where its
    single scattering changed by more than ``tolerance`` (relative, against the mean of the two) or its coverage
    by more than :data:`COVERAGE_TOLERANCE` (see the module docstring)."""
    s_new, s_old = single @ LUMINANCE_WEIGHTS, history.single @ LUMINANCE_WEIGHTS
    level = np.maximum(0.5 * (s_new + s_old), 1e-6 * max(float(s_new.max()), 1e-30))
    changed = (np.abs(s_new - s_old) > tolerance * level) | (
        np.abs((coverage - history.coverage) @ LUMINANCE_WEIGHTS) > COVERAGE_TOLERANCE)
    if scale > 1:
        height, width = changed.shape
        rows, cols = -(-height // scale), -(-width // scale)
        padded = np.zeros((rows * scale, cols * scale), bool)
        padded[:height, :width] = changed
        changed = padded.reshape(rows, scale, cols, scale).any(axis=(1, 3))
    changed = dilate(changed, CHANGE_MARGIN)
    return np.where(changed, 0.0, weight).astype(np.float32)


def take(key: tuple) -> ShotHistory | None:
    """The previous frame's history when it belongs to the shot ``key``."""
    return _last if _last is not None and _last.key == key else None


def keep(history: ShotHistory) -> None:
    global _last
    _last = history


def forget() -> None:
    """Drop the kept history (the next frame starts afresh)."""
    global _last
    _last = None


#: The path sums' fields a frame leaves to the next (the tracking counters stay the frame's own).
KEPT_FIELDS = ("radiance_sum", "radiance_sq", "transmittance_sum", "depth_sum")
#: Name of the host staging of the kept sums' downloads (:func:`warpsky.core.device_buffers.download`).
STAGING_NAME = "hybrid:history"


def warm_start(paths, single: np.ndarray, coverage: np.ndarray) -> int:
    """Start ``paths`` (a :class:`~warpsky.techniques.hybrid.hybrid.MultipleScattering` before its first pass) from
    the previous frame of its shot, if any: its halves' sums and path counts weighted by :func:`kept_weights`.
    Returns the path index the frame's own paths start at (0 without a history); ``paths.reused_spp`` is the
    weighted paths per film pixel it carries over (mean over the film)."""
    scene, width, height = paths.shot
    paths.history_key = shot_key(scene, width, height, paths.scale, paths.device, paths.settings)
    history = take(paths.history_key)
    paths.reused_spp = 0.0
    if history is None:
        return 0
    settings = paths.settings
    weights = kept_weights(history, single, coverage, paths.scale, float(settings.temporal),
                           float(settings.temporal_tolerance))
    paths.carried = (history.counts[0] + history.counts[1]) * weights
    for half in (0, 1):
        for field in KEPT_FIELDS:
            kept = history.sums[half][field]
            kept = kept * weights.reshape(weights.shape + (1,) * (kept.ndim - 2))
            getattr(paths.halves[half], field).assign(kept.astype(np.float32))
        paths.pixel_counts[half] += history.counts[half] * weights
    paths.reused_spp = float(np.mean(paths.carried))
    return history.paths


def fine(film: np.ndarray, scale: int, height: int, width: int) -> np.ndarray:
    """Per film pixel values repeated over the (H, W) frame pixels each covers."""
    return np.repeat(np.repeat(film, scale, axis=0), scale, axis=1)[:height, :width]


def keep_frame(paths, single: np.ndarray, coverage: np.ndarray, next_path: int) -> None:
    """Keep ``paths``' halves for the next frame of its shot (host copies of their sums and counts), with the
    single scattering and coverage of the frames they hold, each frame's weighted as its paths are."""
    sums = [{field: np.array(device_buffers.download(f"{STAGING_NAME}:{field}", getattr(paths.halves[half], field)))
             for field in KEPT_FIELDS} for half in (0, 1)]
    history = take(paths.history_key)
    if history is not None and float(paths.carried.max()) > 0.0:
        height, width = single.shape[:2]
        total = fine(paths.pixel_counts[0] + paths.pixel_counts[1], paths.scale, height, width)[..., None]
        old = fine(paths.carried, paths.scale, height, width)[..., None] / np.maximum(total, 1e-30)
        single = old * history.single + (1.0 - old) * single
        coverage = old * history.coverage + (1.0 - old) * coverage
    keep(ShotHistory(paths.history_key, sums, [count.copy() for count in paths.pixel_counts],
                     np.array(single, np.float32), np.array(coverage, np.float32), next_path))
