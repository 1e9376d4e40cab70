"""Host side of the unbiased volumetric path tracer (the reference every fast technique is measured against)."""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.image import ImageLayer
from warpsky.core.resources import AOV_BYTES, MemoryEstimate, WorkItem
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.dome import dome_struct
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.air.medium import air_struct
from warpsky.media.stratiform.stratiform_voxels import LAYER_SPECIES
from warpsky.media.voxels.detail_bake import baked_bytes, baked_media
from warpsky.media.voxels.extent import grid_bytes
from warpsky.media.voxels.voxel import VoxelMediaBuffers
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Scene
from warpsky.optics.kernels import DevicePhaseTables
from warpsky.optics.oriented_phase import oriented_phases
from warpsky.optics.oriented_sampling import continuation_tables
from warpsky.optics.phase_sampling import phase_tables_struct
from warpsky.optics.prepare import TableNeed
from warpsky.optics.tables import build_tables, phase_table
from warpsky.surfaces.plane import ground_struct
from warpsky.techniques.path_tracer.deck_media import deck_voxel_features, deck_voxel_memory, with_deck_as_media
from warpsky.techniques.path_tracer.fog_media import fog_tracking
from warpsky.techniques.path_tracer.forward_cut import (
    CutMedia,
    check_cut_settings,
    cut_feature,
    cut_medium,
    cut_tables,
    cuts,
)
from warpsky.techniques.path_tracer.majorants import medium_block, upload_majorants
from warpsky.techniques.path_tracer.path_tracer_kernels import (
    PathSettings,
    PixelSums,
    SampleResult,
    path_trace_kernel,
    sum_samples_kernel,
)
from warpsky.techniques.path_tracer.stratiform_media import (
    layer_voxel_memory,
    stratiform_voxel_features,
    with_stratiform_as_media,
)
from warpsky.techniques.path_tracer.sun_lobe import AUTO_LOBE, lobe_asymmetry
from warpsky.techniques.path_tracer.surface_hits import traced_meshes
from warpsky.techniques.single_scatter.single_scatter import MEDIA_CACHE
from warpsky.techniques.technique import Technique


