"""Host side of the single-scattering ray march."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.image import ImageLayer
from warpsky.core.resources import MemoryEstimate, WorkItem
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.skylight import ambient_settings
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.voxels.extent import camera_chord, grid_bytes, longest_chord, media_diagonal
from warpsky.media.voxels.voxel import VoxelMediaBuffers, check_field_count
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Scene
from warpsky.optics.kernels import DevicePhaseTables
from warpsky.optics.oriented_phase import oriented_phases
from warpsky.optics.oriented_sampling import oriented_table_bytes
from warpsky.optics.tables import build_tables
from warpsky.surfaces.plane import ground_struct
from warpsky.techniques.single_scatter.single_scatter_kernels import MarchSettings, single_scatter_kernel
from warpsky.techniques.technique import Technique


@documented
@dataclass(frozen=True)
class SingleScatterSettings(Settings):
    """Settings of the single-scattering ray march."""

    owner = "single_scatter"
    step_length: float | None = setting(None, unit="m", range="> 0", help="eye-ray step",
                                        auto="0.5 x the smallest voxel edge")
    shadow_step_length: float | None = setting(None, unit="m", range="> 0", help="shadow-ray step toward the sun",
                                               auto="1 x the smallest voxel edge")
    min_transmittance: float = setting(1.0e-4, range="[0, 1)", help="stop the eye march once the luminance "
                                       "transmittance falls below this (the view is this opaque)")
    skylight: bool = setting(True, help="light the media with the whole sky on two spherical-harmonic bands per "
                             "hemisphere: the analytic sky of a frame with a sky pass, the dome, the ground they "
                             "light, seen through the phase's asymmetry; 0: the dome's mean radiance alone, "
                             "occluded towards the zenith")

    def resolved(self, min_voxel_size: float) -> SingleScatterSettings:
        """These settings with the automatic step lengths filled in from the smallest voxel edge [m]."""
        return dataclasses.replace(
            self,
            step_length=self.step_length or 0.5 * min_voxel_size,
            shadow_step_length=self.shadow_step_length or 1.0 * min_voxel_size,
        )


#: Name under which the media's voxel values are kept on the device (:mod:`warpsky.core.device_buffers`), shared with
#: the path tracer: hybrid runs both on the same grids and holds one copy.
MEDIA_CACHE = "voxel_media"
#: The march's per-pixel outputs: kept across frames as :func:`warpsky.core.device_buffers.reusable` arrays
#: ``single_scatter:NAME``, each downloaded once at the end of a frame.
OUTPUTS = (("radiance", wp.vec3), ("transmittance", wp.vec3), ("depth", float), ("lookups", wp.int64))


class SingleScatter(Technique):
    """Single scattering of sunlight with exact per-step transmittance (Riley 2004, low-albedo mode, Fig. 13).

    Light scatters once: sun -> shadow march -> one scattering event (phase of the media at that point, weighted
    by their scattering coefficients, Riley Eq. 6) -> attenuated along the eye ray. A ground plane, if present,
    is lit by the sun through the media and hides what lies below it. No light bounces between the ground and
    the media, and no multiple scattering: clouds come out darker than in reality, which is the point of this
    mode as a reference for the faster multiple-scattering techniques. The sky (dome, analytic sky, the ground
    they light) scatters once too, from its first two spherical-harmonic bands per hemisphere, occluded towards
    the zenith and nadir (:mod:`~warpsky.light.skylight`; setting ``skylight``).
    """

    name = "single_scatter"
    Settings = SingleScatterSettings
    kernel_modules = ("warpsky.techniques.single_scatter.single_scatter_kernels",)

    def resolved_settings(self, scene: Scene) -> SingleScatterSettings:
        """The settings with the automatic step lengths filled in from the scene's smallest voxel edge."""
        if self.settings.step_length is not None and self.settings.shadow_step_length is not None:
            return self.settings
        sizes = [float(m.voxel_size.min()) for m in scene.media]
        return self.settings.resolved(min(sizes) if sizes else 1.0)

    #: Bytes per pixel of the outputs: radiance and transmittance RGB, depth (float32) and lookups (int64).
    PIXEL_BYTES = 36

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a frame allocates: the per-pixel outputs and the media's upload on the device (their host copies
        too when the device is a GPU; the upload's concatenated host copy; the column sums the vertical shadow
        depths read, as large as the grids), and the oriented ice's frame slices
        (kept per process on the host, and their upload: 30 MiB measured for the sundogs' two 11.9 MiB slices)."""
        pixels = width * height
        copies = 0 if is_cpu(self.device) else 1
        estimate = (MemoryEstimate()
                    .add("images", host=copies * pixels * self.PIXEL_BYTES, device=pixels * self.PIXEL_BYTES)
                    .add("grids", host=grid_bytes(scene), device=grid_bytes(scene))
                    .add("column sums", host=grid_bytes(scene), device=grid_bytes(scene)))
        slices = oriented_table_bytes(scene.media)[0]
        return estimate.add("oriented ice tables", host=slices, device=slices) if slices else estimate

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Worst-case grid lookups of the march (:func:`march_work`)."""
        settings = self.settings_for(scene)
        return march_work(scene, width * height, float(settings.step_length), float(settings.shadow_step_length))

    def render(self, scene: Scene, width: int, height: int) -> ImageLayer:
        """Render ``scene`` at ``width`` x ``height``; the camera is conformed to that aspect ratio here."""
        camera = scene.camera.conformed(width, height)
        settings = self.settings_for(scene)
        device = self.device
        started = time.perf_counter()
        species = scene.species
        check_field_count(scene.media, "single_scatter", " or use technique path_tracer")
        with wp.ScopedDevice(device), device_buffers.exclusive("single_scatter", device):
            tables = DevicePhaseTables.upload(build_tables(species).phase if species else None, device)
            media = VoxelMediaBuffers.upload(scene.media, camera.position, device, species, time_s=scene.time_s,
                                             cache=MEDIA_CACHE)
            radiance, transmittance, depth, lookups = outputs = [
                device_buffers.reusable(f"single_scatter:{name}", (height, width), dtype, device)
                for name, dtype in OUTPUTS]
            for array in outputs:
                array.zero_()
            march = MarchSettings()
            march.step = float(settings.step_length)
            march.shadow_step = float(settings.shadow_step_length)
            march.min_transmittance = float(settings.min_transmittance)
            march.environment, march.ground_ambient, march.ambient_on = ambient_settings(
                scene, skylight=bool(settings.skylight), traces_air=self.traces_air, device=device)
            kernel = single_scatter_kernel(bool(species), media.has_detail)
            inputs = [media.media, tables.values, oriented_phases(scene, device), pinhole_camera(camera, width, height),
                      sun_struct(sunlight(scene)),
                      ground_struct(scene.ground, camera.position), march, radiance, transmittance, depth, lookups]
            launch_rows(kernel, height, width, inputs, device)
            images = {name: device_buffers.download(f"single_scatter:{name}", array)
                      for (name, _), array in zip(OUTPUTS, outputs, strict=True)}
            seconds = time.perf_counter() - started
        return ImageLayer(images["radiance"], images["transmittance"], images["depth"],
                          stats={"seconds": seconds, "lookups": int(images["lookups"].sum()),
                            "settings": dataclasses.asdict(settings)})


def march_work(scene, pixels: int, step: float, shadow_step: float) -> list[WorkItem]:
    """Grid lookups of the single-scattering march: per eye step one lookup per medium and a shadow march through
    every medium towards the sun (one lookup per shadow step). The eye's path is the longest of the frame's rays
    through the media (:func:`camera_chord`, plus a tenth for rays between the sampled ones); the sun's, the
    longest segment along the sun that fits in each box (the boxes' diagonal without a sun)."""
    if not scene.media:
        return []
    eye_path = min(1.1 * camera_chord(scene), media_diagonal(scene.media))
    eye_steps = math.ceil(eye_path / step)
    sun = scene.sun.direction if scene.sun is not None else None
    shadow_steps = sum(math.ceil(min(media_diagonal((m,)), longest_chord(m, sun) if sun is not None else math.inf)
                                 / shadow_step) for m in scene.media)
    per_pixel = eye_steps * (len(scene.media) + shadow_steps) + shadow_steps
    return [WorkItem("march lookups", float(per_pixel), pixels,
                     f"step_length={step:g} m and shadow_step_length={shadow_step:g} m over "
                     f"{eye_path:.4g} m of media")]
