"""The kernels of the unbiased volumetric path tracer.

One path of a pixel (:func:`sample_function`) is the camera ray, its transmittance through every medium by ratio
tracking (the layer's transmittance AOV; zero where the ground or sea level ends the ray), then the path: a free
flight by delta tracking per bounce (:mod:`~warpsky.techniques.path_tracer.tracking`, local majorants from
:mod:`~warpsky.techniques.path_tracer.majorants`), and at its end a scattering event, a ground bounce or the end of
the path (:mod:`~warpsky.techniques.path_tracer.events`), with Russian roulette from the third bounce. Two ways
to launch it (both :func:`path_trace_kernel`) add the same float32 values in the same order: one thread per pixel
running the launch's paths one after the other, or one thread per path and pixel writing a :class:`SampleResult`,
then one thread per pixel adding them in path order (:func:`sum_samples_kernel`); the second fills a GPU when the
frame has too few pixels.

Warp passes a random state to a function by value, so each function hands back its advanced state and a path
carries one stream (re-seeding from the stream would replay it: rand_init(randi(s)) is s's next). The order of the
random draws is part of the result: a fixed seed gives the same image.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3
from warpsky.light.dome import DomeLight
from warpsky.light.sun import Sun
from warpsky.media.air.medium import Air, altitude, as_analytic, no_air, top_exit, vertical
from warpsky.media.air.mixture_kernels import air_optical_depth
from warpsky.media.air.round_earth_kernels import ray_depth
from warpsky.media.voxels.voxel import VoxelMedia, media_span
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.optics.phase_sampling import PhaseTables
from warpsky.surfaces.mesh import SurfaceHit, SurfaceMeshes, no_hit
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.events import (
    PathState,
    escaped_dome,
    escaped_radiance,
    event_functions,
    media_first_function,
    roulette,
    start_path,
    sun_reaches,
)
from warpsky.techniques.path_tracer.fog_media import fog_sun_transmittance, fog_view_transmittance
from warpsky.techniques.path_tracer.forward_cut import CutMedia, peak_light_function
from warpsky.techniques.path_tracer.majorants import Majorants
from warpsky.techniques.path_tracer.planet import ground_point
from warpsky.techniques.path_tracer.ray_ends import (
    SURFACE_GROUND,
    SURFACE_MESH,
    SURFACE_NONE,
    SURFACE_OPAQUE,
    SURFACE_SEA,
    UNBOUNDED,
    RayEnd,
    flight_end,
    primary_end,
)
from warpsky.techniques.path_tracer.sun_lobe import sun_lobe_function
from warpsky.techniques.path_tracer.surface_hits import (
    camera_mesh_end,
    mesh_event_function,
    mesh_flight_end,
    sun_unblocked,
)
from warpsky.techniques.path_tracer.tracking import tracking_functions

#: Samples of one pixel seed their streams ``seed + sample * SAMPLE_STRIDE`` (the pixel is the stream offset).
SAMPLE_STRIDE = wp.constant(9973)


@wp.struct
class PathSettings:
    """Per-launch settings of the path tracer."""

    environment: wp.vec3  # uniform radiance from every direction
    seed: int
    pixel_jitter: int  # 1: box-filtered pixels, 0: pixel centres
    first_sample: int  # index of the launch's first path per pixel
    sample_count: int  # paths per pixel in this launch
    max_bounces: int
    multiple_only: int  # 1: leave out single scattering (the sun at the first event) and the primary transmittance
    similarity_order: int  # after this many scattering events the media are reduced (high-order similarity); 0: never
    forward_cut: int  # 1: after the first event paths continue through the cut media (forward_cut.py)
    air_by_table: int  # 1: paths whose first event is the air's end there (a table holds the air's own light)
    first_end_low: float  # a camera ray's event at a camera-relative altitude in [low, high] ends its path there
    first_end_high: float  # (another pass draws what lies there: the stratiform layers); low > high: none
    sun_lobe_g: float  # the sun lobe's g (sun_lobe.py); NO_LOBE: none (kernels with meshes or fog take none)
    masked: int  # 1: only pixels whose ``active`` entry is non-zero run paths in this launch
    active: wp.array2d(dtype=wp.uint8)  # per film pixel (read only with ``masked``)


@wp.struct
class PixelSums:
    """Per-pixel sums the launches accumulate into."""

    radiance_sum: wp.array2d(dtype=wp.vec3)
    radiance_sq: wp.array2d(dtype=wp.vec3)
    transmittance_sum: wp.array2d(dtype=wp.vec3)
    depth_sum: wp.array2d(dtype=wp.vec2)  # (sum of depths, hits)
    counters: wp.array2d(dtype=wp.vec4i)  # (tracking steps, capped paths, scattering events, shadow-ray steps)


@wp.struct
class SampleResult:
    """One path of one pixel, as :func:`path_trace_kernel` leaves it for :func:`sum_samples_kernel`."""

    radiance: wp.vec3
    transmittance: wp.vec3  # the primary ray's ratio-tracked transmittance (when counts[2] is 1)
    depth: wp.vec2  # (depth of the first event, 1), or (0, 0) when the first flight ended nowhere
    counts: wp.vec4i  # (tracking steps, 1 if capped, scattering events, shadow-ray steps)
    tracked: int  # 1 if the primary transmittance was tracked


@wp.func
def air_transmittance(air: Air, origin: wp.vec3, view: wp.vec3, distance: float) -> wp.vec3:
    """Transmittance of the air from ``origin`` over ``distance`` [m] along ``view`` in closed form (Riley Eq. 11;
    ones without air), on a round earth by quadrature up to where the ray leaves the air: the primary ray's air is
    not tracked, its majorant bands would cost a step every 800 m."""
    if air.enabled == 0:
        return wp.vec3(1.0)
    if air.round != 0:
        h0 = altitude(air, origin)
        mu0 = wp.dot(view, vertical(air, origin))
        length = wp.min(distance, top_exit(air.planet, h0, mu0))
        return exp3(ray_depth(as_analytic(air), air.planet, h0, mu0, length))
    return exp3(air_optical_depth(as_analytic(air), air.camera_altitude + origin[1], view[1], distance))


@functools.cache
def first_event_function(has_tables: bool, has_detail: bool, has_fog: bool = False):
    """``first_event(...) -> PathState``, what a path does where its first flight ends, specialised like the
    kernels (the peak scatterings' sunlight comes through the analytic fogs too)."""
    first_event_peak_light = peak_light_function(has_tables, has_detail)

    @wp.func
    def first_event(media: VoxelMedia, majorants: Majorants, cut: CutMedia, phase_tables: PhaseTables, air: Air,
                    sun: Sun, ground: Ground, settings: PathSettings, sun_on: bool, path: PathState, t: float,
                    scattered: int, p: wp.vec3) -> PathState:
        """The first flight ended at ``t`` (``p``, scattering or on the ground): its depth is recorded, and with
        ``settings.forward_cut`` the sunlight of the event's peak scatterings added."""
        out = path
        out.hit = 1
        out.first_t = t
        if settings.forward_cut != 0 and sun_on:
            q = p
            if scattered == 0:
                q = ground_point(air, ground, p)
            peak = first_event_peak_light(media, majorants, cut, phase_tables, air, sun, ground, out.throughput,
                                          out.direction, q, 1 - scattered, out.state)
            if wp.static(has_fog):
                peak.radiance = wp.cw_mul(peak.radiance, fog_sun_transmittance(majorants.fog, q, sun.direction, 0))
            out.radiance = out.radiance + peak.radiance
            out.state = peak.state
            out.steps = out.steps + peak.steps
            out.shadow_steps = out.shadow_steps + peak.steps
        return out

    return first_event


@wp.func
def lobe_reaches(settings: PathSettings, sun_on: bool, bounce: int) -> bool:
    """Whether the event after flight ``bounce`` takes the sunlight the sun lobe shares: the sun is up, the path
    may still scatter there and the event is not one after high-order similarity."""
    if not sun_on or bounce >= settings.max_bounces:
        return False
    return settings.similarity_order <= 0 or bounce < settings.similarity_order


@wp.func
def next_media(media: VoxelMedia, cut: CutMedia, settings: PathSettings) -> VoxelMedia:
    """The media of every flight after the first: the cut ones with ``settings.forward_cut``."""
    if settings.forward_cut != 0:
        return cut.media
    return media


@wp.func
def next_majorants(majorants: Majorants, cut: CutMedia, settings: PathSettings) -> Majorants:
    """The majorants of :func:`next_media`."""
    if settings.forward_cut != 0:
        return cut.majorants
    return majorants


@functools.cache
def path_function(has_tables: bool, has_detail: bool = False, has_meshes: bool = False, has_fog: bool = False):
    """``trace_path(...) -> PathState``, one path from its camera ray (one loop carrying state), specialised like
    the kernels; with ``has_meshes`` its flights end at the meshes and bounce on them, with ``has_fog`` the analytic
    fogs are tracked with the media. The ground plane and the dome are runtime tests (``ground.enabled``,
    ``dome.enabled``): uniform over a launch, one per path event."""
    delta_track = tracking_functions(has_detail, has_fog)[1]
    mesh_event = mesh_event_function(has_detail, has_fog)
    scatter_event, reduced_scatter_event, ground_event = event_functions(has_tables, has_detail, has_fog)
    media_first = media_first_function(has_detail, has_fog)
    first_event = first_event_function(has_tables, has_detail, has_fog)
    sun_lobe_light = sun_lobe_function(has_tables, has_detail)

    @wp.func
    def trace_path(media: VoxelMedia, majorants: Majorants, cut: CutMedia, phase_tables: PhaseTables, air: Air,
                   sun: Sun, ground: Ground, dome: DomeLight, surfaces: SurfaceMeshes, settings: PathSettings,
                   sun_on: bool, start: PathState, first: RayEnd, first_hit: SurfaceHit) -> PathState:
        """One path from the camera ray ``start`` (which ends at ``first``, on the mesh ``first_hit`` when it
        hit one): one loop carrying state, per bounce a free flight (with meshes, to the nearest mesh hit at most),
        then a scattering event, a ground or mesh bounce (:mod:`~warpsky.techniques.path_tracer.surface_hits`; the
        meshes also shadow the other events' sunlight), or the end (environment, sun disk, sea level), then
        roulette. With ``settings.multiple_only`` the first event takes no sunlight and a camera ray does not see
        the sun's disk: the path carries light scattered at least twice (media, air or ground), the part that an
        exact single-scattering march and the analytic sky leave out, and all the dome's light but what the camera
        sees of it directly (the composite's background). With ``settings.forward_cut`` the flights and events after
        the first run through the ``cut`` media, and the first event adds the sunlight of its peak scatterings."""
        path = start
        if wp.static(has_tables):  # the hero channel of the phase tables' sampling, uniformly (one draw)
            state = path.state
            path.hero = wp.min(int(wp.randf(state) * 3.0), 2)
            path.state = state
        bounce = int(0)
        while path.alive != 0:
            if bounce >= settings.max_bounces:
                path.capped = 1
                break
            reduced = int(0)
            if settings.similarity_order > 0 and bounce >= settings.similarity_order:
                reduced = 1
            here = media
            bounds = majorants
            if settings.forward_cut != 0 and bounce >= 1:
                here = cut.media
                bounds = cut.majorants
            end = flight_end(air, ground, path.origin, path.direction, bounce, first)
            if wp.static(has_meshes):
                stop = mesh_flight_end(surfaces, path.origin, path.direction, bounce, first_hit, end)
                end = stop.end
            flight = delta_track(here, bounds, air, path.origin, path.direction, end.t, path.throughput,
                                 path.state, reduced)
            path.state = flight.state
            path.steps = path.steps + flight.steps
            path.throughput = wp.cw_mul(path.throughput, flight.weight)
            lit = sun_on
            if bounce == 0:
                lit = sun_on and settings.multiple_only == 0
            if flight.scattered == 0 and end.surface != SURFACE_GROUND and end.surface != SURFACE_MESH:
                # a black sea gives nothing; an opaque surface's pass draws what lies there and beyond
                if end.surface != SURFACE_OPAQUE and end.surface != SURFACE_SEA:
                    path.radiance = path.radiance + escaped_radiance(air, sun, settings.environment,
                                                                     path.direction, path.throughput, bounce, lit)
                    if dome.enabled != 0:
                        path.radiance = path.radiance + escaped_dome(air, dome, path.direction, path.throughput,
                                                                     bounce)
                break
            p = path.origin + flight.t * path.direction
            if bounce == 0 and flight.scattered == 1:
                if p[1] >= settings.first_end_low and p[1] <= settings.first_end_high:
                    break  # the pass that draws this band draws its light on the camera ray
            event_sun = sun_on
            if wp.static(has_meshes):  # a mesh's own event tests its shadow; no peak light is added on a mesh
                event_sun = sun_on and (flight.scattered == 1 or end.surface != SURFACE_MESH)
                if event_sun:
                    if not sun_unblocked(surfaces, air, ground, sun, p, 1 - flight.scattered):
                        event_sun = False
                        lit = False
            if bounce == 0:
                path = first_event(media, majorants, cut, phase_tables, air, sun, ground, settings, event_sun, path,
                                   flight.t, flight.scattered, p)
            if flight.scattered == 1:
                path.events = path.events + 1
                air_weight = float(1.0)
                if bounce == 0 and settings.air_by_table != 0 and air.enabled != 0:
                    path = media_first(here, bounds, air, path, p)
                    air_weight = 0.0
                    if path.alive == 0:
                        break
                if reduced != 0:
                    path = reduced_scatter_event(here, bounds, air, sun, lit, path, p)
                else:
                    arrived = path
                    path = scatter_event(here, bounds, phase_tables, air, sun, lit, path, p, air_weight)
                    if wp.static(not has_meshes and not has_fog):
                        if path.lobe_pdf > 0.0:  # the sun lobe's share of the next event's sunlight
                            if not lobe_reaches(settings, sun_on, bounce + 1):
                                path.lobe_pdf = 0.0
                            else:
                                lobe = sun_lobe_light(here, next_media(media, cut, settings),
                                                      next_majorants(majorants, cut, settings), phase_tables, air,
                                                      sun, ground, arrived, p, air_weight, bounce + 1, first,
                                                      path.state)
                                path.radiance = path.radiance + lobe.radiance
                                path.steps = path.steps + lobe.steps
                                path.shadow_steps = path.shadow_steps + lobe.shadow_steps
                                path.state = lobe.state
            elif end.surface == SURFACE_MESH:
                if wp.static(has_meshes):
                    path = mesh_event(here, bounds, air, sun, surfaces, lit, path, p, stop.hit, reduced)
            else:
                path = ground_event(here, bounds, air, sun, ground, lit, path, p, reduced)
            if flight.scattered == 0 or reduced != 0:
                path.lobe_pdf = 0.0  # a bounce's or a reduced event's direction shares no sunlight
            bounce += 1
            path = roulette(path, bounce)
        return path

    return trace_path


@wp.func
def carries_nothing(media: VoxelMedia, air: Air, settings: PathSettings, origin: wp.vec3, view: wp.vec3,
                    first: RayEnd) -> bool:
    """Whether a multiple-scattering path (``settings.multiple_only``) along this camera ray gathers no light
    whatever its random draws: the ray meets no medium's box before ``first`` and does not end on the ground, and
    the air is absent or a table holds its light (the path would end at its first air event). Such a path escapes
    to space, a black sea level or an opaque surface with nothing (a camera ray that escapes sees neither the
    dome nor the sun's disk here: the composite draws them), so the tracker need not fly it through the air."""
    if settings.multiple_only == 0 or first.surface == SURFACE_GROUND:
        return False
    if air.enabled != 0 and settings.air_by_table == 0:
        return False
    span = media_span(media, origin, view, 0.0, first.t)
    return span[1] <= span[0]


@functools.cache
def sample_function(has_tables: bool, has_detail: bool = False, has_meshes: bool = False, has_fog: bool = False):
    """The function that runs one path of a pixel (:class:`SampleResult`), specialised like the kernels (a scene
    without analytic fog runs the code it ran before the path tracer traced fog)."""
    ratio_track = tracking_functions(has_detail)[2]
    trace_path = path_function(has_tables, has_detail, has_meshes, has_fog)

    @wp.func
    def pixel_sample(media: VoxelMedia, majorants: Majorants, cut: CutMedia, phase_tables: PhaseTables, air: Air,
                     sun: Sun, cam: PinholeCamera, ground: Ground, dome: DomeLight, surfaces: SurfaceMeshes,
                     settings: PathSettings, row: int, col: int, sample: int) -> SampleResult:
        """Path ``sample`` of pixel (row, col): the camera ray (jittered in the pixel when asked), the primary
        transmittance, the path, the depth of its first event. Its random stream depends on the seed, the pixel and
        the path index alone."""
        state = wp.rand_init(settings.seed + sample * SAMPLE_STRIDE, row * cam.width + col)
        fx = float(0.5)
        fy = float(0.5)
        if settings.pixel_jitter != 0:
            # a box-filtered pixel, as Mitsuba and pbrt sample it (used by the Mitsuba cross-check)
            fx = wp.randf(state)
            fy = wp.randf(state)
        ray = primary_ray(cam, row, col, fx, fy)
        view = ray.direction
        origin = ray.origin + view * ray.t_near
        # the far clip bounds what the camera sees of the media and the ground, not the air (which the sky pass
        # also draws to its end): with air the camera ray runs to the ground, sea level or space
        t_end = ray.t_far - ray.t_near
        if air.enabled != 0:
            t_end = UNBOUNDED
        first = primary_end(air, ground, origin, view, t_end)
        first_hit = no_hit(first.t)
        if wp.static(has_meshes):  # the nearest mesh ends the camera ray where it is nearer
            seen = camera_mesh_end(surfaces, origin, view, first)
            first = seen.end
            first_hit = seen.hit
        if cam.has_opaque != 0:  # a surface drawn by another pass ends the camera ray (primary_ray's t_far)
            if cam.opaque[row, col] < cam.far and ray.t_far - ray.t_near <= first.t:
                first.t = ray.t_far - ray.t_near
                first.surface = SURFACE_OPAQUE
                first_hit.hit = 0
        out = SampleResult()
        steps = int(0)
        tracked = int(0)
        if first.surface == SURFACE_NONE and settings.multiple_only == 0:
            tr = ratio_track(media, majorants, no_air(), origin, view, first.t, state, 0)
            state = tr.state
            out.transmittance = wp.cw_mul(tr.value, air_transmittance(air, origin, view, first.t))
            if wp.static(has_fog):  # closed form, exact
                out.transmittance = wp.cw_mul(out.transmittance,
                                              fog_view_transmittance(majorants.fog, origin, view, first.t))
            steps = tr.steps
            tracked = 1
        if wp.static(not has_meshes and not has_fog):
            if carries_nothing(media, air, settings, origin, view, first):
                return out
        start = start_path(origin, view, state, steps)
        if wp.static(not has_meshes and not has_fog):
            start.lobe_g = settings.sun_lobe_g
        path = trace_path(media, majorants, cut, phase_tables, air, sun, ground, dome, surfaces, settings,
                          sun_reaches(sun, air), start, first, first_hit)
        if path.hit != 0:
            out.depth = wp.vec2((ray.t_near + path.first_t) * ray.cos_axis, 1.0)
        out.radiance = path.radiance
        out.counts = wp.vec4i(path.steps, path.capped, path.events, path.shadow_steps)
        out.tracked = tracked
        return out

    return pixel_sample


@wp.func
def add_sample(sums: PixelSums, row: int, col: int, sample: SampleResult):
    """Add one path's radiance, its square, its tracked transmittance and its depth to pixel (row, col)."""
    if sample.tracked != 0:
        sums.transmittance_sum[row, col] = sums.transmittance_sum[row, col] + sample.transmittance
    if sample.depth[1] != 0.0:
        sums.depth_sum[row, col] = sums.depth_sum[row, col] + sample.depth
    sums.radiance_sum[row, col] = sums.radiance_sum[row, col] + sample.radiance
    sums.radiance_sq[row, col] = sums.radiance_sq[row, col] + wp.cw_mul(sample.radiance, sample.radiance)


@kernel_variants(has_tables=(False, True), has_detail=(False, True), has_meshes=(False, True), has_fog=(False, True))
@functools.cache
def path_trace_kernel(has_tables: bool, has_detail: bool = False, has_meshes: bool = False,
                      has_fog: bool = False) -> wp.Kernel:
    """The progressive path tracer in both launch shapes (one kernel per scene kind, hence one CUDA module, for
    frames of any size). With ``samples`` empty (None), one thread per pixel runs the launch's
    ``settings.sample_count`` paths in path order into ``sums`` (with ``settings.masked``, only the pixels it marks
    active). Otherwise one thread per (path, pixel): a launch
    over a frame of H rows covers ``sample_count`` x H rows, row r running path r // H of pixel row r % H into
    ``samples[r]`` (``sums`` untouched); :func:`sum_samples_kernel` then adds them. Only ``has_meshes`` kernels
    read ``surfaces`` (the meshes' BVH); the others are given an empty one (:func:`~warpsky.surfaces.mesh.
    no_surfaces`) and run the code they ran before the path tracer traced meshes; likewise only ``has_fog``
    kernels read the majorants' fogs. Whether the scene has a ground plane or a dome is not a variant: the kernel
    tests ``ground.enabled`` and ``dome.enabled`` (:mod:`~warpsky.core.kernel_variants`' rule)."""
    pixel_sample = sample_function(has_tables, has_detail, has_meshes, has_fog)

    @wp.kernel(module="unique")
    def path_trace(
        media: VoxelMedia,
        majorants: Majorants,
        cut: CutMedia,
        phase_tables: PhaseTables,
        air: Air,
        sun: Sun,
        cam: PinholeCamera,
        ground: Ground,
        dome: DomeLight,
        surfaces: SurfaceMeshes,
        settings: PathSettings,
        sums: PixelSums,
        samples: wp.array2d(dtype=SampleResult),
        row_offset: int,
    ):
        """Thread (row_offset + tid row, tid col): its paths (see the factory) into ``sums`` or ``samples``."""
        r, col = wp.tid()
        row = r + row_offset
        keep = samples.shape[0] != 0
        path = row // cam.height  # 0 with one thread per pixel
        pixel_row = row - path * cam.height
        count = settings.sample_count
        if keep:
            count = 1
        counts = wp.vec4i(0, 0, 0, 0)
        if settings.masked != 0:
            if settings.active[pixel_row, col] == wp.uint8(0):
                if keep:
                    samples[row, col] = SampleResult()  # sum_samples adds nothing for it
                return
        for s in range(count):
            sample = pixel_sample(media, majorants, cut, phase_tables, air, sun, cam, ground, dome, surfaces,
                                  settings, pixel_row, col, settings.first_sample + path + s)
            if keep:
                samples[row, col] = sample
            else:
                add_sample(sums, pixel_row, col, sample)
                counts = counts + sample.counts
        if not keep:
            sums.counters[pixel_row, col] = sums.counters[pixel_row, col] + counts

    return path_trace


@kernel_variants()
@functools.cache
def sum_samples_kernel() -> wp.Kernel:
    """The per-pixel sum of the paths :func:`path_trace_kernel` left in a buffer (one thread per path and pixel)."""

    @wp.kernel(module="unique")
    def sum_samples(samples: wp.array2d(dtype=SampleResult), sample_count: int, sums: PixelSums, row_offset: int):
        """Pixel (row_offset + tid row, tid col): the ``sample_count`` paths in ``samples`` added in path order, as
        :func:`path_trace_kernel` adds them (the same sums, bit for bit)."""
        r, col = wp.tid()
        row = r + row_offset
        height = sums.radiance_sum.shape[0]
        counts = wp.vec4i(0, 0, 0, 0)
        for s in range(sample_count):
            sample = samples[s * height + row, col]
            add_sample(sums, row, col, sample)
            counts = counts + sample.counts
        sums.counters[row, col] = sums.counters[row, col] + counts

    return sum_samples