@documented
@dataclass(frozen=True)
class PathTracerSettings(Settings):
    """Settings of the path tracer."""

    owner = "path_tracer"
    spp: int = setting(64, range=">= 1", help="samples (paths) per pixel")
    seed: int = setting(0, range=">= 0", help="random seed; a seed gives the same image on the same device")
    max_bounces: int = setting(1024, range=">= 1", help="hard cap on scattering events per path; capped paths are "
                               "counted in the stats (capped_paths): their missing light is a bias (raise it for "
                               "references of storms and thick decks: hybrid's default is 16384)")
    bake_detail: bool = setting(False, help="1: trace the media's animated detail baked for the frame into a grid "
                                "within a detail texel (one lookup per collision, majorants of the detailed density; "
                                "a resampled field, not the procedural one); 0: the procedural detail at every "
                                "collision (exact)")
    similarity_order: int = setting(0, range=">= 0", help="after this many scattering events a path continues "
                                    "through the media reduced by high-order similarity (sigma_s (1 - g), "
                                    "isotropic; Zhao et al. 2014): far fewer collisions in thick forward-scattering "
                                    "media, biased by what the angular structure of such light still carries; 0 = "
                                    "exact")
    forward_cut: float = setting(0.0, unit="deg", range="[0, 30]", help="after its first event a path treats "
                                 "light a tabulated species deflects by less than this angle (its diffraction "
                                 "peak) as not scattered: sigma_s (1 - f), the phase flattened below the cut "
                                 "(delta-M). Removes the heavy tail of next-event estimation in thick Mie clouds; "
                                 "biased by the peak's angular spread; 0 = exact")
    sun_lobe: float | None = setting(-1.0, range="[-1, 0.99]", auto=AUTO_LOBE, help="g of a lobe around the sun "
                                     "from which each event also draws a way to the next, sharing its sunlight by "
                                     "the balance heuristic (sun_lobe.py; unbiased); -1 = none")
    majorant_block: int | None = setting(None, unit="voxel", range=">= 1", auto="per medium, 8 down to 2 voxels so "
                                         "that a cell edge holds at most 6 optical depths at the densest point",
                                         help="edge of the coarse majorant cells; a huge value gives one global "
                                         "majorant per medium (slower, same expectation)")
    environment: float = setting(0.0, range=">= 0", help="uniform radiance arriving from every direction (grey), "
                                 "for furnace tests and overcast light; 0 = none")
    samples_per_pass: int | None = setting(None, range=">= 1", help="paths per pixel per kernel launch",
                                           auto="8 on the CPU, 64 on GPUs (at most spp)")
    pixel_jitter: bool = setting(False, help="0: every path through the pixel centre, like the other techniques "
                                 "(the reference compares pixel for pixel); 1: box-filtered pixels")
    layer_voxel: float | None = setting(None, unit="m", range="> 0", help="vertical edge of the voxels a stratiform "
                                        "layer is traced as (partial volume: each column's optical depth is exact)",
                                        auto="the layer's largest thickness / 32, grown with layer_voxel_width until "
                                        "the grid fits 2^27 voxels")
    layer_voxel_width: float | None = setting(None, unit="m", range="> 0", help="horizontal edge of those voxels",
                                              auto="half a texel of the layer's thickness map, grown with layer_voxel "
                                              "until the grid fits 2^27 voxels")
    deck_extent: float | None = setting(None, unit="m", range="> 0", help="half-size of the square around the "
                                        "camera over which a height-field cloud deck and its haze are voxelised",
                                        auto="where the frame's rays enter the deck's band or haze, plus the "
                                        "distance that dims them below 1%, at most 50 km")
    deck_voxel_width: float | None = setting(None, unit="m", range="> 0", help="horizontal edge of the deck's "
                                             "voxels (partial volume: 4x4 sub-columns when cheap)",
                                             auto="the deck's smallest feature / 8, grown with deck_voxel until "
                                             "the grid fits 2^27 voxels")
    deck_voxel: float | None = setting(None, unit="m", range="> 0", help="vertical edge of the deck's voxels "
                                       "(each column's optical depth is exact)", auto="the deck's band height / 32, "
                                       "grown with deck_voxel_width until the grid fits 2^27 voxels")


