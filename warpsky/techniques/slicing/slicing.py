"""Host side of half-angle slicing: slice geometry, Ams tables for every medium, the slice loop, the ground."""

from __future__ import annotations

import dataclasses
import enum
import functools
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.errors import UsageError
from warpsky.core.image import ImageLayer
from warpsky.core.resources import MemoryEstimate, WorkItem
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.skylight import ambient_settings
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.voxels.extent import grid_bytes
from warpsky.media.voxels.voxel import VoxelMediaBuffers, check_field_count
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import PhaseKind, Projection, Scene
from warpsky.optics.grid import angle_grid, delta_table, normalise, sphere_integral
from warpsky.optics.oriented_phase import oriented_phases
from warpsky.optics.phase import phase_numpy
from warpsky.optics.prepare import TableNeed
from warpsky.optics.tables import ams_table, phase_table
from warpsky.surfaces.plane import ground_struct
from warpsky.techniques.slicing.ground import ground_kernel
from warpsky.techniques.slicing.occlusion import sky_shadow
from warpsky.techniques.slicing.slicing_kernels import AmsTables, SliceFrame, slicing_kernels
from warpsky.techniques.slicing.sweep import (
    SliceSweep,
    SweepBuffers,
    capture_warning,
    chunk_planes,
    run_sweep,
    sweep_lock,
)
from warpsky.techniques.technique import Technique

#: Bytes per pixel of the ground pass's device copy of the layer.
LAYER_DEVICE_BYTES = 28


class LightEquation(enum.IntEnum):
    """How the light buffer is updated from one slice to the next (the ``light_equation`` setting)."""

    CONTINUOUS = 0
    EQ24 = 24
    EQ25 = 25


@documented
@dataclass(frozen=True)
class SlicingSettings(Settings):
    """Settings of half-angle slicing.

    Defaults come from ``warpsky bench error-vs-time usd_scenes/cumulus.usda`` (128x85, path tracer 4096 spp): with
    light_equation 0 the relative RMSE is 0.519 / 0.521 / 0.521 at 32 / 128 / 512 slices (converged by 32; Eq. 24
    wanders 0.563 / 0.448 / 0.502): on smooth media 32 slices suffice, so ``auto`` sizes the spacing by the voxels
    instead, which is what keeps thin anvils and rain sheets free of slice banding. ξ = 0.1 takes the bias from -0.41
    to -0.21 and the RMSE from 0.68 to 0.52 (ξ = 0.15: bias -0.11, RMSE 0.51, p95 0.98 against 0.90). The rest is
    the model's: the light buffer carries only forward-scattered light. Set ξ = 0 for thin media, where it only
    adds light.
    """

    owner = "slicing"
    slice_count: int | None = setting(None, range=">= 1", help="planes through the media's extent along the "
                                      "half-angle axis (thin sheets seen edge-on band when the spacing exceeds "
                                      "their thickness)", auto="one per voxel edge of the finest field across that "
                                      "extent, clamped to 32..512")
    light_resolution: int = setting(256, unit="texel", range=">= 2", help="edge of the square light buffer")
    eye_samples: float = setting(2.0, unit="1/voxel", range="> 0", help="samples of each eye ray per voxel edge "
                                 "of the finest field inside every slice's slab (at least one per slab). One per "
                                 "slice striped thin sheets seen obliquely row by row (a uniform 4-voxel sheet seen "
                                 "as the storm's anvil is: rows 1.1% off a smooth profile); 1: 0.4%, 2: 0.1%, "
                                 "more gains nothing")
    xi: float = setting(0.01, unit="1/sr", range=">= 0", help="Riley's back-scatter term added to the phase in the "
                        "eye gather, for media without their own warpsky:slicing:xi; 0.01 lowered the median, p90 "
                        "and worst error together on the validation family's tune half (0.1 tripled the p90)")
    low_albedo: bool = setting(False, help="1: Riley's low-albedo comparison mode (Fig. 13)")
    orders: int = setting(60, range=">= 1", help="highest multiple-scattering order tabulated (Ams_0..N)")
    light_equation: LightEquation = setting(
        LightEquation.CONTINUOUS, help="light-buffer update: 0 = the continuous limit of Riley's model, dI/dtau = "
        "-(1 - alpha F_{n+1}) I solved per step (second order in the slice spacing); 24 = Riley Eq. 24 (first "
        "order); 25 = his GPU shortcut Eq. 25 (tends to no attenuation as slices are added)")
    skylight: bool = setting(True, help="light the media with the whole sky on two spherical-harmonic bands per "
                             "hemisphere (the analytic sky of a frame with a sky pass, the dome, the ground they "
                             "light) through the phase's asymmetry, occluded towards the zenith and nadir; "
                             "0: the dome's mean radiance alone, unoccluded")


