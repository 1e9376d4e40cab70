"""From a model's grid to the regular grid warpsky renders: staggered (Arakawa C) winds to cell centres, and
columns of terrain-following or stretched levels to regular heights, by linear interpolation along each column.

Both are exact for fields linear in the coordinate (tested against analytic fields): a C-grid's face values
average to the centre value, and linear interpolation between levels reproduces a linear profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError


def destagger(values: np.ndarray, axis: int) -> np.ndarray:
    """Cell-centre values of a field given on the cell faces along ``axis`` (one more point than the cells): the
    mean of the two faces of each cell."""
    values = np.asarray(values)
    count = values.shape[axis]
    lower = np.take(values, np.arange(count - 1), axis=axis)
    upper = np.take(values, np.arange(1, count), axis=axis)
    return 0.5 * (lower + upper)


def regular_levels(bottom: float, top: float, spacing: float) -> np.ndarray:
    """Cell-centre heights [m] of regular levels of ``spacing`` [m] filling [bottom, top]."""
    if not (spacing > 0.0) or not (top > bottom):
        raise SceneError(f"regular levels need spacing > 0 and top > bottom, got spacing {spacing!r}, bottom "
                         f"{bottom!r}, top {top!r}")
    count = max(1, int(np.ceil((top - bottom) / spacing - 1e-9)))
    return bottom + spacing * (np.arange(count) + 0.5)


def to_heights(values: np.ndarray, heights: np.ndarray, levels: np.ndarray, ground: np.ndarray | None = None
               ) -> np.ndarray:
    """Columns of ``values`` on their own ``heights`` resampled to the regular ``levels``.

    Args:
        values: (..., nk) values on each column's levels (any leading axes: x, y).
        heights: Heights [m] of those levels, increasing along the last axis; the shape of ``values`` or
            broadcastable to it (a 1-D stretched axis, say).
        levels: (nz,) target heights [m].
        ground: (...) ground height [m] of each column, or None. Below the ground the result is 0; between the
            ground and the lowest level it is the lowest level's value (the model's surface layer).

    Returns:
        (..., nz) values: linear between the two levels around each target height, 0 above the top level.
    """
    values = np.asarray(values, dtype=np.float64)
    return ColumnWeights.between(np.broadcast_to(heights, values.shape), levels, ground).apply(values)


@dataclass
class ColumnWeights:
    """Where each regular level falls in its column's model levels: computed once per time and grid, applied to
    every field (:meth:`apply`).

    Attributes:
        lower: (..., nz) index of the model level at or below each target height (clipped to 0 .. nk - 2).
        weight: (..., nz) linear weight of the level above, in [0, 1].
        keep: (..., nz) False above the top level and under the ground (the result there is 0).
    """

    lower: np.ndarray
    weight: np.ndarray
    keep: np.ndarray

    @classmethod
    def between(cls, heights: np.ndarray, levels: np.ndarray, ground: np.ndarray | None = None) -> ColumnWeights:
        """The weights of columns whose model levels are at ``heights`` [m] (..., nk), increasing along the last
        axis, for the regular ``levels`` (nz,) [m], with each column's ``ground`` (...) [m] or None."""
        heights = np.asarray(heights, dtype=np.float64)
        levels = np.asarray(levels, dtype=np.float64)
        nk = heights.shape[-1]
        if nk < 2:
            raise SceneError(f"resampling to heights needs at least 2 levels per column, got {nk}")
        if np.any(np.diff(heights, axis=-1) <= 0.0):
            raise SceneError("model level heights must increase upwards in every column")
        # model levels strictly below each target height, counted per column without comparing every pair: model
        # level k lies below the targets from starts[k] on (a histogram of starts, summed up the column)
        starts = np.searchsorted(levels, heights, side="right")
        counts = np.zeros((*heights.shape[:-1], len(levels) + 1), dtype=np.int32)
        for k in range(nk):
            index = starts[..., k:k + 1]
            np.put_along_axis(counts, index, np.take_along_axis(counts, index, axis=-1) + 1, axis=-1)
        below = np.cumsum(counts[..., :-1], axis=-1)
        lower = np.clip(below - 1, 0, nk - 2)
        z0 = np.take_along_axis(heights, lower, axis=-1)
        z1 = np.take_along_axis(heights, lower + 1, axis=-1)
        weight = np.clip((levels - z0) / (z1 - z0), 0.0, 1.0)
        keep = below < nk
        if ground is not None:
            keep &= levels >= np.asarray(ground, dtype=np.float64)[..., None]
        return cls(lower, weight, keep)

    def apply(self, values: np.ndarray) -> np.ndarray:
        """(..., nk) values on the model levels -> (..., nz) on the regular levels."""
        values = np.asarray(values, dtype=np.float64)
        v0 = np.take_along_axis(values, self.lower, axis=-1)
        v1 = np.take_along_axis(values, self.lower + 1, axis=-1)
        return np.where(self.keep, v0 + self.weight * (v1 - v0), 0.0)


def default_spacing(heights: np.ndarray, bottom: float, top: float, max_levels: int = 256) -> float:
    """The vertical spacing [m] of the regular grid when none is asked: the finest spacing of the domain-mean
    column's levels (no detail lost), coarsened if needed to keep at most ``max_levels`` levels."""
    mean = np.asarray(heights, dtype=np.float64).reshape(-1, np.shape(heights)[-1]).mean(axis=0)
    finest = float(np.min(np.diff(mean)))
    return max(finest, (top - bottom) / max_levels)
