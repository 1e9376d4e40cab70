"""Validation shared by the scene's dataclasses."""

from __future__ import annotations

import numpy as np

from warpsky.errors import SceneError


def _vec3(value, name: str, *, unit: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise SceneError(f"{name} must be 3 finite numbers, got {value!r}")
    if unit:
        norm = float(np.linalg.norm(arr))
        if norm == 0.0:
            raise SceneError(f"{name} must be a non-zero direction, got {value!r}")
        arr = arr / norm
    return arr
