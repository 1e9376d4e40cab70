"""Host side of the unbiased volumetric path tracer (the reference every fast technique is measured against)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from warpsky.errors import UsageError
from warpsky.scene.model import Scene
from warpsky.techniques.base import Layer


@dataclass(frozen=True)
class PathTracerSettings:
    """Settings of the path tracer.

    ================= ===== ======= ========== =======================================================================
    name              unit  default range      meaning
    ================= ===== ======= ========== =======================================================================
    spp               --    64      >= 1       samples (paths) per pixel
    seed              --    0       >= 0       random seed; a seed gives the same image on the same device
    max_bounces       --    1024    >= 1       hard cap on scattering events per path; capped paths are counted in
                                               the stats (``capped_paths``): their missing light is a bias
    majorant_block    voxel 8       >= 1       edge of the coarse majorant cells; a huge value gives one global
                                               majorant per medium (slower, same expectation)
    environment       --    0       >= 0       uniform radiance arriving from every direction (grey), for furnace
                                               tests and overcast light; 0 = none
    samples_per_pass  --    auto    >= 1       paths per pixel per kernel launch (auto: 8 on the CPU, 64 on GPUs)
    pixel_jitter      --    0       0 or 1     0: every path through the pixel centre, like the other techniques
                                               (the reference compares pixel for pixel); 1: box-filtered pixels
    ================= ===== ======= ========== =======================================================================
    """

    technique = "path_tracer"
    spp: float = 64
    seed: float = 0
    max_bounces: float = 1024
    majorant_block: float = 8
    environment: float = 0.0
    samples_per_pass: float | None = None
    pixel_jitter: float = 0

    def __post_init__(self):
        if self.pixel_jitter not in (0, 1):
            raise UsageError(f"setting pixel_jitter must be 0 or 1, got {self.pixel_jitter}")
        for name in ("spp", "max_bounces", "majorant_block"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 1 and float(value).is_integer()):
                raise UsageError(f"setting {name} must be a whole number >= 1, got {value}")
        if not (self.seed >= 0 and float(self.seed).is_integer()):
            raise UsageError(f"setting seed must be a whole number >= 0, got {self.seed}")
        if not (math.isfinite(self.environment) and self.environment >= 0.0):
            raise UsageError(f"setting environment must be a finite radiance >= 0, got {self.environment}")
        if self.samples_per_pass is not None and not self.samples_per_pass >= 1:
            raise UsageError(f"setting samples_per_pass must be >= 1, got {self.samples_per_pass}")


def effective_block(shape: tuple[int, ...], block: int) -> int:
    """Majorant cell edge [voxels] actually used for a grid of ``shape``: at most its largest edge."""
    return max(1, min(int(block), max(shape)))


def majorant_grid(density: np.ndarray, block: int) -> np.ndarray:
    """Upper bounds of a trilinearly interpolated grid over coarse cells of ``block`` voxels.

    A point in cell c interpolates voxels c*block - 1 .. (c+1)*block, so each cell takes the maximum over its
    voxels dilated by one voxel (edge-clamped like the lookup). ``block`` is clamped to the largest grid edge
    (:func:`effective_block`), where one cell holds the whole grid.
    """
    d = np.asarray(density, dtype=np.float32)
    block = effective_block(d.shape, block)
    dilated = d.copy()
    for axis in range(3):
        padded = np.pad(dilated, [(1, 1) if a == axis else (0, 0) for a in range(3)], mode="edge")
        n = dilated.shape[axis]
        dilated = np.maximum(np.maximum(padded.take(range(0, n), axis), padded.take(range(1, n + 1), axis)),
                             padded.take(range(2, n + 2), axis))
    cells = [max(1, -(-n // block)) for n in d.shape]
    pad = [(0, c * block - n) for c, n in zip(cells, d.shape, strict=True)]
    full = np.pad(dilated, pad, mode="edge")
    return full.reshape(cells[0], block, cells[1], block, cells[2], block).max(axis=(1, 3, 5))


class PathTracer:
    """Unbiased volumetric path tracing of voxel media: delta tracking with local majorants, ratio-tracked
    next-event estimation toward the sun, phase sampling from the optics tables, all media combined (Riley Eq. 6),
    the scene's atmosphere as a Rayleigh medium of exponential density (then it also draws the sun's disk),
    Russian roulette, a Lambertian ground and an optional uniform environment. Progressive: samples accumulate
    per pixel with their running variance (``Layer.aovs["variance"]``, the variance of the pixel mean)."""

    name = "path_tracer"
    Settings = PathTracerSettings
    #: The atmosphere is traced as a medium: no separate sky pass.
    traces_air = True

    def __init__(self, settings: PathTracerSettings | None = None, *, device: str = "cpu"):
        self.settings = settings or PathTracerSettings()
        self.device = device

    def resolved_settings(self, scene: Scene) -> PathTracerSettings:
        per_pass = self.settings.samples_per_pass or (8 if str(self.device).startswith("cpu") else 64)
        return dataclasses.replace(self.settings, samples_per_pass=float(min(per_pass, self.settings.spp)))

    def render(self, scene: Scene, width: int, height: int, *, progress=None) -> Layer:
        import warp as wp

        from warpsky.device import launch_rows
        from warpsky.media.voxel import DETAIL_Z_MAX, VoxelMediaBuffers
        from warpsky.optics.kernels import DevicePhaseTables
        from warpsky.optics.tables import build_tables
        from warpsky.techniques.common import ground_struct, pinhole_camera, sun_struct
        from warpsky.techniques.path_tracer.kernels import (
            MAJORANT_MARGIN,
            Air,
            MajorantGrid,
            Majorants,
            PathSettings,
            PhaseTables,
            PixelSums,
            path_trace_kernel,
        )
        from warpsky.techniques.single_scatter.technique import scene_species

        settings = self.resolved_settings(scene)
        camera = scene.camera.conformed(width, height)
        device = self.device
        started = time.perf_counter()
        species = scene_species(scene)
        block = int(settings.majorant_block)
        with wp.ScopedDevice(device):
            tables = DevicePhaseTables.upload(build_tables(species).phase if species else None, device)
            media = VoxelMediaBuffers.upload(scene.media, camera.position, device, species, time_s=scene.time_s)
            mgrids, chunks, offset = [], [], 0
            for medium in scene.media:
                bound = majorant_grid(medium.density, block) * float(np.max(medium.extinction_scale))
                bound *= float(MAJORANT_MARGIN)
                if medium.detail is not None and medium.detail.active:
                    # animated detail multiplies the density by at most 1 + DETAIL_Z_MAX amplitude
                    bound *= 1.0 + float(DETAIL_Z_MAX) * float(medium.detail.amplitude)
                mg = MajorantGrid()
                mg.offset = offset
                mg.shape = wp.vec3i(*bound.shape)
                mg.block = float(effective_block(medium.density.shape, block))
                mgrids.append(mg)
                chunks.append(bound.reshape(-1))
                offset += bound.size
            majorants = wp.array(np.concatenate(chunks) if chunks else np.zeros(1, np.float32), dtype=float)
            mgrid_array = wp.array(mgrids if mgrids else [MajorantGrid()], dtype=MajorantGrid)
            shape = (height, width)
            radiance_sum = wp.zeros(shape, dtype=wp.vec3)
            radiance_sq = wp.zeros(shape, dtype=wp.vec3)
            transmittance_sum = wp.zeros(shape, dtype=wp.vec3)
            depth_sum = wp.zeros(shape, dtype=wp.vec2)
            counters = wp.zeros(shape, dtype=wp.vec2i)
            sun = scene.sun
            ground = scene.ground
            kernel = path_trace_kernel(ground is not None, bool(species), media.has_detail)
            air = Air()
            atmosphere = scene.atmosphere
            air.enabled = int(atmosphere is not None)
            if atmosphere is not None:
                air.beta_sl = wp.vec3(*atmosphere.beta_sea_level.tolist())
                air.gamma = float(atmosphere.gamma)
                air.camera_altitude = float(camera.position[1] + atmosphere.altitude)
                air.band = float(0.1 * atmosphere.scale_height)
            spp, per_pass = int(settings.spp), int(settings.samples_per_pass)
            majorant_data = Majorants()
            majorant_data.grids = mgrid_array
            majorant_data.values = majorants
            phase = PhaseTables()
            phase.values = tables.values
            phase.cdf = tables.cdf
            sums = PixelSums()
            sums.radiance_sum = radiance_sum
            sums.radiance_sq = radiance_sq
            sums.transmittance_sum = transmittance_sum
            sums.depth_sum = depth_sum
            sums.counters = counters
            done = 0
            while done < spp:
                count = min(per_pass, spp - done)
                path = PathSettings()
                path.environment = wp.vec3(float(settings.environment))
                path.seed = int(settings.seed)
                path.pixel_jitter = int(settings.pixel_jitter)
                path.first_sample = done
                path.sample_count = count
                path.max_bounces = int(settings.max_bounces)
                inputs = [media.media, majorant_data, phase, air, sun_struct(sun),
                          pinhole_camera(camera, width, height), ground_struct(ground, camera.position), path, sums]
                launch_rows(kernel, height, width, inputs, device)
                done += count
                if progress is not None:
                    progress(count)
            wp.synchronize_device(device)
            seconds = time.perf_counter() - started
            total = radiance_sum.numpy().astype(np.float64)
            squares = radiance_sq.numpy().astype(np.float64)
            mean = total / spp
            variance = np.maximum(squares / spp - mean**2, 0.0) / max(spp - 1, 1)  # of the mean
            depth = depth_sum.numpy()
            far = np.float32(camera.far)
            depth_mean = np.where(depth[..., 1] > 0, depth[..., 0] / np.maximum(depth[..., 1], 1), far)
            count_values = counters.numpy()
        return Layer(
            mean.astype(np.float32),
            (transmittance_sum.numpy() / spp).astype(np.float32),
            depth_mean.astype(np.float32),
            stats={
                "seconds": seconds,
                "settings": dataclasses.asdict(settings),
                "spp": spp,
                "tracking_steps": int(count_values[..., 0].sum()),
                "capped_paths": int(count_values[..., 1].sum()),
                "majorant_cells": int(offset),
            },
            aovs={"variance": variance.astype(np.float32)},
        )
