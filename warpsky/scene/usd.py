"""Read a :class:`~warpsky.scene.model.Scene` from a USD stage at any time code.

The only module that imports pxr. Stage units are converted here: ``upAxis`` Y or Z and ``metersPerUnit`` become
warpsky's right-handed Y-up metres. Every problem is a :class:`SceneError` naming the prim, attribute or file.

What is read (the README's "USD attributes" section lists the same with units and defaults):

- ``UsdGeomCamera``: chosen by ``--camera``, else the render settings' camera, else the first camera.
- ``UsdLuxDistantLight``: the sun (the first visible one).
- ``UsdVolVolume`` with ``field:density`` (analytic phase) and/or ``field:cloud|rain|ice|snow`` (tabulated
  species optics) -> ``OpenVDBAsset`` (``.vdb``, ``.nvdb`` or dense ``.npy``).
- ``warpsky:detail:*`` on a Volume: animated density detail (:class:`~warpsky.scene.model.DetailSpec`).
- ``UsdGeomPlane``: a horizontal ground plane, albedo ``color3f warpsky:albedo``, optional albedo texture
  ``warpsky:albedoMap`` / ``warpsky:albedoMapSize`` (:class:`~warpsky.media.stratiform.GroundTexture`).
- Prims with ``warpsky:kind = "stratiformLayer"``: stratiform cloud layers, ``warpsky:stratiform:*`` and
  ``warpsky:advection:*`` (:class:`~warpsky.media.stratiform.StratiformLayer`, ``ThicknessAdvection``).
- ``UsdRenderSettings``: ``resolution`` and ``camera`` as defaults for the command line.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.errors import SceneError
from warpsky.scene.model import Camera, DetailSpec, Ground, PhaseKind, PhaseModel, Scene, Sun, VoxelMedium

PHASE_TOKENS = {"isotropic": PhaseKind.ISOTROPIC, "hg": PhaseKind.HG, "rayleigh": PhaseKind.RAYLEIGH}
DENSITY_FIELD = "density"
#: Field relationship names warpsky renders: the generic one (analytic phase) and one per species (tables).
SPECIES_FIELDS = ("cloud", "rain", "ice", "snow")
RENDERED_FIELDS = (DENSITY_FIELD, *SPECIES_FIELDS)
QUANTITIES = ("extinction", "concentration")
#: ``warpsky:kind`` of a stratiform layer prim, and the attributes such a prim may carry.
LAYER_KIND = "stratiformLayer"
LAYER_ATTRIBUTES = frozenset(
    [f"warpsky:stratiform:{n}" for n in ("thicknessMap", "thicknessScale", "size", "cover", "maxThickness", "seed",
                                         "numberDensity", "effectiveRadius", "radiosity")]
    + [f"warpsky:advection:{n}" for n in ("wind", "curlSpeed", "curlScale", "period", "seed")]
)


@dataclass(frozen=True)
class TimeRange:
    """The stage's animation range: time codes, and their rate."""

    start: float
    end: float
    time_codes_per_second: float
    frames_per_second: float
    authored: bool


def _matrix(gf_matrix) -> np.ndarray:
    """Gf.Matrix4d (row vectors, p' = p M) as a column-vector numpy matrix."""
    return np.array(gf_matrix, dtype=np.float64).reshape(4, 4).T


