"""From a model's grid to the regular grid warpsky renders: staggered (Arakawa C) winds to cell centres, and
columns of terrain-following or stretched levels to regular heights, by linear interpolation along each column.

Both are exact for fields linear in the coordinate (tested against analytic fields): a C-grid's face values
average to the centre value, and linear interpolation between levels reproduces a linear profile.
"""

from __future__ import annotations

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
    heights = np.broadcast_to(np.asarray(heights, dtype=np.float64), values.shape)
    nk = values.shape[-1]
    if nk < 2:
        raise SceneError(f"resampling to heights needs at least 2 levels per column, got {nk}")
    if np.any(np.diff(heights, axis=-1) <= 0.0):
        raise SceneError("model level heights must increase upwards in every column")
    out = np.zeros((*values.shape[:-1], len(levels)))
    for index, level in enumerate(np.asarray(levels, dtype=np.float64)):
        below = np.count_nonzero(heights < level, axis=-1)  # levels strictly below the target, 0..nk
        k0 = np.clip(below - 1, 0, nk - 2)[..., None]
        z0 = np.take_along_axis(heights, k0, axis=-1)[..., 0]
        z1 = np.take_along_axis(heights, k0 + 1, axis=-1)[..., 0]
        weight = np.clip((level - z0) / (z1 - z0), 0.0, 1.0)
        v0 = np.take_along_axis(values, k0, axis=-1)[..., 0]
        v1 = np.take_along_axis(values, k0 + 1, axis=-1)[..., 0]
        column = v0 + weight * (v1 - v0)
        column = np.where(below >= nk, 0.0, column)  # above the top level
        if ground is not None:
            column = np.where(level < np.asarray(ground), 0.0, column)
        out[..., index] = column
    return out


def default_spacing(heights: np.ndarray, bottom: float, top: float, max_levels: int = 256) -> float:
    """The vertical spacing [m] of the regular grid when none is asked: the finest spacing of the domain-mean
    column's levels (no detail lost), coarsened if needed to keep at most ``max_levels`` levels."""
    mean = np.asarray(heights, dtype=np.float64).reshape(-1, np.shape(heights)[-1]).mean(axis=0)
    finest = float(np.min(np.diff(mean)))
    return max(finest, (top - bottom) / max_levels)
