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
from warpsky.techniques.hybrid.denoise import block_mean, box_sum

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


def kept_weights(history: ShotHistory, single: np.ndarray, coverage: np.ndarray, scale: int, weight: float,
                 tolerance: float) -> np.ndarray:
    """Per film pixel, the factor on the history's sums: ``weight`` where the frame did not change, 0 where its
    single scattering changed by more than ``tolerance`` (relative, against the mean of the two) or its coverage
    by more than :data:`COVERAGE_TOLERANCE` (see the module docstring)."""
    s_new, s_old = single @ LUMINANCE_WEIGHTS, history.single @ LUMINANCE_WEIGHTS
    level = np.maximum(0.5 * (s_new + s_old), 1e-6 * max(float(s_new.max()), 1e-30))
    changed = (np.abs(s_new - s_old) > tolerance * level) | (
        np.abs((coverage - history.coverage) @ LUMINANCE_WEIGHTS) > COVERAGE_TOLERANCE)
    if scale > 1:  # a film pixel changed where any of its frame pixels did
        changed = block_mean(changed[..., None].astype(np.float32), scale)[..., 0] > 0.0
    changed = box_sum(changed, CHANGE_MARGIN) > 0.0  # and within the margin of one that did (clipped at the edges)
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


@dataclass
class Reuse:
    """What a frame took from its shot's history (:func:`warm_start`), for :func:`keep_frame`."""

    key: tuple | None  # the shot (None: reuse is off)
    history: ShotHistory | None  # the history it started from (None: it started afresh)
    carried: np.ndarray | None  # per film pixel, the history's weighted paths it kept (both halves)
    first: int  # the path index the frame's own paths start at

    def stats(self) -> dict:
        """``reused_spp`` (the kept paths per film pixel, mean over the film) when reuse is on."""
        if self.key is None:
            return {}
        return {"reused_spp": round(float(np.mean(self.carried)), 2) if self.carried is not None else 0.0}


def warm_start(paths, single: np.ndarray, coverage: np.ndarray) -> Reuse:
    """Start ``paths`` (a :class:`~warpsky.techniques.hybrid.hybrid.MultipleScattering` before its first pass) from
    the previous frame of its shot, if reuse is on and there is one: its halves' sums and path counts weighted by
    :func:`kept_weights`."""
    settings = paths.settings
    if settings.temporal <= 0.0:
        return Reuse(None, None, None, 0)
    scene, width, height = paths.shot
    key = shot_key(scene, width, height, paths.scale, paths.device, settings)
    history = take(key)
    if history is None:
        return Reuse(key, None, None, 0)
    weights = kept_weights(history, single, coverage, paths.scale, float(settings.temporal),
                           float(settings.temporal_tolerance))
    for half in (0, 1):
        for field in KEPT_FIELDS:
            kept = history.sums[half][field]
            kept = kept * weights.reshape(weights.shape + (1,) * (kept.ndim - 2))
            getattr(paths.halves[half], field).assign(kept.astype(np.float32))
        paths.pixel_counts[half] += history.counts[half] * weights
    return Reuse(key, history, (history.counts[0] + history.counts[1]) * weights, history.paths)


def fine(film: np.ndarray, scale: int, height: int, width: int) -> np.ndarray:
    """Per film pixel values repeated over the (H, W) frame pixels each covers."""
    return np.repeat(np.repeat(film, scale, axis=0), scale, axis=1)[:height, :width]


def keep_frame(paths, reuse: Reuse, single: np.ndarray, coverage: np.ndarray, next_path: int) -> None:
    """Keep ``paths``' halves for the next frame of its shot (host copies of their sums and counts), with the
    single scattering and coverage of the frames they hold, each frame's weighted as its paths are; nothing when
    reuse is off."""
    if reuse.key is None:
        return
    sums = [{field: np.array(device_buffers.download(f"{STAGING_NAME}:{field}", getattr(paths.halves[half], field)))
             for field in KEPT_FIELDS} for half in (0, 1)]
    if reuse.history is not None and float(reuse.carried.max()) > 0.0:
        height, width = single.shape[:2]
        total = fine(paths.pixel_counts[0] + paths.pixel_counts[1], paths.scale, height, width)[..., None]
        old = fine(reuse.carried, paths.scale, height, width)[..., None] / np.maximum(total, 1e-30)
        single = old * reuse.history.single + (1.0 - old) * single
        coverage = old * reuse.history.coverage + (1.0 - old) * coverage
    keep(ShotHistory(reuse.key, sums, [count.copy() for count in paths.pixel_counts],
                     np.array(single, np.float32), np.array(coverage, np.float32), next_path))
