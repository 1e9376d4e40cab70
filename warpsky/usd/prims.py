"""What every part of :class:`~warpsky.usd.stage.StageReader` shares: time codes, world transforms, visibility and
purpose, prims by schema, and typed attribute reads whose :class:`SceneError` names the prim and the attribute.

Every traversal goes through :meth:`StagePrims._traverse`: USD's default predicate (active, defined, loaded,
non-abstract prims: ``active = false`` and unloaded payloads drop out with their subtrees) plus instance proxies,
so each instance of an instanceable prim is read at its own path and transform.

pxr is imported inside the methods (a heavy import), so importing this module stays cheap.
"""

from __future__ import annotations

import math

import numpy as np

from warpsky.core.errors import SceneError


def _matrix(gf_matrix) -> np.ndarray:
    """Gf.Matrix4d (row vectors, p' = p M) as a column-vector numpy matrix."""
    return np.array(gf_matrix, dtype=np.float64).reshape(4, 4).T


class StagePrims:
    """Base of the stage reader's parts. The reader sets ``stage``, ``path``, ``options`` (a
    :class:`~warpsky.usd.composition.StageOptions`), ``up_axis``, ``meters_per_unit``, ``world_from_stage``
    (warpsky's Y-up metres from stage space) and the ``_field_cache`` / ``_map_cache`` dicts."""

    # ------------------------------------------------------------------------------------- time and prims
    @staticmethod
    def _time(time):
        from pxr import Usd

        return Usd.TimeCode.EarliestTime() if time is None else Usd.TimeCode(float(time))

    def _world(self, prim, time) -> np.ndarray:
        from pxr import UsdGeom

        return self.world_from_stage @ _matrix(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time))

    def _visible(self, prim, time) -> bool:
        from pxr import UsdGeom

        imageable = UsdGeom.Imageable(prim)
        return not imageable or imageable.ComputeVisibility(time) != UsdGeom.Tokens.invisible

    def _rendered(self, prim, time) -> bool:
        """Visible at ``time`` and of a purpose the options render (for geometry; lights and cameras ignore purpose,
        as in Hydra)."""
        from pxr import UsdGeom

        imageable = UsdGeom.Imageable(prim)
        if imageable and str(imageable.ComputePurpose()) not in self.options.purposes:
            return False
        return self._visible(prim, time)

    def _traverse(self):
        """The stage's prims, depth first, without the pseudo-root: active, defined, loaded, non-abstract, and
        instance proxies (the prims inside each instance of an instanceable prim, at their own paths)."""
        from pxr import Usd

        return self.stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))

    def _prims_of(self, schema) -> list:
        return [p for p in self._traverse() if p.IsA(schema)]

    # ------------------------------------------------------------------------------------------ attributes
    @staticmethod
    def _float_attr(prim, name: str, tc, default: float) -> float:
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return default
        value = attr.Get(tc)
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SceneError(f"{prim.GetPath()}.{name} must be a finite float, got {value!r}")
        return float(value)

    @staticmethod
    def _token_attr(prim, name: str, tc, default: str) -> str:
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return default
        return str(attr.Get(tc)).strip().lower()

    @staticmethod
    def _color_attr(prim, name: str, tc) -> np.ndarray | None:
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return None
        value = attr.Get(tc)
        try:
            return np.array(value, dtype=np.float64).reshape(3) if not isinstance(value, float) else np.full(3, value)
        except (TypeError, ValueError):
            raise SceneError(f"{prim.GetPath()}.{name} must be a color3f, got {value!r}") from None

    @staticmethod
    def _vector_attr(prim, name: str, tc, size: int, shape: str, values: str,
                     positive: bool = False) -> np.ndarray | None:
        """An authored vector of ``size`` finite (and, with ``positive``, > 0) floats, or None when unauthored; the
        SceneError says ``must be {shape}`` or ``must be {values}``."""
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return None
        value = attr.Get(tc)
        try:
            vector = np.array(value, dtype=np.float64).reshape(size)
        except (TypeError, ValueError):
            raise SceneError(f"{prim.GetPath()}.{name} must be {shape}, got {value!r}") from None
        if not np.all(np.isfinite(vector)) or (positive and np.any(vector <= 0.0)):
            raise SceneError(f"{prim.GetPath()}.{name} must be {values}, got {value!r}")
        return vector

    @classmethod
    def _positive2(cls, prim, name: str, tc, default) -> np.ndarray:
        pair = cls._vector_attr(prim, name, tc, 2, "a float2 of lengths [scene units]",
                                "two positive lengths [scene units]", positive=True)
        return np.asarray(default, dtype=np.float64) if pair is None else pair

    @staticmethod
    def _int_attr(prim, name: str, tc, default: int) -> int:
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return default
        value = attr.Get(tc)
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{prim.GetPath()}.{name} must be an int, got {value!r}")
        return int(value)

    @staticmethod
    def _bool_attr(prim, name: str, tc, default: bool) -> bool:
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return default
        value = attr.Get(tc)
        if not isinstance(value, bool):
            raise SceneError(f"{prim.GetPath()}.{name} must be a bool, got {value!r}")
        return value
