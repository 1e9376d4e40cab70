"""Horizontal surfaces of a stage: the ground plane (``UsdGeomPlane``, with an optional albedo texture) and the
stratiform cloud layers (prims with ``warpsky:kind = "stratiformLayer"``, thickness maps and advection).

pxr is imported inside the methods (a heavy import).
"""

from __future__ import annotations

import os

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.media.stratiform.thickness import PROCEDURAL_RESOLUTION, load_map, procedural_thickness
from warpsky.model.scene import Ground
from warpsky.model.stratiform import GroundTexture, StratiformLayer, ThicknessAdvection
from warpsky.usd.generated_data import missing_asset_hint
from warpsky.usd.prims import StagePrims

#: ``warpsky:kind`` of a stratiform layer prim, and the attributes such a prim may carry.
LAYER_KIND = "stratiformLayer"
LAYER_ATTRIBUTES = frozenset(
    [f"warpsky:stratiform:{n}" for n in ("thicknessMap", "thicknessScale", "size", "cover", "maxThickness", "seed",
                                         "numberDensity", "effectiveRadius", "radiosity")]
    + [f"warpsky:advection:{n}" for n in ("wind", "curlSpeed", "curlScale", "period", "seed")]
)


class SurfaceReading(StagePrims):
    """The stage reader's ground plane and stratiform layers."""

    # ---------------------------------------------------------------------------------------------- ground
    def read_ground(self, time=None) -> Ground | None:
        from pxr import UsdGeom

        tc = self._time(time)
        for prim in self._prims_of(UsdGeom.Plane):
            if not self._rendered(prim, tc):
                continue
            plane = UsdGeom.Plane(prim)
            axis = {"X": 0, "Y": 1, "Z": 2}[str(plane.GetAxisAttr().Get(tc))]
            world = self._world(prim, tc)
            normal = world[:3, :3] @ np.eye(3)[axis]
            normal = normal / np.linalg.norm(normal)
            if abs(normal[1]) < 1.0 - 1e-6:
                raise SceneError(
                    f"ground plane {prim.GetPath()}: must be horizontal (normal along the stage's up axis), "
                    f"its normal is {np.round(normal, 4).tolist()} in Y-up world space"
                )
            albedo = self._color_attr(prim, "warpsky:albedo", tc)
            if albedo is None:
                display = UsdGeom.Gprim(prim).GetDisplayColorAttr().Get(tc)
                albedo = np.array(display[0], dtype=np.float64) if display else np.full(3, 0.3)
            return Ground(float(world[1, 3]), albedo, str(prim.GetPath()), self._albedo_map(prim, tc, world))
        return None

    # ------------------------------------------------------------------------------------ stratiform layers
    def read_stratiform_layers(self, time=None) -> tuple:
        """Visible prims of a rendered purpose with ``uniform token warpsky:kind = "stratiformLayer"`` as
        :class:`~warpsky.model.stratiform.StratiformLayer` at ``time`` (the attribute table is on that class)."""
        from pxr import UsdGeom

        tc = self._time(time)
        time_s = 0.0 if time is None else float(time) / float(self.stage.GetTimeCodesPerSecond())
        layers = []
        for prim in self._traverse():
            names = {a.GetName() for a in prim.GetAttributes()}
            ours = {n for n in names if n.startswith(("warpsky:stratiform:", "warpsky:advection:"))}
            kind = prim.GetAttribute("warpsky:kind")
            kind = str(kind.Get(tc)) if kind and kind.HasAuthoredValue() else None
            if kind != LAYER_KIND:
                if ours:
                    raise SceneError(f"{prim.GetPath()}: has {sorted(ours)[0]} but warpsky:kind is {kind!r}; "
                                     f"expected uniform token warpsky:kind = \"{LAYER_KIND}\" on a layer prim")
                continue
            unknown = sorted(ours - LAYER_ATTRIBUTES)
            if unknown:
                raise SceneError(f"stratiform layer {prim.GetPath()}: unknown attribute(s) {', '.join(unknown)}; "
                                 f"known: {', '.join(sorted(LAYER_ATTRIBUTES))}")
            if not prim.IsA(UsdGeom.Xformable):
                raise SceneError(f"stratiform layer {prim.GetPath()}: must be an Xformable prim (e.g. Xform) whose "
                                 f"translation places the cloud base, got {prim.GetTypeName() or 'a typeless prim'}")
            if self._rendered(prim, tc):
                layers.append(self._read_layer(prim, tc, time_s))
        return tuple(layers)

    def _read_layer(self, prim, tc, time_s: float):
        path = str(prim.GetPath())
        mpu = self.meters_per_unit
        world = self._world(prim, tc)
        size = self._positive2(prim, "warpsky:stratiform:size", tc, (1e4 / mpu, 1e4 / mpu)) * mpu
        thickness = self._thickness_map(prim, tc)
        numbers = {}
        for attr, default in (("numberDensity", 3e8), ("effectiveRadius", 7e-6)):
            numbers[attr] = self._float_attr(prim, f"warpsky:stratiform:{attr}", tc, default)
            if numbers[attr] <= 0.0:
                raise SceneError(f"{path}.warpsky:stratiform:{attr} must be > 0, got {numbers[attr]}")
        radiosity = self._bool_attr(prim, "warpsky:stratiform:radiosity", tc, True)
        centre = world[:3, 3]
        try:
            return StratiformLayer(
                thickness, float(centre[1]), (float(centre[0] - size[0] / 2), float(centre[2] - size[1] / 2)),
                (float(size[0]), float(size[1])), numbers["numberDensity"], numbers["effectiveRadius"], path,
                radiosity, self._advection(prim, tc), time_s)
        except SceneError as exc:
            raise SceneError(f"{path}: {exc}") from None

    def _thickness_map(self, prim, tc) -> np.ndarray:
        """The layer's map [m]: a file times thicknessScale, else a procedural map (both cached)."""
        path = str(prim.GetPath())
        attr = prim.GetAttribute("warpsky:stratiform:thicknessMap")
        if attr and attr.HasAuthoredValue():
            for name in ("cover", "maxThickness", "seed"):
                if prim.GetAttribute(f"warpsky:stratiform:{name}").HasAuthoredValue():
                    raise SceneError(f"{path}.warpsky:stratiform:{name} applies to procedural maps only; remove it "
                                     "or warpsky:stratiform:thicknessMap")
            scale = self._float_attr(prim, "warpsky:stratiform:thicknessScale", tc, 1.0)
            if scale < 0.0:
                raise SceneError(f"{path}.warpsky:stratiform:thicknessScale must be >= 0 [m], got {scale}")
            data = self._map_file(prim, "warpsky:stratiform:thicknessMap", tc, channels=1, loader=load_map)
            return np.asarray(data * np.float32(scale), dtype=np.float32)
        cover = self._float_attr(prim, "warpsky:stratiform:cover", tc, 0.5)
        if not 0.0 <= cover <= 1.0:
            raise SceneError(f"{path}.warpsky:stratiform:cover must lie in [0, 1], got {cover}")
        max_thickness = self._float_attr(prim, "warpsky:stratiform:maxThickness", tc, 500.0)
        if max_thickness < 0.0:
            raise SceneError(f"{path}.warpsky:stratiform:maxThickness must be >= 0 [m], got {max_thickness}")
        seed = self._int_attr(prim, "warpsky:stratiform:seed", tc, 0)
        key = ("procedural", cover, max_thickness, seed)
        if key not in self._map_cache:
            self._map_cache[key] = procedural_thickness(PROCEDURAL_RESOLUTION, cover=cover,
                                                        max_thickness=max_thickness, seed=seed)
        return self._map_cache[key]

    def _map_file(self, prim, name: str, tc, *, channels: int, loader) -> np.ndarray:
        attr = prim.GetAttribute(name)
        asset = attr.Get(tc)
        if not hasattr(asset, "resolvedPath"):
            raise SceneError(f"{prim.GetPath()}.{name} must be an asset path (asset {name} = @file@), got {asset!r}")
        if not asset.resolvedPath:
            layer = self.stage.GetRootLayer().realPath
            raise SceneError(f"{prim.GetPath()}.{name}: file {asset.path!r} not found (relative to {layer})"
                             + missing_asset_hint(layer, asset.path))
        resolved = asset.resolvedPath
        stat = os.stat(resolved)
        key = (resolved, channels, stat.st_mtime_ns, stat.st_size)
        if key not in self._map_cache:
            try:
                self._map_cache[key] = loader(resolved, channels=channels)
            except SceneError as exc:
                raise SceneError(f"{prim.GetPath()}.{name}: {exc}") from None
            except (OSError, ValueError) as exc:
                raise SceneError(f"{prim.GetPath()}.{name}: cannot read {resolved}: {exc}") from None
        return self._map_cache[key]

    def _advection(self, prim, tc):
        """``warpsky:advection:*`` as a ThicknessAdvection, or None when none is authored."""
        path = str(prim.GetPath())
        if not any(a.GetName().startswith("warpsky:advection:") and a.HasAuthoredValue()
                   for a in prim.GetAttributes()):
            return None
        kwargs = {}
        vector = self._vector_attr(prim, "warpsky:advection:wind", tc, 2, "a float2 [m/s]", "2 finite speeds [m/s]")
        if vector is not None:
            # the stage's horizontal axes (Y up: x, z; Z up: x, y) -> warpsky's x, z; m/s whatever metersPerUnit
            kwargs["wind_m_s"] = (float(vector[0]), float(vector[1]) if self.up_axis == "Y" else -float(vector[1]))
        for attr, key, low in (("curlSpeed", "curl_speed_m_s", 0.0), ("curlScale", "curl_scale_m", None),
                               ("period", "period_s", None)):
            a = prim.GetAttribute(f"warpsky:advection:{attr}")
            if a.HasAuthoredValue():
                value = self._float_attr(prim, f"warpsky:advection:{attr}", tc, 0.0)
                if (value < low) if low is not None else (value <= 0.0):
                    relation = f">= {low:g}" if low is not None else "> 0"
                    raise SceneError(f"{path}.warpsky:advection:{attr} must be {relation}, got {value}")
                kwargs[key] = value
        kwargs["seed"] = self._int_attr(prim, "warpsky:advection:seed", tc, 0)
        try:
            return ThicknessAdvection(**kwargs)
        except SceneError as exc:
            raise SceneError(f"{path}.warpsky:advection: {exc}") from None

    def _albedo_map(self, prim, tc, world):
        """The plane's ``warpsky:albedoMap`` over ``warpsky:albedoMapSize`` as a GroundTexture, or None."""
        attr = prim.GetAttribute("warpsky:albedoMap")
        if not attr or not attr.HasAuthoredValue():
            if prim.GetAttribute("warpsky:albedoMapSize").HasAuthoredValue():
                raise SceneError(f"{prim.GetPath()}.warpsky:albedoMapSize is authored without warpsky:albedoMap")
            return None
        mpu = self.meters_per_unit
        size = self._positive2(prim, "warpsky:albedoMapSize", tc, (1e4 / mpu, 1e4 / mpu)) * mpu
        albedo = np.clip(self._map_file(prim, "warpsky:albedoMap", tc, channels=3, loader=load_map), 0.0, 1.0)
        centre = world[:3, 3]
        return GroundTexture(albedo, (float(centre[0] - size[0] / 2), float(centre[2] - size[1] / 2)),
                             (float(size[0]), float(size[1])))
