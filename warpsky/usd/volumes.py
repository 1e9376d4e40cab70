"""Voxel media from ``UsdVolVolume`` prims: one :class:`~warpsky.model.scene.VoxelMedium` per rendered field
(``field:density`` or ``field:extinction`` with an analytic phase, ``field:cloud|rain|ice|snow`` with species
tables), the Volume's ``warpsky:detail:*`` animated detail, and the field files (``.vdb``, ``.nvdb``, dense ``.npy``)
behind them.

``field:extinction`` is the name UsdVol's own documentation gives the optical-density field; it is read exactly like
``field:density``: extinction [1/m] = field value × ``warpsky:extinctionScale`` (default 1). A Volume with both is
ambiguous and refused.

The ``OpenVDBAsset`` attributes read besides ``filePath`` (time samples give per-frame files) and ``fieldName``:

============== ======= ======= ========================================================================
attribute      type    default meaning
============== ======= ======= ========================================================================
fieldIndex     int     0       which of the grids named ``fieldName`` in the file (all grids without
                               a name), in file order; may be time-sampled
fieldDataType  token   –       when authored: ``float``, ``half`` or ``double`` (scalar grids only)
fieldClass     token   –       ``levelSet`` is refused with the ``vdb_tool -ls2fog`` command that
                               converts it (``vdbGridClass`` is read the same way)
============== ======= ======= ========================================================================

The grid itself is checked as well: a level set or a vector grid in the file is refused (see
:mod:`warpsky.media.voxels.fields`).

pxr is imported inside the methods (a heavy import).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.media.voxels.fields import level_set_advice, load_field, load_vector_field
from warpsky.media.voxels.velocity import advected_grid
from warpsky.model.scene import FIELD_SPECIES, DetailSpec, IceCrystals, PhaseKind, PhaseModel, VoxelMedium
from warpsky.optics.species import get_species
from warpsky.usd.generated_data import missing_asset_hint
from warpsky.usd.prims import StagePrims

PHASE_TOKENS = {"isotropic": PhaseKind.ISOTROPIC, "hg": PhaseKind.HG, "rayleigh": PhaseKind.RAYLEIGH}
DENSITY_FIELD = "density"
#: Generic extinction fields (analytic phase): ``density`` and UsdVol's documented ``extinction``, one per Volume.
ANALYTIC_FIELDS = (DENSITY_FIELD, "extinction")
#: Field relationship names warpsky renders: the generic ones (analytic phase) and one per species (tables).
SPECIES_FIELDS = FIELD_SPECIES
RENDERED_FIELDS = (*ANALYTIC_FIELDS, *SPECIES_FIELDS)
QUANTITIES = ("extinction", "concentration")
#: Field relationship names of a Volume's velocity (Blender's and EmberGen's ``velocity``, Houdini's ``vel``).
VELOCITY_FIELDS = ("velocity", "vel", "v")
#: ``fieldDataType`` tokens of a velocity grid.
VECTOR_DATA_TYPES = ("float3", "vector3f", "half3", "vector3h")
#: ``fieldDataType`` tokens of scalar grids; UsdVol allows vectors, matrices, ints and more.
SCALAR_DATA_TYPES = ("float", "half", "double")
#: Attributes that say a grid's class: UsdVol's ``fieldClass`` and the ``vdbGridClass`` some tools author.
GRID_CLASS_ATTRS = ("fieldClass", "vdbGridClass")


def velocity_field(fields: dict) -> str | None:
    """The name of a Volume's velocity field among its ``fields`` (:data:`VELOCITY_FIELDS`), or None."""
    return next((name for name in VELOCITY_FIELDS if name in fields), None)


