"""How the hybrid keeps a time budget: the frame's wall time, from its stage read to its EXR written.

The paths are the frame's one adjustable part, so they get what the budget leaves (:class:`PathBudget`): the
budget counted from the frame's start (:mod:`warpsky.core.deadline`; from the technique's own start when it runs
outside a frame), less what will follow them: the final denoise (timed at the error estimate's denoises of the
same film, else :data:`DENOISE_PRIOR_PER_PIXEL`), and the passes, composite and write after the technique (timed in
the last frame of the same shape in this process, else :data:`AFTER_PRIOR_SECONDS` plus
:data:`AFTER_PRIOR_PER_PIXEL` per pixel). A pass of paths starts only when the time measured for the last one fits
before that deadline.

A sub-frame of a frame with motion blur takes its share of what is left
(:class:`~warpsky.core.deadline.FrameClock` ``parts_left``). The two first passes (one per half of the error
estimate) always run. Where they would not fit, the paths run on a coarser film (:func:`film_scale`: pixels 2, 4 or
8 times larger, as ``ms_scale``), chosen from the time a probe of one path per pixel on the coarsest film took; the
frame then says so in a warning. Between error estimates the passes run to :func:`next_check`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import warp as wp

from warpsky.core import deadline
from warpsky.core.device import is_cpu
from warpsky.techniques.path_tracer.path_tracer import pixel_sums

#: Seconds after the hybrid's paths in a first frame (the sky pass, the composite, the EXR and PNG): the constant
#: part, measured on the shipped stages at 96 x 64 on 2 CPU cores (0.1-0.15 s), and per pixel (the sky pass and
#: composite at 384 x 256 added about 2.5 us a pixel).
AFTER_PRIOR_SECONDS = 0.15
AFTER_PRIOR_PER_PIXEL = 3.0e-6
#: Seconds per film pixel of Open Image Denoise's filter before one was timed in this frame (2 CPU cores).
DENOISE_PRIOR_PER_PIXEL = 2.0e-6
#: The two first passes get at most this share of the time left, so that the frame keeps room for more.
FIRST_PASSES_SHARE = 0.6
#: Film scales the paths may fall back on under a budget (pixels this many times larger).
SCALES = (1, 2, 4, 8)

#: What ``ms_scale`` auto means, as the settings print it.
AUTO_FILM = ("the coarsest of 1, 2, 4 and 8 whose film keeps at least 480 pixels along the frame's longer side (1 "
             "below 960: on the demo cumulus at 384x256 1x1 pixels measured best, at 1920x1080 4x4 ones: 27 s to "
             "2.6% against 43 s to 3.9%)")
#: Under ``ms_scale`` auto the paths' film keeps at least this many pixels along the frame's longer side.
AUTO_FILM_PIXELS = 480


def paths_film_scale(asked: int | None, width: int, height: int) -> int:
    """The paths' film scale of a ``width`` x ``height`` frame: ``asked``, or with None :data:`AUTO_FILM`."""
    if asked is not None:
        return int(asked)
    return max((scale for scale in SCALES if max(width, height) >= AUTO_FILM_PIXELS * scale), default=1)


@dataclass
class PathBudget:
    """When the hybrid's paths must stop, and what the last pass took."""

    deadline: float  # perf_counter time by which the paths, the final denoise included, are done
    denoise_per_pixel: float  # seconds of one denoise per film pixel (timed once an estimate ran)
    pass_seconds: float = 0.0  # the last pass of paths

    @classmethod
    def of(cls, budget: float, started: float, pixels: int, device: str) -> PathBudget:
        """The paths' deadline for a ``budget`` [s] of the frame (``started``: the technique's own start, used
        outside a frame) on a frame of ``pixels`` pixels."""
        clock = deadline.current()
        start = started if clock is None else clock.started
        after = deadline.expected_after(clock)
        if after is None:
            after = AFTER_PRIOR_SECONDS + AFTER_PRIOR_PER_PIXEL * pixels * (1.0 if is_cpu(device) else 0.1)
        end = start + float(budget) - after
        if clock is not None and clock.parts_left > 1:  # a sub-frame: its share of what is left
            now = time.perf_counter()
            end = now + (end - now) / clock.parts_left
        return cls(end, DENOISE_PRIOR_PER_PIXEL if is_cpu(device) else 0.0)

    def left(self, film_pixels: int) -> float:
        """Seconds the paths may still run on a film of ``film_pixels`` pixels (the final denoise kept aside)."""
        return self.deadline - time.perf_counter() - self.denoise_per_pixel * film_pixels

    def next_pass_fits(self, film_pixels: int) -> bool:
        """Whether one more pass, as long as the last one, ends before the deadline."""
        return self.pass_seconds <= self.left(film_pixels)


def timed_denoise(budget: PathBudget | None, seconds: float, film_pixels: int) -> None:
    """Record that a denoise of a ``film_pixels``-pixel film took ``seconds``."""
    if budget is not None and film_pixels > 0:
        budget.denoise_per_pixel = max(seconds / film_pixels, 0.0)


def film_scale(tracing, budget: PathBudget, per_pass: int, smallest: int, device: str) -> int:
    """The film scale for paths that must fit ``budget``: ``smallest`` (the scale asked), else the
    finest of the larger :data:`SCALES`, whose two first passes of ``per_pass`` paths per pixel fit
    :data:`FIRST_PASSES_SHARE` of the time left, timed by one path per pixel on the coarsest film (a probe whose
    paths are not kept)."""
    coarsest = tracing.rescaled(SCALES[-1])
    sums = pixel_sums((coarsest.height, coarsest.width), device)
    started = time.perf_counter()
    coarsest.launch(sums, 0, 1)
    wp.synchronize_device(device)
    per_path = (time.perf_counter() - started) / max(coarsest.width * coarsest.height, 1)
    width, height = tracing.frame_size
    for scale in (smallest, *(s for s in SCALES if s > smallest)):  # the scale asked first, whatever it is
        pixels = -(-width // scale) * -(-height // scale)
        if 2 * per_pass * pixels * per_path <= FIRST_PASSES_SHARE * budget.left(pixels):
            return scale
    return SCALES[-1]


def coverage_scale_warning(scale: int, asked: int) -> list[str]:
    """The warning of a frame whose paths ran on a coarser film than ``ms_scale`` asked, to fit its budget."""
    if scale <= asked:
        return []
    return [f"hybrid traced multiple scattering on pixels {scale}x larger than the frame's (ms_scale = {scale}, "
            f"asked {asked}) to fit the time budget"]


def next_check(passes: int, estimate: float, target: float) -> int:
    """The (even) pass count at which to estimate the error again: where noise falling as 1/sqrt(paths) would meet
    the target (10% beyond), at least two passes on and at most twice as many as now, so a few estimates suffice
    and a wrong guess costs at most a doubling."""
    wanted = passes * (estimate / target) ** 2 * 1.1 if math.isfinite(estimate) else 2 * passes
    step = int(math.ceil(min(max(wanted, passes + 2), 2 * passes)))
    return step + step % 2
