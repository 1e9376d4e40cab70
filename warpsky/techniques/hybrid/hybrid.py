"""The default technique: exact single scattering plus denoised Monte Carlo multiple scattering.

Light reaching the eye after one scattering event is marched exactly and without noise (the
:mod:`~warpsky.techniques.single_scatter` kernel: sun -> shadow march -> scattering -> eye). Light scattered at
least twice is path traced (the :mod:`~warpsky.techniques.path_tracer` kernel with the sunlight at the first
event left out, so the two parts never count the same light twice), then denoised with Intel Open Image Denoise
(:mod:`~warpsky.techniques.hybrid.denoise`). After their first event the paths treat the diffraction peak of
tabulated species (within ``forward_cut`` degrees) as no scattering
(:mod:`~warpsky.techniques.path_tracer.forward_cut`): the one approximation in the default settings, which in thick
Mie clouds removes a heavy tail of the paths' sunlight. A dome's light is path traced whole, its first scattering
included (the march cannot integrate a dome exactly and takes the sun alone), so the sum stays unbiased; with
``multiple_scattering = 0`` the dome lights nothing but the background. Passes of paths are added until the
frame's estimated relative error falls below ``target_error``, or ``time_budget`` or ``spp`` is reached.

The error estimate splits the paths into two independent halves A and B (alternate passes). Denoised separately,
their difference has about twice the variance of the denoised whole, so RMS(D(A) - D(B)) / 2 over the covered
pixels, divided by the mean of the frame there, estimates the relative RMSE of the denoised frame's noise. It
misses what the two halves share: the denoiser's blur and bias, and the rare bright paths neither half caught. On
the tune halves of the thin and thick validation families (64 x 64, 1 s budget) it was 0.56 of the measured error
(median; 0.36-0.98), so the estimate reported and stopped on is that figure times :data:`ESTIMATE_CALIBRATION`,
or, where larger, the denoised frame's noise plus the denoiser's bias as each half's raw paths measure it
(:mod:`~warpsky.techniques.hybrid.estimate`): at high path counts the bias is most of the error. Without denoising
the estimate is the variance of each pixel's mean, uncalibrated.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import deadline, device_buffers
from warpsky.core.device import is_cpu
from warpsky.core.image import ImageLayer
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.core.progress import status as progress_status
from warpsky.core.resources import AOV_BYTES, MemoryEstimate, WorkItem
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.sun import above_air
from warpsky.media.voxels.extent import grid_bytes
from warpsky.model.scene import Scene
from warpsky.optics.oriented_sampling import oriented_table_bytes
from warpsky.passes.media import SceneryFrame, scenery_traceable
from warpsky.passes.sky.front import front_air_transmittance
from warpsky.techniques.hybrid.budget import (
    AUTO_FILM,
    PathBudget,
    coverage_scale_warning,
    film_scale,
    next_check,
    paths_film_scale,
    timed_denoise,
)
from warpsky.techniques.hybrid.denoise import (
    bilinear_upsample,
    block_mean,
    denoise,
    guided_upsample,
    require_denoiser,
)
from warpsky.techniques.hybrid.estimate import denoised_estimate, relative_rms
from warpsky.techniques.hybrid.history import HISTORY_FILM_BYTES, HISTORY_PIXEL_BYTES, keep_frame, warm_start
from warpsky.techniques.hybrid.scenery import deck_paths_features, paths_scene, scenery_guide
from warpsky.techniques.path_tracer.deck_media import deck_voxel_memory
from warpsky.techniques.path_tracer.forward_cut import check_cut_settings, cut_feature
from warpsky.techniques.path_tracer.path_tracer import (
    PathTracer,
    PathTracerSettings,
    PathTracing,
    path_tracing_memory,
    path_work,
    pixel_sums,
    sums_layer,
    variance_of_mean,
)
from warpsky.techniques.path_tracer.stratiform_media import layer_voxel_memory
from warpsky.techniques.path_tracer.sun_lobe import AUTO_LOBE, lobe_asymmetry
from warpsky.techniques.single_scatter.single_scatter import SingleScatter, SingleScatterSettings, march_work
from warpsky.techniques.technique import Technique

#: Name under which the multiple-scattering paths keep their device buffers (:mod:`warpsky.core.device_buffers`).
BUFFER_NAME = "path_tracer:hybrid"
#: Pixels whose luminance transmittance is below this count as covered by the media (or an opaque surface).
COVERED_BELOW = 0.99
#: The denoised estimate's factor: the geometric mean of measured net error / raw estimate over the 13 tune-half
#: members of the thin and thick validation families where the error was resolved (1.70; per member 1.0-2.8).
ESTIMATE_CALIBRATION = 1.7


@documented
@dataclass(frozen=True)
class HybridSettings(Settings):
    """Settings of the hybrid technique."""

    owner = "hybrid"
    target_error: float = setting(0.05, range="[0, 1)", help="stop adding paths once the frame's estimated "
                                  "relative RMSE over covered pixels is below this; 0 = exactly spp paths")
    time_budget: float | None = setting(None, unit="s", range="> 0", help="the frame's wall time, from its stage "
                                        "read to its EXR written: paths are added while the next pass fits; one "
                                        "pass of each half always runs (the error estimate needs both), on "
                                        "coarser pixels where they would not fit", auto="no limit")
    spp: int = setting(256, range=">= 1", help="most multiple-scattering paths per pixel (exactly this many with "
                       "target_error = 0)")
    samples_per_pass: int | None = setting(None, range=">= 1", help="paths per pixel per pass; passes alternate "
                                           "between the two halves of the error estimate",
                                           auto="2 on the CPU, 16 on GPUs (at most spp)")
    seed: int = setting(0, range=">= 0", help="random seed; a seed gives the same image on the same device")
    multiple_scattering: bool = setting(True, help="0: single scattering only (equals single_scatter)")
    denoise: bool = setting(True, help="denoise the multiple-scattering part with Open Image Denoise (pyoidn)")
    mean_radius: int = setting(-1, unit="pixel", range=">= -1", help="box radius over which the denoised image "
                               "keeps the noisy image's local mean; -1 = off (chosen on the validation family's "
                               "tune half: the correction raised the p90 error there)")
    max_bounces: int = setting(16384, range=">= 1", help="cap on scattering events per path; capped paths are "
                               "counted (capped_paths): their missing light is a bias (1024 lost 2.3 % of a storm "
                               "frame's multiple scattering; 16384 left 17 of its 1,019 capped paths, 22 % slower)")
    majorant_block: int | None = setting(None, unit="voxel", range=">= 1", help="edge of the coarse majorant cells",
                                         auto="per medium, as the path tracer's")
    bake_detail: bool = setting(False, help="1: the multiple-scattering paths trace the media's animated detail baked "
                                "for the frame into a grid within a detail texel (the single-scattering march keeps "
                                "the procedural detail); 0: procedural at every collision")
    similarity_order: int = setting(0, range=">= 0", help="scattering events after which the paths continue through "
                                    "the media reduced by high-order similarity (sigma_s (1 - g), isotropic); "
                                    "0 = exact")
    forward_cut: float = setting(3.0, unit="deg", range="[0, 30]", help="after their first event the multiple-"
                                 "scattering paths treat light a tabulated species deflects by less than this angle "
                                 "(its diffraction peak) as not scattered (delta-M; see the path tracer's setting); "
                                 "0 = exact. 3 was chosen on the thick validation family's tune half (0, 3, 5): "
                                 "worst net error at a 1 s budget 0.89 -> 0.20, median bias -10% -> 0%")
    sun_lobe: float | None = setting(None, range="[-1, 0.99]", auto=AUTO_LOBE, help="g of the paths' sun lobe "
                                     "(see the path tracer's setting); -1 = none. On the demo cumulus (g 0.85, lit "
                                     "from the side) it cut the paths' variance 2.6x for 1.3-1.5x their time")
    uncovered_spp: int = setting(16, range=">= 1", help="paths per pixel after which the pixels the error estimate "
                                 "does not cover (the ground, the sky; coverage below 1%) get no more, so the rest "
                                 "of the frame's paths go where the target is measured; not used when the paths "
                                 "trace fog, decks or meshes; >= spp: every pixel alike")
    temporal: float = setting(0.0, range="[0, 1)", help="reuse the previous frame's paths in frames rendered one "
                              "after another in one process (same camera, size and settings), each frame's weighted "
                              "by this factor per frame of age, dropped where the single scattering or the coverage "
                              "changed; 0 = every frame alone")
    temporal_tolerance: float = setting(0.05, range="> 0", help="relative change of a pixel's single scattering "
                                        "beyond which temporal reuse drops its history: smaller, less lag; larger, "
                                        "less noise")
    ms_scale: int | None = setting(None, unit="pixel", range="1..8", auto=AUTO_FILM, help="trace multiple "
                                   "scattering on pixels this many times larger (box-filtered), upsampled with the "
                                   "exact coverage as guide")
    step_length: float | None = setting(None, unit="m", range="> 0", help="single-scattering eye-ray step",
                                        auto="0.5 x the smallest voxel edge")
    shadow_step_length: float | None = setting(None, unit="m", range="> 0", help="single-scattering shadow step",
                                               auto="1 x the smallest voxel edge")
    deck_extent: float | None = setting(None, unit="m", range="> 0", help="half-size of the square around the "
                                        "camera over which the paths trace a height-field deck and its haze "
                                        "voxelised (the deck pass draws their single scattering everywhere)",
                                        auto="as the path tracer's")
    deck_voxel_width: float | None = setting(None, unit="m", range="> 0", help="horizontal edge of those voxels",
                                             auto="as the path tracer's")
    deck_voxel: float | None = setting(None, unit="m", range="> 0", help="vertical edge of those voxels",
                                       auto="as the path tracer's")

    def single_scatter(self) -> SingleScatterSettings:
        # skylight off: the paths carry the sky's light (traced through the air) and the dome's, first scattering
        # included, so the march takes the sun alone
        return SingleScatterSettings(step_length=self.step_length, shadow_step_length=self.shadow_step_length,
                                     skylight=False)

    def path_tracer(self) -> PathTracerSettings:
        return PathTracerSettings(spp=self.spp, seed=self.seed, max_bounces=self.max_bounces,
                                  majorant_block=self.majorant_block, samples_per_pass=self.samples_per_pass,
                                  similarity_order=self.similarity_order,
                                  bake_detail=self.bake_detail, forward_cut=self.forward_cut,
                                  sun_lobe=self.sun_lobe, deck_extent=self.deck_extent,
                                  deck_voxel_width=self.deck_voxel_width, deck_voxel=self.deck_voxel)


class Hybrid(Technique):
    """Exact single scattering plus path-traced, denoised multiple scattering, rendered to a target error.

    Every species, the ground (its direct sunlight marched, its bounces traced) and the stratiform and sky passes
    work as with ``single_scatter``: the sky pass draws the air's single scattering around the media's layer,
    while the paths are traced through the air too (skylight on the media, light between air, media and ground,
    the air's own multiple scattering). Next to stratiform layers the front-air correction uses the media's own
    depth. Next to the fog and surfaces passes its paths also trace the fog and the meshes and carry their light
    beyond the sun's single scattering (:mod:`.scenery`). AOVs: ``single_scatter`` and ``multiple_scatter``
    radiance, ``variance`` of the noisy multiple-scattering mean.
    """

    name = "hybrid"
    Settings = HybridSettings
    traces_dome = True
    #: Next to the fog and surfaces passes its paths carry the fog's and the meshes' light beyond the sun's single
    #: scattering (:mod:`.scenery`).
    scatters_scenery = True
    aovs = {"variance": "RGB", "single_scatter": "RGB", "multiple_scatter": "RGB"}
    kernel_modules = SingleScatter.kernel_modules + PathTracer.kernel_modules
    settings_notes = ("--target-error E, --time-budget S, --spp N and --seed S are shorthands for --set "
                      "target_error=E / time_budget=S / spp=N / seed=S. Writes single_scatter.RGB, "
                      "multiple_scatter.RGB and variance.RGB AOVs; the header holds errorEstimate, spp, passes, "
                      "stoppedBy, targetError, paths and cappedPaths (a warning above 0.1%).")

    def resolved_settings(self, scene: Scene) -> HybridSettings:
        s = self.settings
        check_cut_settings(float(s.forward_cut), int(s.similarity_order))
        march = SingleScatter(s.single_scatter(), device=self.device).resolved_settings(scene)
        per_pass = s.samples_per_pass or (2 if is_cpu(self.device) else 16)
        return dataclasses.replace(s, step_length=march.step_length, shadow_step_length=march.shadow_step_length,
                                   samples_per_pass=min(per_pass, s.spp), sun_lobe=lobe_asymmetry(scene, s.sun_lobe))

    #: Bytes per pixel of the multiple-scattering film on the host: float64 sums, squares, mean and variance of
    #: both halves (128), the float32 mean and variance (24), the denoiser's input, guide and output for the
    #: estimate's two halves (72) and Open Image Denoise's own buffers (about 256, measured).
    COARSE_HOST_BYTES = 480
    #: Bytes per frame pixel on the host besides the single-scattering layer: coverage, the multiple-scattering
    #: image and variance, upsampled, divided by the front air's transmittance (96), the layer's sum (12), and on a
    #: coarser film the estimate's two halves upsampled, the upsampling's temporaries and their spread (72).
    FINE_HOST_BYTES = 180

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a frame allocates: the single-scattering march's, two halves of :class:`PixelSums` on the
        ``ms_scale`` film with their host sums and denoiser copies, the frame-size multiple-scattering images,
        the front-air transmittance and three AOVs."""
        s = self.settings_for(scene)
        pixels = width * height
        estimate = SingleScatter(s.single_scatter(), device=self.device).memory_estimate(scene, width, height)
        if not (s.multiple_scattering and (scene.media or self.scenery_paths(scene))):
            return estimate
        scale = paths_film_scale(s.ms_scale, width, height)
        coarse = -(-width // scale) * -(-height // scale)
        paths = path_tracing_memory(scene, 2 * coarse, s.majorant_block, self.device, int(s.samples_per_pass),
                                    film_pixels=coarse, bake_detail=bool(s.bake_detail))
        host, device = paths.parts.pop("grids")  # the paths trace the march's upload of the grids (one buffer)
        estimate.merge(paths).add("grids", host=host - 2 * grid_bytes(scene), device=device - grid_bytes(scene))
        # the paths' oriented ice: the frame slices and the continuation tables, kept per process and uploaded
        # (24 + 77 MiB measured on the sundogs)
        slices, continuation = oriented_table_bytes(scene.media)
        if slices:
            estimate.add("oriented ice tables", host=slices + continuation, device=slices + continuation)
        estimate.add("multiple scattering", host=coarse * self.COARSE_HOST_BYTES + pixels * self.FINE_HOST_BYTES)
        if s.temporal > 0.0:
            estimate.add("temporal history", host=coarse * HISTORY_FILM_BYTES + pixels * HISTORY_PIXEL_BYTES)
        if scene.decks and self.scenery_paths(scene):
            estimate.merge(deck_voxel_memory(scene, s.path_tracer(), width, height, time_budget=s.time_budget))
        if scene.stratiform_layers and self.scenery_paths(scene):  # the layers its paths trace, voxelised
            estimate.merge(layer_voxel_memory(scene, s.path_tracer()))
        if scene.atmosphere is not None:
            estimate.add("sky", host=pixels * 64, device=pixels * 40)
        return estimate.add("AOVs", host=3 * pixels * AOV_BYTES)

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Worst-case grid lookups of the march and path events of the spp cap on the ``ms_scale`` film (none
        counted with a time budget, which bounds them)."""
        s = self.settings_for(scene)
        items = march_work(scene, width * height, float(s.step_length), float(s.shadow_step_length))
        if s.multiple_scattering and (scene.media or self.scenery_paths(scene)) and s.time_budget is None:
            scale = paths_film_scale(s.ms_scale, width, height)
            items.append(path_work(s.path_tracer(), -(-width // scale) * -(-height // scale)))
        return items

    def features(self, scene: Scene, width: int, height: int, features: dict[str, str]) -> dict[str, str]:
        """The ``forward cut`` line of its multiple-scattering paths, and how they trace a height-field deck."""
        s = self.settings_for(scene)
        if not s.multiple_scattering:
            return features
        if scene.decks and self.scenery_paths(scene):
            features = deck_paths_features(scene, s.path_tracer(), width, height, features, s.time_budget)
        return cut_feature(scene, float(s.forward_cut), features)

    def scenery_paths(self, scene: Scene) -> bool:
        """With multiple scattering on, its paths trace the fog, the height-field deck and the meshes, and the
        stratiform layers above fog and meshes (:func:`~warpsky.passes.media.scenery_traceable`; :mod:`.scenery`)."""
        return bool(self.settings_for(scene).multiple_scattering) and scenery_traceable(scene)

    def render(self, scene: Scene, width: int, height: int, *, around: SceneryFrame | None = None) -> ImageLayer:
        """The media's layer; with :meth:`scenery_paths` the paths' light (the scenery's multiple scattering
        included) is its ``front`` light (:mod:`.scenery`), and ``around`` is what the frame's other passes draw
        (:class:`~warpsky.passes.media.SceneryFrame`: the ground plane the paths bounce on, the stratiform layers
        they trace beyond their first event, the light the error estimate counts in the frame's level)."""
        settings = self.settings_for(scene)
        if settings.multiple_scattering and settings.denoise:
            require_denoiser()
        started = time.perf_counter()
        # The dome's light, its first scattering included, is all path traced: the march takes the sun alone.
        single = SingleScatter(settings.single_scatter(), device=self.device).render(
            dataclasses.replace(scene, dome=None), width, height)
        stats = {"single_scatter_seconds": single.stats["seconds"], "lookups": single.stats["lookups"]}
        multiple = np.zeros_like(single.radiance)
        variance = np.zeros_like(single.radiance)
        scenery = self.scenery_paths(scene)
        paths, band = scene, None
        if scenery:
            around = around or SceneryFrame()
            paths, band = paths_scene(scene, around, settings.path_tracer(), width, height, self.device,
                                      time_budget=settings.time_budget)
        lit = (scene.sun is not None and (scene.media or scenery)) or (
            scene.dome is not None and (scene.media or scene.ground or scenery))
        if settings.multiple_scattering and lit:
            guide = scenery_guide(scene, single, self.device, around) if scenery else single
            with device_buffers.exclusive(BUFFER_NAME, self.device):  # the halves and kept paths
                multiple, variance, ms_stats = MultipleScattering(paths, width, height, settings, self.device,
                                                                  scenery=scenery, first_end=band).run(guide, started)
            stats.update(ms_stats)
            if scene.atmosphere is not None and not scenery:  # the scenery's paths go in front of the air's layer
                multiple, variance = behind_front_air(scene, width, height, single.depth, multiple, variance,
                                                      self.device)
            deadline.progressive_done()  # what the frame runs from here on, the next frame's budget sets aside
        stats["seconds"] = time.perf_counter() - started
        stats["settings"] = dataclasses.asdict(settings)
        if scenery:  # the paths' light is attenuated to the eye: in front of the other passes' layers
            front = ImageLayer(multiple, np.ones_like(multiple),
                               np.full(single.depth.shape, scene.camera.far, np.float32),
                               aovs={"multiple_scatter": multiple, "variance": variance})
            return ImageLayer(single.radiance, single.transmittance, single.depth, stats=stats,
                              aovs={"single_scatter": single.radiance}, warnings=stats.pop("warnings", []), front=front)
        return ImageLayer(single.radiance + multiple, single.transmittance, single.depth, stats=stats,
                          aovs={"single_scatter": single.radiance, "multiple_scatter": multiple, "variance": variance},
                          warnings=stats.pop("warnings", []))


def behind_front_air(scene: Scene, width: int, height: int, depth: np.ndarray, multiple: np.ndarray,
                     variance: np.ndarray, device: str) -> tuple[np.ndarray, np.ndarray]:
    """Multiple scattering traced through the air already carries the air between the camera and each event;
    the frame's composite multiplies the media's layer by the sky pass's front transmittance T_f, so the layer
    holds multiple / T_f (and its variance / T_f^2). T_f is the sky pass's own, at the media's depth
    (:func:`~warpsky.passes.sky.front.front_air_transmittance`)."""
    t_front = np.maximum(front_air_transmittance(scene, width, height, depth, device), 1e-4)
    return (multiple / t_front).astype(np.float32), (variance / t_front**2).astype(np.float32)


class MultipleScattering:
    """Progressive passes of multiple-scattering paths into two halves, the error estimate, and the denoising."""

    def __init__(self, scene: Scene, width: int, height: int, settings: HybridSettings, device: str, *,
                 scenery: bool = False, first_end: tuple[float, float] | None = None):
        self.settings = settings
        self.device = device
        self.scale = paths_film_scale(settings.ms_scale, width, height)
        # With air, paths are traced through it from the sun at the top of the atmosphere: they carry skylight on
        # the media and the light between air, media and ground. The air's own light, single and multiple
        # scattering, is the sky pass's: a path whose first event is in the air ends there (air_by_table), unless
        # the atmosphere turns the table off (then the paths carry the air's multiple scattering as before).
        atmosphere = scene.atmosphere
        self.tracing = PathTracing(above_air(scene), width, height, settings.path_tracer(), device,
                                   air=atmosphere is not None, multiple_only=True, scale=self.scale,
                                   buffer_name=BUFFER_NAME,
                                   air_by_table=atmosphere is not None and atmosphere.multiple_scattering,
                                   meshes=scenery and bool(scene.meshes), fog=scenery and bool(scene.fogs),
                                   first_end=first_end)
        shape = (self.tracing.height, self.tracing.width)
        self.halves = [pixel_sums(shape, device, name=f"{BUFFER_NAME}:half{half}") for half in (0, 1)]
        self.shot = (scene, width, height)
        self.scenery = scenery
        self.pixel_counts = [np.zeros(shape, np.float32) for _ in (0, 1)]  # paths per film pixel and half
        self.active: wp.array | None = None  # the covered film pixels, once uncovered ones get no more paths

    def run(self, single: ImageLayer, started: float) -> tuple[np.ndarray, np.ndarray, dict]:
        """(denoised multiple scattering, variance of its noisy mean, stats), given the single-scattering layer."""
        s = self.settings
        asked, budget = self.scale, None
        if s.time_budget is not None:
            budget = PathBudget.of(s.time_budget, started, single.radiance.shape[0] * single.radiance.shape[1],
                                   self.device)
            scale = film_scale(self.tracing, budget, int(s.samples_per_pass), self.scale, self.device)
            if scale != self.scale:
                self.rescale(scale)
        film_pixels = self.tracing.width * self.tracing.height
        fine_coverage = np.clip(1.0 - single.transmittance, 0.0, 1.0)
        coverage = block_mean(fine_coverage, self.scale) if self.scale > 1 else fine_coverage
        covered = coverage @ LUMINANCE_WEIGHTS > 1.0 - COVERED_BELOW
        reuse = warm_start(self, single.radiance, fine_coverage)
        per_pass, done, passes, check_at, estimated_at = int(s.samples_per_pass), 0, 0, 2, 0
        estimate, stop = math.inf, "spp"
        while done < s.spp:
            if budget is not None and passes >= 2 and not budget.next_pass_fits(film_pixels):
                stop = "time_budget"
                break
            count = min(per_pass, s.spp - done)
            half = passes % 2
            launched = time.perf_counter()
            active = self.active_pixels(covered, done)
            # path indices, hence streams, never repeat (a shot's reused paths' included)
            self.tracing.launch(self.halves[half], reuse.first + done, count, active)
            self.pixel_counts[half] += count if active is None else count * covered
            if budget is not None:
                wp.synchronize_device(self.device)
                budget.pass_seconds = time.perf_counter() - launched
            done += count
            passes += 1
            if s.target_error > 0.0 and passes == check_at:
                checked = time.perf_counter()
                estimate, estimated_at = self.estimate(single.radiance, fine_coverage, coverage), passes
                timed_denoise(budget, 0.5 * (time.perf_counter() - checked) if s.denoise else 0.0, film_pixels)
                if estimate <= s.target_error:
                    stop = "target"
                    break
                check_at = next_check(passes, estimate, s.target_error)
            progress_status(f"hybrid: {done} of at most {s.spp} paths per pixel"
                            + (f", estimated error {estimate:.1%} (target {s.target_error:.1%})"
                               if math.isfinite(estimate) else ""))
        wp.synchronize_device(self.device)
        keep_frame(self, reuse, single.radiance, fine_coverage, reuse.first + done)
        film = self.film()
        mean, variance = film.radiance, film.aovs["variance"]
        image, denoise_seconds, sanitised, warnings = mean, 0.0, 0, coverage_scale_warning(self.scale, asked)
        if s.denoise:
            result = denoise(mean, coverage, radius=s.mean_radius, device=self.device)
            image, denoise_seconds, sanitised = result.image, result.seconds, result.sanitised
        if self.scale > 1:
            height, width = fine_coverage.shape[:2]
            image = guided_upsample(image, fine_coverage, self.scale)
            variance = bilinear_upsample(variance, self.scale, height, width)
        if s.target_error > 0.0 and stop != "target":
            if estimated_at != passes:  # paths were added since the last estimate (or there was none)
                estimate = self.estimate(single.radiance, fine_coverage, coverage) if passes >= 2 else math.inf
            if estimate <= s.target_error:
                stop = "target"  # reached with the last paths, before the next scheduled check
            else:
                reason = "the time budget" if stop == "time_budget" else f"the path cap (spp = {s.spp})"
                warnings.append(f"hybrid stopped by {reason} after {done} paths per pixel with an estimated error "
                                f"of {estimate:.1%}, above the target {s.target_error:.1%}")
        stats = {"spp": done, "passes": passes, "stopped_by": stop, "error_estimate": estimate,
                 "target_error": s.target_error, "denoise_seconds": denoise_seconds,
                 "sanitised_values": sanitised, "tracking_steps": film.stats["tracking_steps"],
                 "scatter_events": film.stats["scatter_events"], "shadow_steps": film.stats["shadow_steps"],
                 "capped_paths": film.stats["capped_paths"], "paths": film.stats["paths"],
                 "ms_scale": self.scale, "warnings": warnings, **reuse.stats()}
        return image, variance, stats

    def active_pixels(self, covered: np.ndarray, done: int) -> wp.array | None:
        """The film pixels the next pass runs paths in: all of them (None) until each has ``uncovered_spp`` paths
        (or in a frame whose paths trace scenery, whose light the error estimate counts), then only the pixels the
        error estimate covers."""
        if self.scenery or done < int(self.settings.uncovered_spp) or covered.all():
            return None
        if self.active is None:
            self.active = wp.array(covered.astype(np.uint8), dtype=wp.uint8, device=self.device)
        return self.active

    def rescale(self, scale: int) -> None:
        """Trace the paths on pixels ``scale`` times the frame's from now on (before any pass ran)."""
        self.tracing = self.tracing.rescaled(scale)
        self.scale = scale
        shape = (self.tracing.height, self.tracing.width)
        self.halves = [pixel_sums(shape, self.device, name=f"{BUFFER_NAME}:half{half}") for half in (0, 1)]
        self.pixel_counts = [np.zeros(shape, np.float32) for _ in (0, 1)]

    def half_film(self, half: int, *, variance: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Mean radiance of ``half``'s paths and, with ``variance``, the variance of that mean (downloads: the error
        estimate needs them on the host)."""
        sums, count = self.halves[half], self.pixel_counts[half]
        radiance = device_buffers.download(f"{BUFFER_NAME}:radiance_sum", sums.radiance_sum)
        mean = radiance / np.maximum(count, 1)[..., None]
        if not variance:
            return mean, None
        total = radiance.astype(np.float64)
        squares = device_buffers.download(f"{BUFFER_NAME}:radiance_sq", sums.radiance_sq).astype(np.float64)
        return mean, variance_of_mean(total, squares, count.astype(np.float64)[..., None]).astype(np.float32)

    def film(self) -> ImageLayer:
        """Both halves' paths as the path tracer reports its own: their mean, the variance of that mean
        (``aovs["variance"]``) and the tracking counters (``stats``)."""
        return sums_layer(self.halves, self.pixel_counts[0] + self.pixel_counts[1], far=0.0, name=BUFFER_NAME)

    def estimate(self, single: np.ndarray, fine_coverage: np.ndarray, coverage: np.ndarray) -> float:
        """Estimated relative RMSE of the frame over its covered pixels (0 when nothing is covered), measured on the
        frame's own pixels: on a coarser film (``coverage`` its block means of ``fine_coverage``) the two halves
        are upsampled as the frame's image is, which averages part of the film's noise away. Denoised, at least
        the denoiser's bias where the halves measure it (:mod:`~warpsky.techniques.hybrid.estimate`, on the film)."""
        covered = fine_coverage @ LUMINANCE_WEIGHTS > 1.0 - COVERED_BELOW
        if not covered.any():
            return 0.0
        halves = [self.half_film(half, variance=self.settings.denoise) for half in (0, 1)]
        raw = tuple(mean for mean, _ in halves)
        a, b = raw
        if self.settings.denoise:
            radius, device = self.settings.mean_radius, self.device
            a, b = (denoise(half, coverage, radius=radius, device=device).image for half in raw)
        film_halves = (a, b)
        a, b = (guided_upsample(half, fine_coverage, self.scale) for half in (a, b))
        if self.settings.denoise:
            spread = 0.5 * (a - b) * ESTIMATE_CALIBRATION
        else:
            variance = self.film().aovs["variance"]
            if self.scale > 1:
                variance = bilinear_upsample(variance, self.scale, *fine_coverage.shape[:2])
            spread = np.sqrt(variance)
        level = float((single[covered] + 0.5 * (a[covered] + b[covered])).mean())
        if level <= 0.0:
            return 0.0
        estimate = relative_rms(spread, covered, level)
        if self.settings.denoise:  # at least the denoiser's bias, measured on the film
            film_single = block_mean(single, self.scale) if self.scale > 1 else single
            film_covered = coverage @ LUMINANCE_WEIGHTS > 1.0 - COVERED_BELOW
            estimate = max(estimate, denoised_estimate(halves, film_halves, film_single, film_covered,
                                                       self.pixel_counts))
        return estimate
