"""Read a :class:`~warpsky.model.scene.Scene` from a USD stage at any time code.

Stage units are converted here: ``upAxis`` Y or Z and ``metersPerUnit`` become warpsky's right-handed Y-up metres.
Every problem is a :class:`SceneError` naming the prim, attribute or file. :class:`StageReader` reads the camera,
atmosphere and render settings itself; its parts read the rest: :mod:`warpsky.usd.lights` (suns and dome),
:mod:`warpsky.usd.volumes` (voxel media), :mod:`warpsky.usd.surfaces` (ground and stratiform layers),
:mod:`warpsky.usd.scenery` (meshes, height-field clouds, analytic fog) and :mod:`warpsky.usd.ignored`
(warnings on what is not rendered), on :mod:`warpsky.usd.prims` (transforms, visibility, typed attributes).
:mod:`warpsky.usd.composition` decides how the stage is composed (payloads loaded or not, variant selections,
which purposes render: :class:`StageOptions`). pxr is imported inside the methods (a heavy import).

What is read (the README's "USD attributes" section lists the same with units and defaults):

- ``UsdGeomCamera``: chosen by ``--camera``, else the render settings' camera, else the first camera.
- ``UsdLuxDistantLight``: the sun (the first visible one); further visible ones are ``extra_suns``.
- ``UsdLuxDomeLight``: the environment (the first visible one), uniform or a lat-long EXR texture.
- ``UsdVolVolume`` with ``field:density`` (analytic phase) and/or ``field:cloud|rain|ice|snow`` (tabulated
  species optics) -> ``OpenVDBAsset`` (``.vdb``, ``.nvdb`` or dense ``.npy``).
- ``warpsky:detail:*`` on a Volume: animated density detail (:class:`~warpsky.model.scene.DetailSpec`).
- ``UsdGeomPlane``: a horizontal ground plane, albedo ``color3f warpsky:albedo``, optional albedo texture
  ``warpsky:albedoMap`` / ``warpsky:albedoMapSize`` (:class:`~warpsky.model.stratiform.GroundTexture`).
- Prims with ``warpsky:kind = "stratiformLayer"``: stratiform cloud layers, ``warpsky:stratiform:*`` and
  ``warpsky:advection:*`` (:class:`~warpsky.model.stratiform.StratiformLayer`, ``ThicknessAdvection``).
- ``UsdGeomMesh``: opaque Lambertian surfaces such as terrain (:class:`~warpsky.model.terrain.TerrainMesh`).
- Prims with ``warpsky:kind = "heightFieldClouds"`` (``warpsky:hf:*``, ``warpsky:haze:*``) and
  ``warpsky:kind = "analyticFog"`` (``warpsky:fog:*``): :mod:`warpsky.usd.scenery`.
- Lights and gprims of other kinds (``RectLight``, a second ``DomeLight``, ``Cube``, ``Sphere``, ...): one
  ``warning:`` line each, :mod:`warpsky.usd.ignored`.
- ``UsdRenderSettings``: ``resolution`` (the schema's 2048 x 1080 when unauthored) and ``camera`` as defaults for
  the command line.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError, did_you_mean
from warpsky.model.scene import Atmosphere, Camera, Scene
from warpsky.usd.composition import StageOptions, apply_variants, composition_summary
from warpsky.usd.ignored import IgnoredReading
from warpsky.usd.layer_files import composition_problem, open_layers, tf_message
from warpsky.usd.lights import LightReading
from warpsky.usd.scenery import SceneryReading
from warpsky.usd.surfaces import SurfaceReading
from warpsky.usd.volumes import VolumeReading


@dataclass(frozen=True)
class TimeRange:
    """The stage's animation range: time codes, and their rate."""

    start: float
    end: float
    time_codes_per_second: float
    frames_per_second: float
    authored: bool