class PathTracer(Technique):
    """Unbiased volumetric path tracing of voxel media: delta tracking with local majorants, ratio-tracked
    next-event estimation toward the sun, phase sampling from the optics tables, all media combined (Riley Eq. 6),
    the scene's atmosphere as a Rayleigh medium of exponential density (then it also draws the sun's disk),
    Russian roulette, a Lambertian ground, an optional uniform environment and the scene's dome (light of paths
    that escape after a bounce; the composite draws it behind the camera rays). Stratiform layers are voxelised
    (:mod:`.layer_media`) and traced as media, and so is a height-field cloud deck with its haze
    (:mod:`.deck_media`); analytic fog (Biri et al. 2002) is traced as a medium of closed-form density
    (:mod:`.fog_media`). Progressive: samples accumulate per pixel with their running
    variance (``ImageLayer.aovs["variance"]``, the variance of the pixel mean)."""

    name = "path_tracer"
    Settings = PathTracerSettings
    #: The atmosphere is traced as a medium: no separate sky pass.
    traces_air = True
    #: It does not run next to the stratiform pass ...
    renders_layers = False
    #: ... it traces the layers itself, voxelised (``layer_voxel``, ``layer_voxel_width``).
    traces_layers = True
    #: It traces a height-field cloud deck itself too, voxelised (``deck_extent``, ``deck_voxel*``).
    traces_decks = True
    #: And analytic fog, as a medium whose density is evaluated in closed form (:mod:`.fog_media`): no fog pass.
    traces_fog = True
    traces_dome = True
    #: It traces the scene's triangle meshes itself, inside its paths (:mod:`.surfaces`): no surfaces pass.
    traces_meshes = True
    aovs = {"variance": "RGB"}
    kernel_modules = ("warpsky.techniques.path_tracer.path_tracer_kernels",)
    settings_notes = ("--spp N and --seed S are shorthands for --set spp=N / seed=S. Writes a variance.RGB AOV "
                      "(variance of each pixel's mean); the header holds spp, paths and cappedPaths (a warning above "
                      "0.1%).")

    def resolved_settings(self, scene: Scene) -> PathTracerSettings:
        """The settings with ``samples_per_pass = auto`` filled in for the device, and at most ``spp``."""
        check_cut_settings(float(self.settings.forward_cut), int(self.settings.similarity_order))
        given = self.settings.samples_per_pass
        if given is not None and given <= self.settings.spp:
            return self.settings
        per_pass = given or (8 if is_cpu(self.device) else 64)
        return dataclasses.replace(self.settings, samples_per_pass=min(per_pass, self.settings.spp))

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a frame allocates: a :class:`PixelSums` (and on a GPU the paths of one launch when the frame is
        small), the float64 sums of :func:`sums_layer`, the variance AOV, the media with their majorants, and the
        meshes it traces (their points, indices and Warp's BVH, as the surfaces pass counts them)."""
        settings = self.settings_for(scene)
        pixels = width * height
        estimate = (path_tracing_memory(scene, pixels, settings.majorant_block, self.device,
                                        int(settings.samples_per_pass), bake_detail=bool(settings.bake_detail))
                    .add("images", host=pixels * SUMS_LAYER_BYTES)
                    .add("AOVs", host=pixels * AOV_BYTES)
                    .merge(layer_voxel_memory(scene, settings))
                    .merge(deck_voxel_memory(scene, settings, width, height)))
        triangles = sum(len(m.triangles) for m in scene.meshes)
        return estimate.add("meshes", host=40 * triangles, device=88 * triangles) if triangles else estimate

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Worst-case path events: every path runs to the bounce cap."""
        settings = self.settings_for(scene)
        return [path_work(settings, width * height)]

    def tables(self, scene: Scene) -> list[TableNeed]:
        """A phase table per species, and the stratus table of the layers it voxelises."""
        needs = super().tables(scene)
        if scene.stratiform_layers and LAYER_SPECIES not in scene.species:
            needs.append(TableNeed(LAYER_SPECIES, "phase", functools.partial(phase_table, LAYER_SPECIES)))
        return needs

    def features(self, scene: Scene, width: int, height: int, features: dict[str, str]) -> dict[str, str]:
        """The lines of the layers and the deck it voxelises, and of the forward cut."""
        settings = self.settings_for(scene)
        if scene.stratiform_layers:
            features = stratiform_voxel_features(scene, settings, features)
        if scene.decks:
            features = deck_voxel_features(scene, settings, width, height, features)
        return cut_feature(scene, float(settings.forward_cut), features)

    def for_extra_light(self) -> PathTracer:
        """Itself, without the uniform ``environment`` (it lights the first run only)."""
        if not self.settings.environment:
            return self
        return self.with_settings(dataclasses.replace(self.settings, environment=0.0))

    def render(self, scene: Scene, width: int, height: int, *, progress=None) -> ImageLayer:
        settings = self.settings_for(scene)
        started = time.perf_counter()
        scene = with_deck_as_media(with_stratiform_as_media(scene, settings, self.device), settings, width, height,
                                   device=self.device)
        with device_buffers.exclusive("path_tracer", self.device):  # the sums and kept paths below
            tracing = PathTracing(scene, width, height, settings, self.device, meshes=True, fog=True)
            sums = pixel_sums((height, width), self.device, name="path_tracer")
            spp, per_pass = int(settings.spp), int(settings.samples_per_pass)
            done = 0
            while done < spp:
                count = min(per_pass, spp - done)
                tracing.launch(sums, done, count)
                done += count
                if progress is not None:
                    progress(count)
            wp.synchronize_device(self.device)
            seconds = time.perf_counter() - started
            layer = sums_layer([sums], spp, float(tracing.camera.far), name="path_tracer")
        layer.stats = {"seconds": seconds, "settings": dataclasses.asdict(settings), "spp": spp, **layer.stats,
                       "majorant_cells": tracing.majorant_cells}
        return layer


#: Name under which media with baked detail are kept on the device (the exact march keeps the procedural ones).
BAKED_CACHE = "voxel_media:baked"


class PathTracing:
    """The path tracer set up for one frame: tables, media, majorants and the specialised kernel uploaded once;
    :meth:`launch` adds paths per pixel to a :class:`PixelSums` (progressive passes reuse everything).

    ``air=False`` leaves the atmosphere out (the sky pass draws it); ``fog=True`` traces the scene's analytic fogs
    (:mod:`.fog_media`; else the fog pass draws them); ``multiple_only`` keeps only light scattered
    at least twice, for techniques that march single scattering exactly; ``air_by_table`` leaves out the paths
    whose first event is in the air (the sky pass's multiple-scattering table holds their light); ``meshes``
    traces the scene's meshes inside the paths (else another pass draws them and camera rays end at its depth,
    ``Camera.opaque_depth``); ``first_end`` (world altitudes low, high [m]) ends the paths whose camera ray
    scatters first in that band (another pass draws it: the stratiform layers). The media's
    values (under :data:`MEDIA_CACHE`, shared with the single-scattering march) and majorants go through
    :func:`warpsky.core.device_buffers.upload`: the next frame of a batch with the same grids copies nothing; the sums
    and kept paths are :func:`warpsky.core.device_buffers.reusable` arrays under ``buffer_name``.

    How a launch runs (:func:`per_sample_launches`): one thread per pixel looping over the launch's paths, or,
    for a frame too small to fill a GPU, one thread per path and pixel writing to a kept buffer, then one thread
    per pixel adding them in path order. Both add the same float32 values in the same order, so a pixel depends
    on the seed and the path count alone, however the paths are split into launches; ``per_sample`` forces the
    choice (tests run both on the CPU)."""

    def __init__(self, scene: Scene, width: int, height: int, settings: PathTracerSettings, device: str, *,
                 air: bool = True, multiple_only: bool = False, scale: int = 1, buffer_name: str = "path_tracer",
                 per_sample: bool | None = None, air_by_table: bool = False, meshes: bool = False,
                 fog: bool = False, first_end: tuple[float, float] | None = None):
        # a coarser film's pixel is box-filtered, as the frame's pixels it covers average it
        self.settings = dataclasses.replace(settings, pixel_jitter=settings.pixel_jitter or scale > 1)
        self.air_by_table = bool(air_by_table and air)
        self.device = device
        camera = scene.camera.conformed(width, height)
        self.frame_camera, self.frame_size = camera, (width, height)  # the frame's own film, before any coarsening
        self.buffer_name, self.per_sample = buffer_name, per_sample
        if scale > 1:
            camera, width, height = coarse_camera(camera, width, height, scale)
        self.width, self.height = width, height
        self.multiple_only = multiple_only
        self.camera = camera
        self.first_end = None if first_end is None else tuple(float(v) - float(camera.position[1]) for v in first_end)
        species = scene.species
        media_list, cache = scene.media, MEDIA_CACHE
        if settings.bake_detail and any(m.has_detail for m in scene.media):
            media_list, cache = baked_media(scene.media, scene.time_s, camera.position, device), BAKED_CACHE
        self.forward_cut = cuts(scene, float(settings.forward_cut))
        self.lobe_g = lobe_asymmetry(scene, settings.sun_lobe, meshes=meshes, fog=fog)
        with wp.ScopedDevice(device):
            phase = build_tables(species).phase if species else None
            cut = cut_tables(species, phase, float(settings.forward_cut)) if self.forward_cut else None
            tables = DevicePhaseTables.upload(phase if cut is None else cut.phase, device)
            media = VoxelMediaBuffers.upload(media_list, camera.position, device, species, time_s=scene.time_s,
                                             cache=cache, cells=False)
            majorants, self.majorant_cells = upload_majorants(media_list, settings.majorant_block, device,
                                                              cache_name="path_tracer:majorants",
                                                              reduced=int(settings.similarity_order) > 0)
            cut_struct = CutMedia()
            cut_struct.media, cut_struct.majorants = media.media, majorants
            if cut is not None:
                cut_list = tuple(cut_medium(m, species, cut.fraction) for m in media_list)
                cut_media = VoxelMediaBuffers.upload(cut_list, camera.position, device, species, time_s=scene.time_s,
                                                     table_offset=len(species), values=media.values, cells=False)
                cut_struct.media = cut_media.media
                cut_struct.majorants = upload_majorants(cut_list, settings.majorant_block, device,
                                                        cache_name="path_tracer:majorants:cut")[0]
            surfaces, mesh_buffers = traced_meshes(scene.meshes if meshes else (), camera.position, device)
        fogs = scene.fogs if fog else ()
        majorants.fog = fog_tracking(fogs, camera.position, scene.time_s, device)
        cut_struct.majorants.fog = majorants.fog
        flags = (bool(species), media.has_detail, mesh_buffers is not None, bool(fogs))  # ground, dome: runtime
        self.kernel = path_trace_kernel(*flags)
        self._launch_buffers()
        dome = dome_struct(scene.dome, device)
        oriented = oriented_phases(scene, device, cache="path_tracer")
        continuation = continuation_tables(scene, device, cache="path_tracer")
        # the structs below point into these
        self._keep = (tables, media, dome, oriented, continuation, cut_struct, mesh_buffers, surfaces)
        self.fixed = [media.media, majorants, cut_struct, phase_tables_struct(tables, oriented, continuation),
                      air_struct(scene, camera.position, device, air=air), sun_struct(sunlight(scene)),
                      pinhole_camera(camera, width, height), ground_struct(scene.ground, camera.position), dome,
                      surfaces]

    def _launch_buffers(self) -> None:
        """How a launch runs on this film (:func:`per_sample_launches`) and the kept paths' buffer it needs."""
        per_pass = int(self.settings.samples_per_pass or 1)
        capacity = per_sample_launches(self.device, self.width * self.height, per_pass)
        if self.per_sample is not None:
            capacity = max(1, per_pass) if self.per_sample else 0
        self.samples_per_launch = capacity  # 0: one thread per pixel
        self.samples = None  # the kernel's "one thread per pixel"
        if capacity:
            self.samples = device_buffers.reusable(f"{self.buffer_name}:samples", (capacity * self.height, self.width),
                                                   SampleResult, self.device)

    def rescaled(self, scale: int) -> PathTracing:
        """The same paths on a film whose pixels are ``scale`` times the frame's (everything but the camera and the
        film shared with this one)."""
        out = copy.copy(self)
        width, height = self.frame_size
        out.camera, out.width, out.height = self.frame_camera, width, height
        if scale > 1:
            out.camera, out.width, out.height = coarse_camera(self.frame_camera, width, height, scale)
        out.settings = dataclasses.replace(self.settings, pixel_jitter=self.settings.pixel_jitter or scale > 1)
        out.fixed = list(self.fixed)
        out.fixed[6] = pinhole_camera(out.camera, out.width, out.height)
        out._launch_buffers()
        return out

    def _launch_settings(self, first_sample: int, count: int, active: wp.array | None) -> PathSettings:
        """Kernel settings of one launch: ``count`` paths per pixel from path index ``first_sample``, of the pixels
        ``active`` marks (uint8 per film pixel; None: all)."""
        out, settings = PathSettings(), self.settings
        out.environment = wp.vec3(float(settings.environment))
        out.seed, out.pixel_jitter = int(settings.seed), int(settings.pixel_jitter)
        out.first_sample, out.sample_count = int(first_sample), int(count)
        out.max_bounces, out.similarity_order = int(settings.max_bounces), int(settings.similarity_order)
        out.multiple_only, out.forward_cut = int(self.multiple_only), int(self.forward_cut)
        out.sun_lobe_g, out.air_by_table = float(self.lobe_g), int(self.air_by_table)
        out.first_end_low, out.first_end_high = (1.0, -1.0) if self.first_end is None else self.first_end
        out.masked = int(active is not None)
        if active is not None:
            out.active = active
        return out

    def launch(self, sums: PixelSums, first_sample: int, count: int, active: wp.array | None = None) -> None:
        """Add paths ``first_sample .. first_sample + count - 1`` of every pixel (of the pixels ``active``, uint8 per
        film pixel, marks) to ``sums`` (asynchronous on GPUs)."""
        if not self.samples_per_launch:
            launch = self._launch_settings(first_sample, count, active)
            launch_rows(self.kernel, self.height, self.width, [*self.fixed, launch, sums, None], self.device)
            return
        end = first_sample + count
        while first_sample < end:
            chunk = min(self.samples_per_launch, end - first_sample)
            launch = self._launch_settings(first_sample, chunk, active)
            launch_rows(self.kernel, chunk * self.height, self.width, [*self.fixed, launch, sums, self.samples],
                        self.device)
            launch_rows(sum_samples_kernel(), self.height, self.width, [self.samples, chunk, sums], self.device)
            first_sample += chunk


#: Bytes per pixel of a :class:`PixelSums` (radiance sum and sum of squares, transmittance RGB, depth vec2, counters).
PIXEL_SUMS_BYTES = 60
#: Bytes of a :class:`~warpsky.techniques.path_tracer.path_tracer_kernels.SampleResult` (one path of one pixel).
SAMPLE_BYTES = 56
#: Bytes per pixel :func:`sums_layer` holds at once: float64 sums, squares, mean and variance (96), transmittance and
#: depth sums (40), counters (16), the float32 outputs (40).
SUMS_LAYER_BYTES = 192


def path_tracing_memory(scene: Scene, pixel_sums_count: int, majorant_block: int | None, device: str,
                        samples_per_pass: int = 1, *, film_pixels: int | None = None,
                        bake_detail: bool = False) -> MemoryEstimate:
    """Bytes of :class:`PathTracing` on a film of ``film_pixels`` pixels (default ``pixel_sums_count``) and
    ``pixel_sums_count`` pixels of :class:`PixelSums`: the sums on the device (and their host copies on a GPU), the
    paths of one launch when they are kept per sample (:func:`per_sample_launches`), the media and their majorant
    grids (built on the host from a copy), and with ``bake_detail`` the grids of the baked detail."""
    copies = 0 if is_cpu(device) else 1
    film = pixel_sums_count if film_pixels is None else film_pixels
    samples = per_sample_launches(device, film, samples_per_pass) * film * SAMPLE_BYTES
    grids = grid_bytes(scene) + (baked_bytes(scene.media) if bake_detail else 0)
    majorants = sum(4 * math.prod(-(-n // medium_block(m, majorant_block)) for n in m.shape) for m in scene.media)
    return (MemoryEstimate()
            .add("path sums", host=copies * pixel_sums_count * PIXEL_SUMS_BYTES,
                 device=pixel_sums_count * PIXEL_SUMS_BYTES)
            .add("grids", host=2 * grids, device=grids + majorants + samples))


def path_work(settings: PathTracerSettings, pixels: int) -> WorkItem:
    """Worst-case path events of ``settings.spp`` paths per pixel that all reach ``settings.max_bounces``."""
    spp, bounces = int(settings.spp), int(settings.max_bounces)
    return WorkItem("path events", float(spp) * bounces, pixels, f"spp={spp} x max_bounces={bounces}")


def coarse_camera(camera, width: int, height: int, scale: int):
    """(camera, width, height) of a film whose pixel (r, c) covers pixels [r s, r s + s) x [c s, c s + s) of
    ``camera`` (already conformed to ``width`` x ``height``): the same top-left corner, ceil(width / s) x
    ceil(height / s) pixels, so the last row and column may reach past the frame's edge."""
    coarse_w, coarse_h = -(-width // scale), -(-height // scale)
    h_ap = camera.horizontal_aperture * coarse_w * scale / width
    v_ap = camera.vertical_aperture * coarse_h * scale / height
    return dataclasses.replace(
        camera, horizontal_aperture=h_ap, vertical_aperture=v_ap,
        horizontal_aperture_offset=camera.horizontal_aperture_offset + 0.5 * (h_ap - camera.horizontal_aperture),
        vertical_aperture_offset=camera.vertical_aperture_offset - 0.5 * (v_ap - camera.vertical_aperture),
    ), coarse_w, coarse_h


#: The fields of :class:`PixelSums` and their element types.
PIXEL_SUMS_FIELDS = (("radiance_sum", wp.vec3), ("radiance_sq", wp.vec3), ("transmittance_sum", wp.vec3),
                     ("depth_sum", wp.vec2), ("counters", wp.vec4i))


def pixel_sums(shape: tuple[int, int], device, *, name: str | None = None) -> PixelSums:
    """Zeroed per-pixel sums of ``shape`` (rows, columns) on ``device``. With ``name`` the arrays are
    :func:`warpsky.core.device_buffers.reusable` ones (``name:field``), cleared here: a frame of the same size
    allocates nothing, and sums under one name must not be in use twice at once."""
    out = PixelSums()
    for field, dtype in PIXEL_SUMS_FIELDS:
        if name is None:
            array = wp.zeros(shape, dtype=dtype, device=device)
        else:
            array = device_buffers.reusable(f"{name}:{field}", shape, dtype, device)
            array.zero_()
        setattr(out, field, array)
    return out


#: Threads a GPU keeps resident at once (a large one: 132 SMs x 2048 on an H200, about 2^18).
GPU_RESIDENT_THREADS = 1 << 18
#: Most threads of one launch when paths run one per thread (bounds the kept paths: 2^21 x 44 bytes = 92 MB).
GPU_LAUNCH_THREADS = 1 << 21


def per_sample_launches(device: str, pixels: int, samples_per_pass: int) -> int:
    """Paths per pixel of one launch when each path runs on its own thread, or 0 for one thread per pixel.

    One thread per pixel fills a GPU once the frame has :data:`GPU_RESIDENT_THREADS` pixels (512 x 512: 95 M
    paths/s on an H200) and is what the CPU runs (its row bands use the cores). A smaller frame on a GPU left
    most of it idle (128 x 128: 2^14 threads, 20 M paths/s): there a launch runs ``samples_per_pass`` paths of
    every pixel on as many threads (128 x 128 at the GPU default of 64 per pass: 2^20 threads), at most
    :data:`GPU_LAUNCH_THREADS`. The paths' sums are the same either way (:class:`PathTracing`)."""
    if is_cpu(device) or pixels >= GPU_RESIDENT_THREADS:
        return 0
    return max(1, min(int(samples_per_pass), GPU_LAUNCH_THREADS // max(pixels, 1)))


def variance_of_mean(total: np.ndarray, squares: np.ndarray, count) -> np.ndarray:
    """Per pixel, the variance of the mean of ``count`` paths (at least 1) from the sums of their radiance and of its
    squares (float64; 0 where fewer than two paths)."""
    n = np.maximum(count, 1.0)
    mean = total / n
    return np.maximum(squares / n - mean**2, 0.0) / np.maximum(n - 1.0, 1.0)


def sums_layer(sums: list[PixelSums], spp, far: float, *, name: str = "path_tracer") -> ImageLayer:
    """The layer of ``spp`` paths per pixel (an int, or per pixel an (H, W) array) accumulated in ``sums`` (one per
    stream): mean radiance, mean transmittance, mean depth of first events (``far`` where none), the variance of
    the pixel mean as an AOV, and the tracking counters. One download per field and sums, through
    :func:`warpsky.core.device_buffers.download` (pinned staging kept under ``name:field``)."""
    def total_of(field):
        return sum(device_buffers.download(f"{name}:{field}", getattr(s, field)).astype(np.float64) for s in sums)

    total = total_of("radiance_sum")
    squares = total_of("radiance_sq")
    count = np.asarray(spp, dtype=np.float64)
    if count.ndim == 2:
        count = count[..., None]
    n = np.maximum(count, 1.0)
    mean = total / n
    variance = variance_of_mean(total, squares, count)
    depth = total_of("depth_sum")
    depth_mean = np.where(depth[..., 1] > 0, depth[..., 0] / np.maximum(depth[..., 1], 1), np.float32(far))
    count_values = sum(device_buffers.download(f"{name}:counters", s.counters) for s in sums)
    return ImageLayer(
        mean.astype(np.float32),
        (total_of("transmittance_sum") / n).astype(np.float32),
        depth_mean.astype(np.float32),
        stats={
            "tracking_steps": int(count_values[..., 0].sum()),
            "capped_paths": int(count_values[..., 1].sum()),
            "scatter_events": int(count_values[..., 2].sum()),
            "shadow_steps": int(count_values[..., 3].sum()),
            "paths": int(np.broadcast_to(count[..., 0] if count.ndim else count, count_values.shape[:2]).sum()),
        },
        aovs={"variance": variance.astype(np.float32)},
    )
