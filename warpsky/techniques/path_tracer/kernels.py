"""The per-pixel kernel of the unbiased volumetric path tracer.

Each thread runs a pixel's paths of one launch: the camera ray, its transmittance through every medium by ratio
tracking (the layer's transmittance AOV; zero where the ground or sea level ends the ray), then the path: a free
flight by delta tracking per bounce (:mod:`~warpsky.techniques.path_tracer.tracking`, local majorants from
:mod:`~warpsky.techniques.path_tracer.majorants`), and at its end a scattering event, a ground bounce or the end of
the path (:mod:`~warpsky.techniques.path_tracer.events`), with Russian roulette from the third bounce.

Warp passes a random state to a function by value, so each function hands back its advanced state and a path
carries one stream (re-seeding from the stream would replay it: rand_init(randi(s)) is s's next). The order of the
random draws is part of the result: a fixed seed gives the same image.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.kernel_variants import kernel_variants
from warpsky.media.air import Air
from warpsky.media.voxel import VoxelMedia
from warpsky.optics.phase_sampling import PhaseTables
from warpsky.techniques.common import (
    Ground,
    PinholeCamera,
    Sun,
    camera_forward,
    camera_ray,
    camera_ray_at,
    camera_ray_origin,
)
from warpsky.techniques.dome import DomeLight
from warpsky.techniques.path_tracer.events import (
    SURFACE_GROUND,
    SURFACE_NONE,
    PathState,
    RayEnd,
    escaped_dome,
    escaped_radiance,
    event_functions,
    roulette,
    start_path,
    surface_functions,
)
from warpsky.techniques.path_tracer.majorants import Majorants
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


@wp.struct
class PixelSums:
    """Per-pixel sums the launches accumulate into."""

    radiance_sum: wp.array2d(dtype=wp.vec3)
    radiance_sq: wp.array2d(dtype=wp.vec3)
    transmittance_sum: wp.array2d(dtype=wp.vec3)
    depth_sum: wp.array2d(dtype=wp.vec2)  # (sum of depths, hits)
    counters: wp.array2d(dtype=wp.vec2i)  # (tracking steps, capped paths)


@kernel_variants(has_ground=(False, True), has_tables=(False, True), has_detail=(False, True),
                 has_dome=(False, True))
@functools.cache
def path_trace_kernel(has_ground: bool, has_tables: bool, has_detail: bool = False,
                      has_dome: bool = False) -> wp.Kernel:
    """The per-pixel progressive path tracer, specialised on ground, tabulated species, animated detail and a
    dome (a scene without one runs exactly the code it ran before domes existed)."""
    _media_at, delta_track, ratio_track = tracking_functions(has_detail)
    primary_end, flight_end, sun_reaches = surface_functions(has_ground)
    scatter_event, ground_event = event_functions(has_ground, has_tables, has_detail)

    @wp.func
    def trace_path(media: VoxelMedia, majorants: Majorants, phase_tables: PhaseTables, air: Air, sun: Sun,
                   ground: Ground, dome: DomeLight, settings: PathSettings, sun_on: bool, start: PathState,
                   first: RayEnd) -> PathState:
        """One path from the camera ray ``start`` (which ends at ``first``): per bounce a free flight, then a
        scattering event, a ground bounce, or the end (environment, sun disk, sea level), then roulette. With
        ``settings.multiple_only`` the first event takes no sunlight and a camera ray does not see the sun's disk:
        the path carries light scattered at least twice (media, air or ground), the part that an exact
        single-scattering march and the analytic sky leave out, and all the dome's light but what the camera sees
        of it directly (the composite's background)."""
        path = start
        bounce = int(0)
        while path.alive != 0:
            if bounce >= settings.max_bounces:
                path.capped = 1
                break
            end = flight_end(air, ground, path.origin, path.direction, bounce, first)
            flight = delta_track(media, majorants, air, path.origin, path.direction, end.t, path.throughput,
                                 path.state)
            path.state = flight.state
            path.steps = path.steps + flight.steps
            path.throughput = wp.cw_mul(path.throughput, flight.weight)
            lit = sun_on
            if bounce == 0:
                lit = sun_on and settings.multiple_only == 0
            if flight.scattered == 0 and end.surface != SURFACE_GROUND:
                path.radiance = path.radiance + escaped_radiance(air, sun, settings.environment, path.direction,
                                                                 path.throughput, bounce, lit)
                if wp.static(has_dome):
                    path.radiance = path.radiance + escaped_dome(air, dome, path.direction, path.throughput, bounce)
                break
            p = path.origin + flight.t * path.direction
            if bounce == 0:
                path.hit = 1
                path.first_t = flight.t
            if flight.scattered == 1:
                path = scatter_event(media, majorants, phase_tables, air, sun, lit, path, p)
            else:
                path = ground_event(media, majorants, air, sun, ground, lit, path, p)
            bounce += 1
            path = roulette(path, bounce)
        return path

    @wp.kernel(module="unique")
    def path_trace(
        media: VoxelMedia,
        majorants: Majorants,
        phase_tables: PhaseTables,
        air: Air,
        sun: Sun,
        cam: PinholeCamera,
        ground: Ground,
        dome: DomeLight,
        settings: PathSettings,
        sums: PixelSums,
        row_offset: int,
    ):
        """Pixel (row_offset + tid row, tid col): ``settings.sample_count`` paths added to ``sums``. Per sample: the
        camera ray (jittered in the pixel when asked), the primary transmittance AOV, the path, the depth AOV where
        its first flight ended in a medium or on the ground."""
        r, col = wp.tid()
        row = r + row_offset
        centre = camera_ray(cam, row, col)
        centre_origin = camera_ray_origin(cam, row, col, 0.5, 0.5)
        axis = camera_forward(cam)
        sun_on = sun_reaches(sun, air)
        pixel = row * cam.width + col
        steps = int(0)
        capped = int(0)
        for s in range(settings.sample_count):
            state = wp.rand_init(settings.seed + (settings.first_sample + s) * SAMPLE_STRIDE, pixel)
            view = centre
            eye = centre_origin
            if settings.pixel_jitter != 0:
                # a box-filtered pixel, as Mitsuba and pbrt sample it (used by the Mitsuba cross-check)
                fx = wp.randf(state)
                fy = wp.randf(state)
                view = camera_ray_at(cam, row, col, fx, fy)
                eye = camera_ray_origin(cam, row, col, fx, fy)
            cos_axis = wp.dot(view, axis)
            t_near = cam.near / cos_axis
            t_far = cam.far / cos_axis
            origin = eye + view * t_near
            first = primary_end(air, ground, origin, view, t_far - t_near)
            if first.surface == SURFACE_NONE and settings.multiple_only == 0:
                tr = ratio_track(media, majorants, air, origin, view, first.t, state)
                state = tr.state
                sums.transmittance_sum[row, col] = sums.transmittance_sum[row, col] + tr.value
                steps += tr.steps
            path = trace_path(media, majorants, phase_tables, air, sun, ground, dome, settings, sun_on,
                              start_path(origin, view, state, steps), first)
            steps = path.steps
            capped += path.capped
            if path.hit != 0:
                sums.depth_sum[row, col] = sums.depth_sum[row, col] + wp.vec2((t_near + path.first_t) * cos_axis, 1.0)
            sums.radiance_sum[row, col] = sums.radiance_sum[row, col] + path.radiance
            sums.radiance_sq[row, col] = sums.radiance_sq[row, col] + wp.cw_mul(path.radiance, path.radiance)
        sums.counters[row, col] = sums.counters[row, col] + wp.vec2i(steps, capped)

    return path_trace