class VolumeReading(StagePrims):
    """The stage reader's voxel media."""

    #: The frame whose sub-frames are being read (:meth:`sub_frames_of`), else None.
    motion_origin: float | None = None

    def read_media(self, time=None) -> tuple[VoxelMedium, ...]:
        from pxr import UsdVol

        tc = self._time(time)
        media = []
        # Inside an instance each Volume is an instance proxy at its own path (unique medium names), and USD maps
        # its field relationships' targets into the same instance.
        for prim in self._prims_of(UsdVol.Volume):
            if self._rendered(prim, tc):
                media.extend(self._read_volume(prim, tc))
        return tuple(media)

    def _read_volume(self, prim, tc) -> list[VoxelMedium]:
        """One medium per rendered field of the Volume (``field:density`` and ``field:<species>``)."""
        from pxr import UsdVol

        volume = UsdVol.Volume(prim)
        path = str(prim.GetPath())
        fields = {str(name): field_path for name, field_path in volume.GetFieldPaths().items()}
        rendered = [name for name in RENDERED_FIELDS if name in fields]
        if not rendered:  # a procedural volume its material makes: the ignored-prim warnings name it
            return []
        if all(name in fields for name in ANALYTIC_FIELDS):
            raise SceneError(
                f"Volume {path} has both field:density and field:extinction, which mean the same thing; keep one"
            )
        volume_world = self._world(prim, tc)
        phase_token = self._token_attr(prim, "warpsky:phase", tc, "hg")
        if phase_token not in PHASE_TOKENS:
            raise SceneError(f"{path}.warpsky:phase must be one of {', '.join(PHASE_TOKENS)}, got {phase_token!r}")
        g = self._float_attr(prim, "warpsky:phase:g", tc, 0.85)
        volume_albedo = self._float_attr(prim, "warpsky:albedo", tc, 1.0)
        slicing_xi = self._float_attr(prim, "warpsky:slicing:xi", tc, math.nan)  # nan: not authored
        slicing_xi = None if math.isnan(slicing_xi) else slicing_xi
        detail = self._read_detail(prim, tc)
        media = []
        for name in rendered:
            field_prim = self.stage.GetPrimAtPath(fields[name])
            if not field_prim or not field_prim.IsA(UsdVol.OpenVDBAsset):
                raise SceneError(f"Volume {path}: field:{name} targets {fields[name]}, which is not an OpenVDBAsset")
            grid = self._load_field(field_prim, tc)
            if grid.empty:
                self._warn(f"field {field_prim.GetPath()}: grid {grid.grid_name!r} of {grid.source} has no active "
                           "voxels at this time: an empty medium, nothing rendered for it")
                continue
            if grid.local_from_index is None:
                local_from_index = self._extent_placement(prim, tc, grid.values.shape)
            else:
                local_from_index = grid.local_from_index
            values, local_from_index = self._moved(prim, fields, field_prim, tc, grid.values, local_from_index)
            species = None if name in ANALYTIC_FIELDS else name
            self._warn_extinction_unit(field_prim)
            scale = np.full(3, self._float_attr(field_prim, "warpsky:extinctionScale", tc, 1.0))
            quantity = self._token_attr(field_prim, "warpsky:quantity", tc, "extinction")
            if quantity not in QUANTITIES:
                raise SceneError(
                    f"{field_prim.GetPath()}.warpsky:quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}"
                )
            if quantity == "concentration":
                if species is None:
                    raise SceneError(
                        f"{field_prim.GetPath()}: warpsky:quantity = concentration needs a species field "
                        f"(field:{'|'.join(SPECIES_FIELDS)}), not field:{name}"
                    )
                scale = scale * np.array(get_species(species).extinction_cross_section)
            albedo = self._float_attr(field_prim, "warpsky:albedo", tc, volume_albedo)
            ice = self._read_ice(field_prim, name, tc)
            field_detail = self._field_detail(detail, field_prim, path, tc)
            try:
                media.append(VoxelMedium(
                    f"{path}:{name}" if species else path, values, volume_world @ local_from_index, scale,
                    albedo, PhaseModel(PHASE_TOKENS[phase_token], g), grid.source, species, slicing_xi, field_detail,
                    ice, self._velocity_source(fields, tc), self._water(field_prim, tc),
                ))
            except SceneError as exc:
                raise SceneError(f"Volume {path}: {exc}") from None
        return media

    @contextlib.contextmanager
    def sub_frames_of(self, time_code: float):
        """Within this block the media are read as sub-frames of the frame at ``time_code``: a Volume with a
        velocity field has its density moved from the cached state to the sub-frame's time
        (:mod:`warpsky.media.voxels.velocity`)."""
        self.motion_origin = float(time_code)
        try:
            yield self
        finally:
            self.motion_origin = None

    def _moved(self, prim, fields: dict, field_prim, tc, values: np.ndarray, local_from_index: np.ndarray):
        """(values, local_from_index) of a density field at the sub-frame time ``tc``: moved by the Volume's
        velocity over the seconds since the state its file holds (the filePath's time sample at or before ``tc``,
        or, for one file, the frame's time), unchanged outside a blurred frame or without a velocity field."""
        from pxr import UsdVol

        origin = self.motion_origin
        velocity_name = velocity_field(fields)
        if origin is None or velocity_name is None:
            return values, local_from_index
        samples = UsdVol.OpenVDBAsset(field_prim).GetFilePathAttr().GetTimeSamples()
        held = [t for t in samples if t <= tc.GetValue()]
        state = held[-1] if held else (samples[0] if samples else origin)
        seconds = (tc.GetValue() - state) / self.stage.GetTimeCodesPerSecond()
        scale = self._float_attr(prim, "warpsky:velocityScale", tc, 1.0)
        if seconds * scale == 0.0:
            return values, local_from_index
        vel_prim = self.stage.GetPrimAtPath(fields[velocity_name])
        path = prim.GetPath()
        if not vel_prim or not vel_prim.IsA(UsdVol.OpenVDBAsset):
            raise SceneError(f"Volume {path}: field:{velocity_name} targets {fields[velocity_name]}, which is not "
                             "an OpenVDBAsset")
        velocity, vel_from_index = self._load_velocity(prim, vel_prim, tc)
        if velocity.size == 0:
            return values, local_from_index
        return advected_grid(values, local_from_index, velocity * np.float32(scale), vel_from_index, seconds)

    def _water(self, field_prim, tc) -> tuple[float, float] | None:
        """(peak [kg/m³], total [kg]) a field's writer recorded (``warpsky:water:peak``, ``warpsky:water:total``),
        or None."""
        peak = self._float_attr(field_prim, "warpsky:water:peak", tc, math.nan)
        total = self._float_attr(field_prim, "warpsky:water:total", tc, math.nan)
        return None if math.isnan(peak) or math.isnan(total) else (peak, total)

    def _velocity_source(self, fields: dict, tc) -> str:
        """The resolved file of the Volume's velocity field at ``tc`` ("" without one or when it does not resolve)."""
        from pxr import UsdVol

        name = velocity_field(fields)
        prim = self.stage.GetPrimAtPath(fields[name]) if name else None
        if not prim or not prim.IsA(UsdVol.OpenVDBAsset):
            return ""
        asset = UsdVol.OpenVDBAsset(prim).GetFilePathAttr().Get(tc)
        return str(asset.resolvedPath) if asset is not None and asset.resolvedPath else ""

    def _load_velocity(self, prim, vel_prim, tc) -> tuple[np.ndarray, np.ndarray]:
        """A velocity field's (X, Y, Z, 3) values [stage units per second] and its index-to-Volume matrix."""
        from pxr import UsdVol

        asset = UsdVol.OpenVDBAsset(vel_prim)
        field_path = vel_prim.GetPath()
        data_type = vel_prim.GetAttribute("fieldDataType")
        if data_type and data_type.HasAuthoredValue() and str(data_type.Get(tc)) not in VECTOR_DATA_TYPES:
            raise SceneError(f"{field_path}.fieldDataType is {str(data_type.Get(tc))!r}; a velocity field is a "
                             f"vector grid ({', '.join(VECTOR_DATA_TYPES)})")
        asset_path = asset.GetFilePathAttr().Get(tc)
        if asset_path is None or not asset_path.resolvedPath:
            layer = vel_prim.GetStage().GetRootLayer().realPath
            authored = getattr(asset_path, "path", None)
            raise SceneError(f"field {field_path}: file {authored!r} not found (relative to {layer})"
                             + missing_asset_hint(layer, authored))
        name = asset.GetFieldNameAttr().Get(tc)
        index = vel_prim.GetAttribute("fieldIndex")
        index = int(index.Get(tc)) if index and index.HasAuthoredValue() else 0
        resolved = asset_path.resolvedPath
        try:
            stat = os.stat(resolved)
        except OSError as exc:
            raise SceneError(f"field {field_path}: cannot read {resolved}: {exc.strerror}") from None
        key = (resolved, str(name) if name else None, index, stat.st_mtime_ns, stat.st_size, "vector")
        if key not in self._field_cache:  # read once for all the sub-frames and fields of a frame
            try:
                self._field_cache[key] = load_vector_field(resolved, grid_name=key[1], grid_index=index)
            except SceneError as exc:
                raise SceneError(f"field {field_path}: {exc}") from None
        grid = self._field_cache[key]
        if grid.local_from_index is None:
            return grid.values, self._extent_placement(prim, tc, grid.values.shape[:3])
        return grid.values, grid.local_from_index

    def _read_ice(self, field_prim, name: str, tc) -> IceCrystals | None:
        """``warpsky:ice:*`` of a field prim (see IceCrystals); None when none is authored. Refused on any field
        but ``field:ice``, naming the attribute."""
        from warpsky.optics.oriented_ice import parse_orientation

        where = str(field_prim.GetPath())
        names = sorted(a.GetName() for a in field_prim.GetAttributes() if a.GetName().startswith("warpsky:ice:")
                       and a.HasAuthoredValue())
        if not names:
            return None
        if name != "ice":
            raise SceneError(f"{where}.{names[0]}: crystal orientation applies to the field:ice of a Volume; this "
                             f"prim is its field:{name}")
        known = {f"warpsky:ice:{n}" for n in ("orientation", "habit", "tilt", "fraction")}
        unknown = [n for n in names if n not in known]
        if unknown:
            raise SceneError(f"{where}.{unknown[0]} is not an ice attribute; expected one of "
                             f"{', '.join(sorted(known))}")
        orientation = self._token_attr(field_prim, "warpsky:ice:orientation", tc, "random")
        habit = self._token_attr(field_prim, "warpsky:ice:habit", tc, "plate" if orientation == "plate" else "column")
        tilt = self._float_attr(field_prim, "warpsky:ice:tilt", tc, 1.0)
        fraction = self._float_attr(field_prim, "warpsky:ice:fraction", tc, 1.0)
        law = parse_orientation(habit, orientation, tilt, where)
        if not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
            raise SceneError(f"{where}.warpsky:ice:fraction must be a number fraction in [0, 1], got {fraction!r}")
        return IceCrystals(law.kind, law.habit, law.tilt_deg, fraction)

    def _read_detail(self, prim, tc) -> DetailSpec | None:
        """``warpsky:detail:*`` of a Volume (see DetailSpec); None when absent or amplitude 0 (detail off)."""
        path = str(prim.GetPath())
        names = {a.GetName() for a in prim.GetAttributes() if a.GetName().startswith("warpsky:detail:")}
        if not names:
            return None
        known = {f"warpsky:detail:{n}" for n in ("amplitude", "scale", "wind", "curlSpeed", "period", "seed")}
        unknown = sorted(names - known)
        if "warpsky:detail:edge" in unknown:
            raise SceneError(f"Volume {path}: warpsky:detail:edge goes on each field prim (OpenVDBAsset), one "
                             "extinction [1/m] per species, not on the Volume")
        if unknown:
            raise SceneError(f"Volume {path}: unknown attribute(s) {', '.join(unknown)}; known: "
                             f"{', '.join(sorted(known))}")
        defaults = DetailSpec()
        kwargs = {"name": f"Volume {path}"}
        for attr, key in (("amplitude", "amplitude"), ("scale", "scale"), ("curlSpeed", "curl_speed"),
                          ("period", "period")):
            kwargs[key] = self._float_attr(prim, f"warpsky:detail:{attr}", tc, getattr(defaults, key))
        seed = prim.GetAttribute("warpsky:detail:seed")
        if seed.HasAuthoredValue():
            value = seed.Get(tc)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise SceneError(f"{path}.warpsky:detail:seed must be an int >= 0, got {value!r}")
            kwargs["seed"] = int(value)
        vector = self._vector_attr(prim, "warpsky:detail:wind", tc, 3, "a float3 [m/s]", "3 finite speeds [m/s]")
        if vector is not None:
            # stage axes -> warpsky's Y-up axes; a speed in m/s is not rescaled by metersPerUnit
            kwargs["wind"] = tuple((self.world_from_stage[:3, :3] / self.meters_per_unit @ vector).tolist())
        spec = DetailSpec(**kwargs)  # validates ranges; its SceneError names the Volume and the attribute
        return spec if spec.active else None

    def _field_detail(self, detail: DetailSpec | None, field_prim, volume: str, tc) -> DetailSpec | None:
        """The Volume's detail with the field's own ``warpsky:detail:edge`` [1/m] (see DetailSpec)."""
        edge = self._float_attr(field_prim, "warpsky:detail:edge", tc, 0.0)
        if edge == 0.0:
            return detail
        if detail is None:
            raise SceneError(f"{field_prim.GetPath()}.warpsky:detail:edge = {edge:g} needs the Volume's detail: set "
                             f"warpsky:detail:amplitude > 0 on {volume}")
        return dataclasses.replace(detail, edge=edge, name=f"field {field_prim.GetPath()}")

    def _warn_extinction_unit(self, field_prim) -> None:
        """One warning per field of a stage whose unit is not the metre: warpsky reads extinction per metre
        whatever metersPerUnit says (a rescaled stage keeps its optical depths), where a renderer that takes a
        density per scene unit (Hydra delegates are not told the unit) does not; it names the extinctionScale
        that renders as such a renderer does."""
        mpu = self.meters_per_unit
        if abs(mpu - 1.0) <= 1e-9:
            return
        self._warn(f"field {field_prim.GetPath()}: extinction is read per metre (field value x "
                   f"warpsky:extinctionScale, 1/m) although the stage's metersPerUnit is {mpu:g}"
                   f"{'' if self.meters_per_unit_authored else ' (unauthored: USD fallback)'}; "
                   "renderers that read "
                   f"density per stage unit see it {1.0 / mpu:g} times denser: author warpsky:extinctionScale "
                   f"= {1.0 / mpu:g} (times the current scale) for their look")

    def _extent_placement(self, prim, tc, shape) -> np.ndarray:
        """Index-to-local matrix of a dense grid filling the Volume's authored extent, cell-centred."""
        from pxr import UsdGeom

        extent = UsdGeom.Boundable(prim).GetExtentAttr().Get(tc)
        if extent is None or len(extent) != 2:
            raise SceneError(
                f"Volume {prim.GetPath()}: a dense .npy field needs an authored extent (float3[] extent = "
                "[(min), (max)]) to place it"
            )
        lo, hi = np.array(extent[0], dtype=np.float64), np.array(extent[1], dtype=np.float64)
        if not np.all(hi > lo):
            raise SceneError(
                f"Volume {prim.GetPath()}.extent must have min < max on every axis, got {lo.tolist()} .. {hi.tolist()}"
            )
        cell = (hi - lo) / np.array(shape, dtype=np.float64)
        local_from_index = np.diag([*cell, 1.0])
        local_from_index[:3, 3] = lo + 0.5 * cell
        return local_from_index

    def _load_field(self, field_prim, tc):
        from pxr import UsdVol

        asset = UsdVol.OpenVDBAsset(field_prim)
        field_path = str(field_prim.GetPath())
        asset_path = asset.GetFilePathAttr().Get(tc)
        if asset_path is None or not asset_path.path:
            raise SceneError(f"field {field_path}: filePath is not authored")
        resolved = asset_path.resolvedPath
        if not resolved:
            layer = field_prim.GetStage().GetRootLayer().realPath
            raise SceneError(f"field {field_path}: file {asset_path.path!r} not found (relative to {layer})"
                             + missing_asset_hint(layer, asset_path.path))
        grid_name = asset.GetFieldNameAttr().Get(tc)
        grid_name = str(grid_name) if grid_name else None
        grid_index = self._check_grid_attrs(field_prim, tc, resolved, grid_name)
        try:
            stat = os.stat(resolved)
        except OSError as exc:
            raise SceneError(f"field {field_path}: cannot read {resolved}: {exc.strerror}") from None
        key = (resolved, grid_name, grid_index, stat.st_mtime_ns, stat.st_size)
        if key not in self._field_cache:
            try:
                self._field_cache[key] = load_field(resolved, grid_name=grid_name, grid_index=grid_index)
            except SceneError as exc:
                raise SceneError(f"field {field_path}: {exc}") from None
        return self._field_cache[key]

    @staticmethod
    def _check_grid_attrs(field_prim, tc, resolved: str, grid_name: str | None) -> int:
        """Check ``fieldDataType`` and the grid class attributes; return ``fieldIndex`` (0 when unauthored)."""
        path = field_prim.GetPath()
        data_type = field_prim.GetAttribute("fieldDataType")
        if data_type and data_type.HasAuthoredValue():
            value = str(data_type.Get(tc))
            if value not in SCALAR_DATA_TYPES:
                raise SceneError(
                    f"{path}.fieldDataType is {value!r} (file {resolved}); warpsky renders scalar grids "
                    f"({', '.join(SCALAR_DATA_TYPES)}): point fieldName at a scalar density grid"
                )
        for name in GRID_CLASS_ATTRS:
            attr = field_prim.GetAttribute(name)
            if attr and attr.HasAuthoredValue() and str(attr.Get(tc)) == "levelSet":
                advice = level_set_advice(resolved, grid_name)
                raise SceneError(f"{path}.{name} is 'levelSet' (file {resolved}): {advice}")
        index = field_prim.GetAttribute("fieldIndex")
        if not index or not index.HasAuthoredValue():
            return 0
        value = index.Get(tc)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise SceneError(f"{path}.fieldIndex must be an int >= 0 (0 = the first grid of its name), got {value!r}")
        return int(value)