class StageReader:
    """An open stage plus the caches that make reading many frames cheap.

    Args:
        path: The stage file (.usd, .usda, .usdc, .usdz).
    """

    def __init__(self, path: str | os.PathLike):
        from pxr import Tf, Usd, UsdGeom

        self.path = Path(path)
        if not self.path.is_file():
            raise SceneError(f"stage file {self.path} does not exist")
        try:
            stage = Usd.Stage.Open(str(self.path))
        except Tf.ErrorException as exc:
            detail = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unreadable"
            raise SceneError(f"cannot open stage {self.path}: {detail}") from None
        if stage is None:
            raise SceneError(f"cannot open stage {self.path}")
        self.stage = stage
        self.up_axis = str(UsdGeom.GetStageUpAxis(stage))
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(stage))
        if not (self.meters_per_unit > 0.0 and math.isfinite(self.meters_per_unit)):
            raise SceneError(f"stage {self.path}: metersPerUnit must be positive, got {self.meters_per_unit}")
        if self.up_axis not in ("Y", "Z"):
            raise SceneError(f"stage {self.path}: upAxis must be Y or Z, got {self.up_axis!r}")
        # warpsky world (Y up, metres) from stage space: Z-up (x, y, z) -> Y-up (x, z, -y), then scale.
        rotation = np.eye(3) if self.up_axis == "Y" else np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
        self.world_from_stage = np.eye(4)
        self.world_from_stage[:3, :3] = self.meters_per_unit * rotation
        self._field_cache: dict[tuple, object] = {}
        self._map_cache: dict[tuple, np.ndarray] = {}

    # ----------------------------------------------------------------------------------------------- time
    def time_range(self) -> TimeRange:
        stage = self.stage
        return TimeRange(
            float(stage.GetStartTimeCode()),
            float(stage.GetEndTimeCode()),
            float(stage.GetTimeCodesPerSecond()),
            float(stage.GetFramesPerSecond()),
            bool(stage.HasAuthoredTimeCodeRange()),
        )

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

    def _prims_of(self, schema) -> list:
        from pxr import Usd

        return [p for p in Usd.PrimRange(self.stage.GetPseudoRoot()) if p.IsA(schema) and p.IsActive()]

    # ---------------------------------------------------------------------------------------------- camera
    def camera_paths(self) -> list[str]:
        from pxr import UsdGeom

        return [str(p.GetPath()) for p in self._prims_of(UsdGeom.Camera)]

    def render_settings(self) -> tuple[tuple[int, int] | None, str | None]:
        """Resolution and camera path authored on the stage's UsdRenderSettings prim, if any."""
        from pxr import UsdRender

        settings_path = self.stage.GetMetadata("renderSettingsPrimPath") or ""
        prim = self.stage.GetPrimAtPath(settings_path) if settings_path else None
        if not prim:
            candidates = self._prims_of(UsdRender.Settings)
            prim = candidates[0] if candidates else None
        if not prim:
            return None, None
        settings = UsdRender.Settings(prim)
        resolution = None
        res_attr = settings.GetResolutionAttr()
        if res_attr.HasAuthoredValue():
            res = res_attr.Get()
            if res[0] <= 0 or res[1] <= 0:
                raise SceneError(f"{prim.GetPath()}.resolution must be positive, got {tuple(res)}")
            resolution = (int(res[0]), int(res[1]))
        targets = settings.GetCameraRel().GetTargets()
        return resolution, (str(targets[0]) if targets else None)

    def resolve_camera_path(self, camera_path: str | None) -> str:
        from pxr import Sdf, UsdGeom

        if camera_path is None:
            _, camera_path = self.render_settings()
        if camera_path is None:
            cameras = self.camera_paths()
            if not cameras:
                raise SceneError(f"stage {self.path} has no camera (UsdGeomCamera prim); add one or pass --camera")
            return cameras[0]
        if not Sdf.Path.IsValidPathString(camera_path):
            raise SceneError(f"--camera {camera_path!r} is not a valid prim path")
        prim = self.stage.GetPrimAtPath(camera_path)
        if not prim:
            raise SceneError(f"stage {self.path} has no prim at camera path {camera_path}")
        if not prim.IsA(UsdGeom.Camera):
            raise SceneError(f"prim {camera_path} is a {prim.GetTypeName() or 'typeless prim'}, not a Camera")
        return camera_path

    def read_camera(self, camera_path: str | None = None, time=None) -> Camera:
        from pxr import UsdGeom

        path = self.resolve_camera_path(camera_path)
        prim = self.stage.GetPrimAtPath(path)
        tc = self._time(time)
        usd_camera = UsdGeom.Camera(prim)
        if usd_camera.GetProjectionAttr().Get(tc) != UsdGeom.Tokens.perspective:
            raise SceneError(f"camera {path}: projection must be 'perspective'; orthographic is not supported")
        gf = usd_camera.GetCamera(tc)
        world = self._world(prim, tc)
        u, _, vt = np.linalg.svd(world[:3, :3])
        rotation = u @ vt
        if np.linalg.det(rotation) < 0.0:
            raise SceneError(f"camera {path}: its transform mirrors space (negative determinant)")
        # Focal length and apertures are in tenths of a scene unit.
        tenth = 0.1 * self.meters_per_unit
        clip = gf.clippingRange
        values = {
            "focalLength": gf.focalLength, "horizontalAperture": gf.horizontalAperture,
            "verticalAperture": gf.verticalAperture,
        }
        for name, value in values.items():
            if not (value > 0.0 and math.isfinite(value)):
                raise SceneError(f"camera {path}: {name} must be positive, got {value}")
        if not (0.0 < clip.min < clip.max):
            raise SceneError(
                f"camera {path}: clippingRange must satisfy 0 < near < far, got ({clip.min:g}, {clip.max:g})"
            )
        return Camera(
            path,
            world[:3, 3],
            rotation,
            gf.focalLength * tenth,
            gf.horizontalAperture * tenth,
            gf.verticalAperture * tenth,
            gf.horizontalApertureOffset * tenth,
            gf.verticalApertureOffset * tenth,
            clip.min * self.meters_per_unit,
            clip.max * self.meters_per_unit,
        )

    # ------------------------------------------------------------------------------------------------- sun
    def read_sun(self, time=None) -> Sun | None:
        from pxr import UsdLux

        tc = self._time(time)
        for prim in self._prims_of(UsdLux.DistantLight):
            if not self._visible(prim, tc):
                continue
            light = UsdLux.DistantLight(prim)
            world = self._world(prim, tc)
            # Light travels along the light's local -Z, so the sun lies along +Z.
            direction = world[:3, :3] @ np.array([0.0, 0.0, 1.0])
            if np.linalg.norm(direction) == 0.0:
                raise SceneError(f"light {prim.GetPath()}: its transform collapses the light direction")
            intensity = float(light.GetIntensityAttr().Get(tc))
            exposure = float(light.GetExposureAttr().Get(tc))
            color = np.array(light.GetColorAttr().Get(tc), dtype=np.float64)
            if light.GetEnableColorTemperatureAttr().Get(tc):
                color = color * np.array(UsdLux.BlackbodyTemperatureAsRgb(light.GetColorTemperatureAttr().Get(tc)))
            angle = float(light.GetAngleAttr().Get(tc))
            if not (0.0 <= angle < 180.0):
                raise SceneError(f"light {prim.GetPath()}: inputs:angle must lie in [0, 180) degrees, got {angle}")
            irradiance = intensity * 2.0**exposure * color
            if not np.all(np.isfinite(irradiance)) or np.any(irradiance < 0.0):
                raise SceneError(
                    f"light {prim.GetPath()}: intensity x 2^exposure x color must be finite and >= 0, "
                    f"got {irradiance.tolist()}"
                )
            return Sun(direction, irradiance, math.radians(angle), str(prim.GetPath()))
        return None

    # ---------------------------------------------------------------------------------------------- ground
    def read_ground(self, time=None) -> Ground | None:
        from pxr import UsdGeom

        tc = self._time(time)
        for prim in self._prims_of(UsdGeom.Plane):
            if not self._visible(prim, tc):
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

    # ------------------------------------------------------------------------------------------ atmosphere
    def read_atmosphere(self, time=None):
        """The first active prim with ``warpsky:atmosphere:*`` attributes (e.g. a Scope /World/Atmosphere)."""
        from warpsky.scene.model import Atmosphere

        tc = self._time(time)
        for prim in self.stage.Traverse():
            names = [a.GetName() for a in prim.GetAttributes() if a.GetName().startswith("warpsky:atmosphere:")]
            if not names:
                continue
            known = {"warpsky:atmosphere:betaSeaLevel", "warpsky:atmosphere:scaleHeight",
                     "warpsky:atmosphere:altitude", "warpsky:atmosphere:enabled"}
            unknown = sorted(set(names) - known)
            if unknown:
                raise SceneError(f"atmosphere {prim.GetPath()}: unknown attribute(s) {', '.join(unknown)}; known: "
                                 f"{', '.join(sorted(known))}")
            enabled = prim.GetAttribute("warpsky:atmosphere:enabled")
            if enabled and enabled.HasAuthoredValue() and not bool(enabled.Get(tc)):
                return None
            kwargs = {"name": str(prim.GetPath())}
            beta = self._color_attr(prim, "warpsky:atmosphere:betaSeaLevel", tc)
            if beta is not None:
                kwargs["beta_sea_level"] = beta
            for attr, key, scale in (("scaleHeight", "scale_height", self.meters_per_unit),
                                     ("altitude", "altitude", self.meters_per_unit)):
                a = prim.GetAttribute(f"warpsky:atmosphere:{attr}")
                if a and a.HasAuthoredValue():
                    value = a.Get(tc)
                    if not isinstance(value, (int, float)):
                        raise SceneError(f"atmosphere {prim.GetPath()}: warpsky:atmosphere:{attr} must be a float "
                                         f"[scene units], got {value!r}")
                    kwargs[key] = float(value) * scale
            return Atmosphere(**kwargs)
        return None

    # ----------------------------------------------------------------------------------------------- media
    def read_media(self, time=None) -> tuple[VoxelMedium, ...]:
        from pxr import UsdVol

        tc = self._time(time)
        media = []
        for prim in self._prims_of(UsdVol.Volume):
            if self._visible(prim, tc):
                media.extend(self._read_volume(prim, tc))
        return tuple(media)

    def _read_volume(self, prim, tc) -> list[VoxelMedium]:
        """One medium per rendered field of the Volume (``field:density`` and ``field:<species>``)."""
        from pxr import UsdVol

        volume = UsdVol.Volume(prim)
        path = str(prim.GetPath())
        fields = {str(name): field_path for name, field_path in volume.GetFieldPaths().items()}
        expected = ", ".join(f"field:{n}" for n in RENDERED_FIELDS)
        if not fields:
            raise SceneError(f"Volume {path} has no fields; expected one of {expected}")
        rendered = [name for name in RENDERED_FIELDS if name in fields]
        if not rendered:
            raise SceneError(
                f"Volume {path} has fields {', '.join(sorted(fields))} but none that warpsky renders ({expected})"
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
            if grid.local_from_index is None:
                local_from_index = self._extent_placement(prim, tc, grid.values.shape)
            else:
                local_from_index = grid.local_from_index
            species = None if name == DENSITY_FIELD else name
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
                        f"(field:{'|'.join(SPECIES_FIELDS)}), not field:{DENSITY_FIELD}"
                    )
                from warpsky.optics.species import get_species

                scale = scale * np.array(get_species(species).extinction_cross_section)
            albedo = self._float_attr(field_prim, "warpsky:albedo", tc, volume_albedo)
            try:
                media.append(VoxelMedium(
                    f"{path}:{name}" if species else path, grid.values, volume_world @ local_from_index, scale,
                    albedo, PhaseModel(PHASE_TOKENS[phase_token], g), grid.source, species, slicing_xi, detail,
                ))
            except SceneError as exc:
                raise SceneError(f"Volume {path}: {exc}") from None
        return media

    def _read_detail(self, prim, tc) -> DetailSpec | None:
        """``warpsky:detail:*`` of a Volume (see DetailSpec); None when absent or amplitude 0 (detail off)."""
        path = str(prim.GetPath())
        names = {a.GetName() for a in prim.GetAttributes() if a.GetName().startswith("warpsky:detail:")}
        if not names:
            return None
        known = {f"warpsky:detail:{n}" for n in ("amplitude", "scale", "wind", "curlSpeed", "period", "seed")}
        unknown = sorted(names - known)
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

        from warpsky.media.fields import load_field

        asset = UsdVol.OpenVDBAsset(field_prim)
        field_path = str(field_prim.GetPath())
        asset_path = asset.GetFilePathAttr().Get(tc)
        if asset_path is None or not asset_path.path:
            raise SceneError(f"field {field_path}: filePath is not authored")
        resolved = asset_path.resolvedPath
        if not resolved:
            layer = field_prim.GetStage().GetRootLayer().realPath
            raise SceneError(f"field {field_path}: file {asset_path.path!r} not found (relative to {layer})")
        grid_name = asset.GetFieldNameAttr().Get(tc)
        grid_name = str(grid_name) if grid_name else None
        try:
            stat = os.stat(resolved)
        except OSError as exc:
            raise SceneError(f"field {field_path}: cannot read {resolved}: {exc.strerror}") from None
        key = (resolved, grid_name, stat.st_mtime_ns, stat.st_size)
        if key not in self._field_cache:
            try:
                self._field_cache[key] = load_field(resolved, grid_name=grid_name)
            except SceneError as exc:
                raise SceneError(f"field {field_path}: {exc}") from None
        return self._field_cache[key]

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

    # ------------------------------------------------------------------------------------ stratiform layers
    def read_layers(self, time=None) -> tuple:
        """Visible prims with ``uniform token warpsky:kind = "stratiformLayer"`` as
        :class:`~warpsky.media.stratiform.StratiformLayer` at ``time`` (the attribute table is on that class)."""
        from pxr import UsdGeom

        tc = self._time(time)
        time_s = 0.0 if time is None else float(time) / float(self.stage.GetTimeCodesPerSecond())
        layers = []
        for prim in self.stage.Traverse():  # not the pseudo-root, which has no attributes to ask for
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
            if self._visible(prim, tc):
                layers.append(self._read_layer(prim, tc, time_s))
        return tuple(layers)

    def _read_layer(self, prim, tc, time_s: float):
        from warpsky.media.stratiform import StratiformLayer

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
        from warpsky.media.stratiform import PROCEDURAL_RESOLUTION, load_map, procedural_thickness

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
            raise SceneError(f"{prim.GetPath()}.{name}: file {asset.path!r} not found (relative to {layer})")
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
        from warpsky.media.stratiform import ThicknessAdvection

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
        from warpsky.media.stratiform import GroundTexture, load_map

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

    # ----------------------------------------------------------------------------------------------- scene
    def scene_at(self, time=None, *, camera_path: str | None = None) -> Scene:
        """Everything warpsky renders, at ``time`` (None: the earliest time sample, like usdrecord)."""
        resolution, _ = self.render_settings()
        return Scene(
            camera=self.read_camera(camera_path, time),
            sun=self.read_sun(time),
            media=self.read_media(time),
            ground=self.read_ground(time),
            atmosphere=self.read_atmosphere(time),
            time_code=float("nan") if time is None else float(time),
            source=str(self.path),
            resolution=resolution,
            time_codes_per_second=float(self.stage.GetTimeCodesPerSecond()),
            layers=self.read_layers(time),
        )