@functools.lru_cache(maxsize=64)
def analytic_ams(kind: PhaseKind, g: float, orders: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form Ams_0..N (N+1, 3, M) and F_n (N+1, 3) for an analytic phase: HG(g)^{*n} = HG(g^n); Rayleigh
    (1/4pi)(1 + 5 (1/10)^n P_2); isotropic 1/4pi. Kept per (kind, g, orders): a frame's tables cost no host time
    after the first (callers must not write into the arrays)."""
    mu = np.cos(angle_grid())
    rows = [delta_table()]
    for n in range(1, orders + 1):
        if kind == PhaseKind.HG:
            rows.append(normalise(phase_numpy(PhaseKind.HG, g**n, mu)[None])[0])
        elif kind == PhaseKind.RAYLEIGH:
            rows.append(normalise(((1.0 + 5.0 * 0.1**n * 0.5 * (3 * mu * mu - 1)) / (4 * np.pi))[None])[0])
        else:
            rows.append(np.full_like(mu, 1.0 / (4.0 * np.pi)))
    ams = np.repeat(np.stack(rows)[:, None, :], 3, axis=1)
    return ams, sphere_integral(ams, upto=0.5 * np.pi)


def slice_axis(camera, toward_sun: np.ndarray) -> tuple[np.ndarray, int]:
    """(unit slice axis, 1 if the eye composites front to back): the half-angle between the light's travel and the
    view (sun behind the viewer), else between the light and the reversed view (Kniss et al.)."""
    view = -np.asarray(camera.rotation, dtype=np.float64)[:, 2]
    light = -np.asarray(toward_sun, dtype=np.float64)
    if float(view @ light) > 0.0:  # sun behind the viewer: light and eye advance together, front to back
        axis, front_to_back = view + light, 1
    else:  # sun ahead: slices run from the far side towards the eye, back to front
        axis, front_to_back = light - view, 0
    return axis / np.linalg.norm(axis), front_to_back  # never zero: light = -view gives 2 light, = view 2 view


def media_corners(scene: Scene, origin: np.ndarray) -> np.ndarray:
    """World corners of every medium's index box relative to ``origin``, (8 x media, 3)."""
    return np.concatenate([m.world_corners() for m in scene.media]) - np.asarray(origin, dtype=np.float64)


class Slicing(Technique):
    """Half-angle slicing with multiple-scattering phase functions (Riley 2004 §4.2, §5): one sweep through the
    media carrying a light buffer (intensity and expected scattering count per channel, Eqs. 22, 25) and the eye
    buffer (Eq. 26 with Ams_{n+1} of the mixed phase at each sample)."""

    name = "slicing"
    Settings = SlicingSettings
    kernel_modules = ("warpsky.techniques.slicing.slicing_kernels",)

    #: Bounds of the automatic slice count.
    AUTO_SLICES = (32, 512)

    def resolved_settings(self, scene: Scene) -> SlicingSettings:
        """The settings with ``slice_count = auto`` replaced by one slice per voxel edge of the finest field across
        the media's depth along the half-angle axis (32..512). Refuses an orthographic camera: the slices and
        the eye buffers are laid out for rays from the eye."""
        if scene.camera.projection is Projection.ORTHOGRAPHIC:
            raise UsageError(f"camera {scene.camera.name} is orthographic, which slicing does not render (it slices "
                             "from the eye); use technique single_scatter, path_tracer or hybrid")
        if self.settings.slice_count is not None:
            return self.settings
        count = self.AUTO_SLICES[0]
        if scene.media:
            light = sunlight(scene)
            toward_sun = light.direction if light is not None else np.array([0.0, 1.0, 0.0])
            axis, _ = slice_axis(scene.camera, toward_sun)
            along = media_corners(scene, scene.camera.position) @ axis
            finest = min(float(m.voxel_size.min()) for m in scene.media)
            count = int(np.clip(np.ceil((along.max() - along.min()) / finest), *self.AUTO_SLICES))
        return dataclasses.replace(self.settings, slice_count=count)

    #: Bytes per pixel: radiance, transmittance (RGB) and depth moments (vec2) on the device; on the host the
    #: layer, its depth division and the ground pass's copies.
    PIXEL_BYTES = 32
    HOST_PIXEL_BYTES = 72

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a frame allocates: the eye buffers, the two light buffers (``light_resolution``^2 RGB each), their
        copies at a chunk's slice planes and the media's upload (its column sums as large)."""
        res = int(self.settings.light_resolution)
        planes = int(self.settings.slice_count or self.AUTO_SLICES[1]) if scene.media else 0
        pixels = width * height
        copies = 0 if is_cpu(self.device) else 1
        return (MemoryEstimate()
                .add("images", host=pixels * (self.HOST_PIXEL_BYTES + copies * self.PIXEL_BYTES),
                     device=pixels * (self.PIXEL_BYTES + LAYER_DEVICE_BYTES))
                .add("light buffers", device=2 * res * res * 12 * (1 + chunk_planes(planes, res, self.device)))
                .add("grids", host=grid_bytes(scene), device=grid_bytes(scene))
                .add("column sums", host=grid_bytes(scene), device=grid_bytes(scene)))

    def tables(self, scene: Scene) -> list[TableNeed]:
        """A phase table and the Ams_0..orders tables (at the ``orders`` setting) per species."""
        orders = int(self.settings.orders)
        needs = []
        for name in scene.species:
            needs.append(TableNeed(name, "phase", functools.partial(phase_table, name)))
            needs.append(TableNeed(name, "ams", functools.partial(ams_table, name, orders), f"{orders}"))
        return needs

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Lookups per pixel (one per medium and slice) and per light-buffer texel (the same)."""
        if not scene.media:
            return []
        settings = self.settings_for(scene)
        slices, res = int(settings.slice_count), int(settings.light_resolution)
        per_pixel = float(slices * len(scene.media))
        return [WorkItem("slice lookups", per_pixel, width * height, f"slice_count={slices}"),
                WorkItem("light-buffer lookups", per_pixel, res * res,
                         f"slice_count={slices}, light_resolution={res}")]

    def _tables(self, scene: Scene, species: tuple[str, ...], orders: int):
        """One Ams table per species and per distinct analytic phase; the table index of every medium."""
        tables, forwards, index, keys = [], [], [], {}
        for medium in scene.media:  # one table per species / analytic phase, however many media share it
            key = ("species", medium.species) if medium.species else ("phase", int(medium.phase.kind),
                                                                        float(medium.phase.g))
            if key not in keys:
                if medium.species:
                    ams, forward = ams_table(medium.species, orders)
                else:
                    ams, forward = analytic_ams(medium.phase.kind, medium.phase.g, orders)
                keys[key] = len(tables)
                tables.append(ams)
                forwards.append(forward)
            index.append(keys[key])
        return tables, forwards, index

    def _ams_tables(self, scene: Scene, species: tuple[str, ...], orders: int, xi: float) -> AmsTables:
        """The device Ams tables of the scene's media, with each medium's table index and xi (its own
        ``warpsky:slicing:xi`` or the setting ``xi``)."""
        tables, forwards, index = self._tables(scene, species, orders)
        xi_of = [xi if m.slicing_xi is None else m.slicing_xi for m in scene.media]
        ams = AmsTables()  # kept on the device across frames, uploaded again only when a table changes
        ams.ams = device_buffers.upload("slicing:ams", np.stack(tables).astype(np.float32).reshape(-1), float,
                                        self.device)
        ams.forward = device_buffers.upload("slicing:forward", np.stack(forwards).astype(np.float32).reshape(-1),
                                            float, self.device)
        ams.orders = orders + 1
        ams.table_of = device_buffers.upload("slicing:table_of", np.asarray(index, dtype=np.int32), int, self.device)
        ams.xi_of = device_buffers.upload("slicing:xi_of", np.asarray(xi_of, dtype=np.float32), float, self.device)
        return ams

    def render(self, scene: Scene, width: int, height: int) -> ImageLayer:
        settings = self.settings_for(scene)
        camera = scene.camera.conformed(width, height)
        device = self.device
        started = time.perf_counter()
        far = np.float32(camera.far)
        with wp.ScopedDevice(device):
            # uploaded for the sweep and the ground pass only when the contents changed since the last frame (with
            # detail this also advects its noise to time_s)
            media = VoxelMediaBuffers.upload(scene.media, camera.position, device, scene.species, time_s=scene.time_s,
                                             cache="slicing")
            # the sky's light on the media and the ground: (environment, E / pi at the ground, 1 when any)
            ambient = ambient_settings(scene, skylight=bool(settings.skylight), traces_air=self.traces_air,
                                       device=device)
            if scene.media:
                check_field_count(scene.media, "slicing", " or use technique path_tracer")
                sweep = self._sweep(scene, settings, camera, width, height, media, ambient)
                with sweep_lock(device):
                    how = run_sweep(sweep)
                    warning = capture_warning(device)
                    radiance, transmittance, depth = self._finish(scene, camera, width, height, media, sweep.buffers,
                                                                  ambient)
                slices = len(sweep.planes)
            else:
                how, slices, warning = "none", 0, None
                shape = (height, width)
                images = [wp.zeros(shape, dtype=wp.vec3), wp.full(shape, wp.vec3(1.0, 1.0, 1.0), dtype=wp.vec3),
                          wp.full(shape, far, dtype=float)]
                if scene.ground is not None:
                    self._ground(scene, camera, width, height, media, ambient, *images)
                radiance, transmittance, depth = (image.numpy() for image in images)
            layer = ImageLayer(radiance, transmittance, depth, stats={
                "seconds": time.perf_counter() - started, "settings": dataclasses.asdict(settings),
                "slices": slices, "sweep": how}, warnings=[warning] if warning else [])
        return layer

    def _finish(self, scene: Scene, camera, width: int, height: int, media: VoxelMediaBuffers,
                buffers: SweepBuffers, ambient: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(radiance, transmittance, depth [m]) of the frame after its sweep: the mean depth divided out on the
        host, the ground drawn on the sweep's images still on the device, then one download per image."""
        far = np.float32(camera.far)
        depth_sum = device_buffers.download("slicing:depth_sum", buffers.depth_sum)
        depth = np.where(depth_sum[..., 1] > 1e-6, depth_sum[..., 0] / np.maximum(depth_sum[..., 1], 1e-30), far)
        depth = depth.astype(np.float32)
        if scene.ground is not None:
            depth_image = device_buffers.reusable("slicing:depth", (height, width), float, self.device)
            depth_image.assign(depth)
            self._ground(scene, camera, width, height, media, ambient, buffers.radiance, buffers.transmittance,
                         depth_image)
            depth = device_buffers.download("slicing:depth", depth_image)
        return (device_buffers.download("slicing:radiance", buffers.radiance),
                device_buffers.download("slicing:transmittance", buffers.transmittance), depth)

    def _sweep(self, scene: Scene, settings: SlicingSettings, camera, width: int, height: int,
               media: VoxelMediaBuffers, ambient: tuple) -> SliceSweep:
        """The frame's sweep: slice geometry, Ams tables and kernel arguments, on the kept ``slicing:*`` buffers."""
        sun = sunlight(scene)
        toward_sun = sun.direction if sun is not None else np.array([0.0, 1.0, 0.0])  # unlit: any axis
        res = int(settings.light_resolution)
        frame, planes = self._frame(scene, camera, toward_sun, int(settings.slice_count), res)
        # a sun set behind the horizon lights nothing, but the media still hide what lies behind them
        start = sun.irradiance if sun is not None and sun.lit else np.zeros(3)
        environment, _, ambient_on = ambient
        eye_kernel, light_kernel = slicing_kernels(bool(settings.low_albedo), int(settings.light_equation),
                                                   media.has_detail, bool(ambient_on))
        return SliceSweep(
            device=self.device, eye_kernel=eye_kernel, light_kernel=light_kernel, media=media.media,
            tables=self._ams_tables(scene, scene.species, int(settings.orders), settings.xi),
            oriented=oriented_phases(scene, self.device, cache="slicing"),
            shadow=sky_shadow(media, media_corners(scene, camera.position), float(media.min_voxel_size),
                              self.device, on=bool(ambient_on) and bool(settings.skylight)),
            cam=pinhole_camera(camera, width, height), frame=frame, sun=sun_struct(sun), ambient=environment,
            sample_length=float(media.min_voxel_size) / float(settings.eye_samples), planes=planes,
            start=tuple(np.asarray(start, dtype=np.float64).tolist()),
            buffers=SweepBuffers.kept(height, width, res, planes, self.device))

    @staticmethod
    def _frame(scene: Scene, camera, toward_sun: np.ndarray, slice_count: int, light_res: int):
        """Slice axis and order (half-angle, Kniss et al.), slice planes and the light buffer's square."""
        axis, front_to_back = slice_axis(camera, toward_sun)
        light = -np.asarray(toward_sun, dtype=np.float64)  # the way light travels
        corners = media_corners(scene, camera.position)
        along = corners @ axis
        lo, hi = float(along.min()), float(along.max())
        spacing = (hi - lo) / slice_count
        planes = lo + (np.arange(slice_count) + 0.5) * spacing
        helper = np.array([0.0, 1.0, 0.0]) if abs(light[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(helper, light)
        u /= np.linalg.norm(u)
        v = np.cross(light, u)
        pu, pv = corners @ u, corners @ v
        size = max(pu.max() - pu.min(), pv.max() - pv.min()) * 1.02 + 1e-6
        centre_u, centre_v = 0.5 * (pu.max() + pu.min()), 0.5 * (pv.max() + pv.min())
        origin = u * (centre_u - 0.5 * size) + v * (centre_v - 0.5 * size)
        frame = SliceFrame()
        frame.axis = wp.vec3(*axis.tolist())
        frame.light_dir = wp.vec3(*light.tolist())
        frame.light_u = wp.vec3(*u.tolist())
        frame.light_v = wp.vec3(*v.tolist())
        frame.light_origin = wp.vec3(*origin.tolist())
        frame.light_size = float(size)
        frame.light_res = int(light_res)
        frame.spacing = float(spacing)
        frame.front_to_back = int(front_to_back)
        return frame, planes

    def _ground(self, scene: Scene, camera, width: int, height: int, media: VoxelMediaBuffers, ambient: tuple,
                radiance: wp.array, transmittance: wp.array, depth: wp.array) -> None:
        """Lambertian ground behind the media, lit by the sun through them (shadow rays marched per voxel), drawn
        into the device images ``radiance``, ``transmittance`` (RGB) and ``depth`` [m]; ``media`` is the sweep's
        upload (:class:`~warpsky.media.voxels.voxel.VoxelMediaBuffers`); the sky above it lights it too, occluded
        towards
        the zenith."""
        _, ground_sky, ambient_on = ambient
        launch_rows(ground_kernel(media.has_detail, bool(ambient_on)), height, width, [
            media.media, pinhole_camera(camera, width, height), sun_struct(sunlight(scene)),
            ground_struct(scene.ground, camera.position), float(media.min_voxel_size), ground_sky,
            radiance, transmittance, depth], self.device)