class StageReader(LightReading, VolumeReading, SurfaceReading, SceneryReading, IgnoredReading):
    """An open stage plus the caches that make reading many frames cheap.

    Args:
        path: The stage file (.usd, .usda, .usdc, .usdz).
        options: How to compose it: payloads loaded or not, variant selections (made on the session layer, never
            in the files) and the purposes that render; None: :class:`StageOptions` defaults (all payloads, the
            authored variants, default and render purposes).
    """

    def __init__(self, path: str | os.PathLike, options: StageOptions | None = None):
        from pxr import Tf, Usd, UsdGeom

        self.path = Path(path)
        self.options = StageOptions() if options is None else options
        if not self.path.is_file():
            raise SceneError(f"stage file {self.path} does not exist")
        try:
            # Held open: the stage reuses them instead of parsing again. Payload files are read even with
            # --load none (a missing one is skipped here, and USD does not compose it unloaded).
            self._layers = open_layers(self.path)
            stage = Usd.Stage.Open(self._layers[0], self.options.initial_load_set())
        except SceneError as exc:  # the message names the file at fault, often the stage itself
            named = str(exc).startswith(str(self.path))
            raise SceneError(f"cannot open stage{':' if named else f' {self.path}:'} {exc}") from None
        except Tf.ErrorException as exc:
            raise SceneError(f"cannot open stage {self.path}: {tf_message(exc) or 'unreadable'}") from None
        if stage is None:
            raise SceneError(f"cannot open stage {self.path}")
        try:
            self._variant_lines = apply_variants(stage, self.options.variants)
        except SceneError as exc:
            raise SceneError(f"stage {self.path}: {exc}") from None
        problem = composition_problem(stage)  # after the variants: a selected variant may reference a missing file
        if problem is not None:
            raise SceneError(f"stage {self.path}: {problem}")
        self.stage = stage
        self.up_axis = str(UsdGeom.GetStageUpAxis(stage))
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(stage))
        self.meters_per_unit_authored = bool(UsdGeom.StageHasAuthoredMetersPerUnit(stage))
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
        #: The ``warning:`` lines printed so far (each once per reader, however many frames repeat it).
        self.warnings: list[str] = []

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

    def composition_summary(self) -> list[str]:
        """One line per thing composition did (payloads, references, variants, instances, purposes rendered), for
        ``warpsky info``."""
        return composition_summary(self.stage, self.options, self._variant_lines)

    # ---------------------------------------------------------------------------------------------- camera
    def camera_paths(self) -> list[str]:
        from pxr import UsdGeom

        return [str(p.GetPath()) for p in self._prims_of(UsdGeom.Camera)]

    def render_settings(self) -> tuple[tuple[int, int] | None, str | None]:
        """Resolution and camera path authored on the stage's default UsdRenderSettings prim (its
        renderSettingsPrimPath, else the first one), if any; :mod:`warpsky.usd.render_settings` reads the rest."""
        from pxr import UsdRender

        from warpsky.usd.render_settings import base_values, find_settings

        prim = find_settings(self.stage, None)
        if prim is None:
            return None, None
        camera, resolution, _, _ = base_values(UsdRender.Settings(prim), None)
        return resolution, camera

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
            raise SceneError(f"stage {self.path} has no prim at camera path {camera_path}; "
                             + self._cameras_hint(camera_path))
        if not prim.IsA(UsdGeom.Camera):
            raise SceneError(f"prim {camera_path} is a {prim.GetTypeName() or 'typeless prim'}, not a Camera; "
                             + self._cameras_hint(camera_path))
        return camera_path

    def _cameras_hint(self, camera_path: str) -> str:
        """"did you mean P? the stage's cameras: A, B" (or "the stage has no camera") for a wrong camera path."""
        cameras = self.camera_paths()
        if not cameras:
            return "the stage has no camera"
        return f"{did_you_mean(camera_path, cameras, cutoff=0.8)}the stage's cameras: {', '.join(cameras)}"

    def read_camera(self, camera_path: str | None = None, time=None) -> Camera:
        from pxr import UsdGeom

        if camera_path is None and self.render_settings()[1] is None and not self.camera_paths():
            return self._free_camera(self._time(time))
        path = self.resolve_camera_path(camera_path)
        prim = self.stage.GetPrimAtPath(path)
        tc = self._time(time)
        usd_camera = UsdGeom.Camera(prim)
        token = usd_camera.GetProjectionAttr().Get(tc)
        if token not in (UsdGeom.Tokens.perspective, UsdGeom.Tokens.orthographic):
            raise SceneError(f"camera {path}: projection must be 'perspective' or 'orthographic', got {token!r}")
        gf = usd_camera.GetCamera(tc)
        world = self._world(prim, tc)
        u, _, vt = np.linalg.svd(world[:3, :3])
        rotation = u @ vt
        if np.linalg.det(rotation) < 0.0:
            raise SceneError(f"camera {path}: its transform mirrors space (negative determinant)")
        # Focal length and apertures are in tenths of a scene unit; orthographic apertures are the view's extent.
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
            str(token),
            shutter=self._shutter(usd_camera, path, tc),
        )

    @staticmethod
    def _shutter(usd_camera, path, tc) -> tuple[float, float]:
        """The camera's (shutter:open, shutter:close) [frames]; close before open is an error naming both."""
        shutter = (float(usd_camera.GetShutterOpenAttr().Get(tc)), float(usd_camera.GetShutterCloseAttr().Get(tc)))
        if not (all(math.isfinite(v) for v in shutter) and shutter[1] >= shutter[0]):
            raise SceneError(f"camera {path}: shutter:close must be at or after shutter:open, got {shutter}")
        return shutter

    def _free_camera(self, tc) -> Camera:
        """A stage without a camera is seen as usdrecord sees it, through a free camera framing the bounds of what
        it renders: a 50 mm lens on a 36 x 24 mm back, looking along warpsky's -Z at the bounds' centre from where
        their bounding sphere fills the height of the frame (one warning says so)."""
        from pxr import UsdGeom

        cache = UsdGeom.BBoxCache(tc, [UsdGeom.Tokens.default_, UsdGeom.Tokens.render], useExtentsHint=True)
        box = cache.ComputeWorldBound(self.stage.GetPseudoRoot()).ComputeAlignedRange()
        if box.IsEmpty():
            raise SceneError(f"stage {self.path} has no camera (UsdGeomCamera prim) and no bounds to frame; add a "
                             "camera or pass --camera")
        corners = np.array([[*box.GetMin(), 1.0], [*box.GetMax(), 1.0]]) @ self.world_from_stage.T
        centre = 0.5 * (corners[0, :3] + corners[1, :3])
        radius = max(0.5 * float(np.linalg.norm(corners[1, :3] - corners[0, :3])), 1e-3)
        distance = radius / math.sin(math.atan(12.0 / 50.0))
        position = centre + np.array([0.0, 0.0, distance])
        self._warn(f"stage {self.path} has no camera: rendering through a free camera framing its bounds, as "
                   f"usdrecord does (at {np.round(position, 3).tolist()} m looking along -Z, 50 mm); add a Camera or "
                   "pass --camera to choose the view")
        return Camera("free camera", position, np.eye(3), 50.0, 36.0, 24.0, near=max(1e-3 * distance, 1e-3),
                      far=distance + 10.0 * radius)

    def _warn(self, message: str) -> None:
        """Print ``warpsky: warning: <message>`` to stderr, once per reader."""
        if message not in self.warnings:
            self.warnings.append(message)
            print(f"warpsky: warning: {message}", file=sys.stderr, flush=True)

    # ------------------------------------------------------------------------------------------ atmosphere
    def read_atmosphere(self, time=None):
        """The first active prim with ``warpsky:atmosphere:*`` attributes (e.g. a Scope /World/Atmosphere) that is
        visible at ``time`` and of a rendered purpose."""
        tc = self._time(time)
        for prim in self._traverse():
            names = [a.GetName() for a in prim.GetAttributes() if a.GetName().startswith("warpsky:atmosphere:")]
            if not names or not self._rendered(prim, tc):
                continue
            known = {f"warpsky:atmosphere:{n}" for n in (
                "betaSeaLevel", "scaleHeight", "altitude", "enabled", "multipleScattering", "mieScattering",
                "mieAbsorption", "mieScaleHeight", "mieAnisotropy", "ozoneAbsorption", "ozoneAltitude",
                "ozoneWidth", "planetRadius")}
            unknown = sorted(set(names) - known)
            if unknown:
                raise SceneError(f"atmosphere {prim.GetPath()}: unknown attribute(s) {', '.join(unknown)}; known: "
                                 f"{', '.join(sorted(known))}")
            enabled = prim.GetAttribute("warpsky:atmosphere:enabled")
            if enabled and enabled.HasAuthoredValue() and not bool(enabled.Get(tc)):
                return None
            kwargs = {"name": str(prim.GetPath())}
            for attr, key in (("betaSeaLevel", "beta_sea_level"), ("mieScattering", "mie_scattering"),
                              ("mieAbsorption", "mie_absorption"), ("ozoneAbsorption", "ozone_absorption")):
                value = self._color_attr(prim, f"warpsky:atmosphere:{attr}", tc)
                if value is not None:
                    kwargs[key] = value
            for attr, key, scale in (("scaleHeight", "scale_height", self.meters_per_unit),
                                     ("altitude", "altitude", self.meters_per_unit),
                                     ("mieScaleHeight", "mie_scale_height", self.meters_per_unit),
                                     ("mieAnisotropy", "mie_g", 1.0),
                                     ("ozoneAltitude", "ozone_altitude", self.meters_per_unit),
                                     ("ozoneWidth", "ozone_width", self.meters_per_unit),
                                     ("planetRadius", "planet_radius", self.meters_per_unit)):
                a = prim.GetAttribute(f"warpsky:atmosphere:{attr}")
                if a and a.HasAuthoredValue():
                    value = a.Get(tc)
                    if not isinstance(value, (int, float)):
                        unit = "" if attr == "mieAnisotropy" else " [scene units]"
                        raise SceneError(f"atmosphere {prim.GetPath()}: warpsky:atmosphere:{attr} must be a float"
                                         f"{unit}, got {value!r}")
                    kwargs[key] = float(value) * scale
            multiple = prim.GetAttribute("warpsky:atmosphere:multipleScattering")
            if multiple and multiple.HasAuthoredValue():
                value = multiple.Get(tc)
                if not isinstance(value, (bool, int)):
                    raise SceneError(f"atmosphere {prim.GetPath()}: warpsky:atmosphere:multipleScattering must be a "
                                     f"bool, got {value!r}")
                kwargs["multiple_scattering"] = bool(value)
            return Atmosphere(**kwargs)
        return None

    # ----------------------------------------------------------------------------------------------- scene
    def scene_at(self, time=None, *, camera_path: str | None = None) -> Scene:
        """Everything warpsky renders, at ``time`` (None: the earliest time sample, like usdrecord)."""
        resolution, _ = self.render_settings()
        suns = self.read_suns(time)
        scene = Scene(
            camera=self.read_camera(camera_path, time),
            sun=suns[0] if suns else None,
            extra_suns=suns[1:],
            dome=self.read_dome(time),
            media=self.read_media(time),
            ground=self.read_ground(time),
            atmosphere=self.read_atmosphere(time),
            time_code=float("nan") if time is None else float(time),
            source=str(self.path),
            resolution=resolution,
            time_codes_per_second=float(self.stage.GetTimeCodesPerSecond()),
            stratiform_layers=self.read_stratiform_layers(time),
            meshes=self.read_meshes(time),
            decks=self.read_decks(time),
            fogs=self.read_fogs(time),
        )
        self.warn_ignored(time)
        return scene
