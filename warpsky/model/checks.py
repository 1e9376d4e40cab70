"""Validation shared by the scene's dataclasses and their readers."""

from __future__ import annotations

import numpy as np

from warpsky.core.errors import SceneError


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


def float_array_attr(prim, name: str, tc, width: int) -> np.ndarray | None:
    """An authored ``float[]`` (width 1) or ``floatN[]`` (width N) attribute as a (count,) / (count, N) float64
    array of finite values, or None when unauthored; anything else is a SceneError naming the prim and attribute."""
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return None
    value = attr.Get(tc)
    try:
        array = np.array(value if value is not None else [], dtype=np.float64)
        array = array.reshape(-1) if width == 1 else array.reshape(-1, width)
    except (TypeError, ValueError):
        kind = "float[]" if width == 1 else f"float{width}[]"
        raise SceneError(f"{prim.GetPath()}.{name} must be a {kind}, got {value!r}") from None
    if not np.all(np.isfinite(array)):
        raise SceneError(f"{prim.GetPath()}.{name} must hold finite numbers, got {array.tolist()}")
    return array
