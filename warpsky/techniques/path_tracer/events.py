"""What happens where a path's free flight ends: scattering in a medium, a bounce on the ground, or the end.

At a scattering point the path takes next-event estimation toward the sunlight (the light of the disk's visible
part, :mod:`warpsky.light.sun`; ratio-tracked transmittance times the media's mixed phase) and samples a
new direction from that mixture; where the sun lobe also reaches the event (:mod:`~warpsky.techniques.path_tracer.
sun_lobe`), it keeps its balance-heuristic share of that sunlight. On the Lambertian ground it takes the sun
through the media, then a cosine-weighted bounce. A path that leaves every medium gains the uniform environment
and the dome (after a bounce) or, with air, the sun's disk seen directly; with air a downward path ends at a black
sea level.

On a round earth (``air.round``) the air ends below at its floor's sphere: the ground plane, when the scene has one
at or above sea level, is that sphere (its albedo, the local vertical its normal), else it is a black sea level; a
path that leaves the top of the air escapes, whichever way it points, when it misses the planet.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.light.dome import DomeLight, dome_radiance
from warpsky.light.sun import Sun
from warpsky.media.air.medium import (
    Air,
    AirPart,
    air_part,
    air_scattering,
    no_air,
    part_phase,
    part_total,
    scaled_part,
    vertical,
)
from warpsky.media.phase_mixture import mixture_functions, oriented_correction_function
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia, media_functions
from warpsky.optics.kernels import medium_phase, scattering_angle
from warpsky.optics.phase import hg_sample_cos, isotropic_sample_cos, phase_hg
from warpsky.optics.phase_sampling import PhaseTables, rotate_about
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.fog_media import fog_coefficients, fog_sun_transmittance, pick_fog
from warpsky.techniques.path_tracer.majorants import Majorants
from warpsky.techniques.path_tracer.planet import (
    air_to_sun,
    cosine_about,
    cosine_up,
    ground_cosine,
    ground_point,
)
from warpsky.techniques.path_tracer.ray_ends import UNBOUNDED
from warpsky.techniques.path_tracer.tracking import Transmittance, reduced_with_air, tracking_functions

oriented_mixture_correction = oriented_correction_function(medium_phase)[1]

#: Russian roulette starts once a path has bounced this often.
ROULETTE_BOUNCE = wp.constant(3)
#: ``PathState.lobe_g`` of a path that takes no sun lobe (sun_lobe.py).
NO_LOBE = wp.constant(-1.0)


@wp.func
def reduced_mixture(air_s: AirPart, media_part: wp.vec3, total: wp.vec3, cos_theta: float) -> wp.vec3:
    """The phase [1/sr] of air (its constituents' scattering ``air_s``) mixed with isotropic media
    (``media_part``), per channel; 0 where nothing scatters."""
    out = wp.vec3(0.0)
    air_phase = part_phase(air_s, cos_theta)
    for c in range(3):
        if total[c] > 0.0:
            out[c] = (air_phase[c] + media_part[c] / (4.0 * wp.pi)) / total[c]
    return out


@wp.struct
class PathState:
    """One path between events."""

    origin: wp.vec3  # start of the next flight (camera-relative) [m]
    direction: wp.vec3
    throughput: wp.vec3
    radiance: wp.vec3  # gathered so far
    state: wp.uint32  # the path's one random stream
    steps: int  # tentative collisions so far (the pixel's running count)
    shadow_steps: int  # of those, the ones of shadow rays towards the sun
    events: int  # scattering events in the media and the air so far
    alive: int
    capped: int  # 1 when the path stopped at max_bounces
    hit: int  # 1 when the first flight ended in a medium or on the ground
    first_t: float  # where the first flight ended [m from the near plane]
    hero: int  # the colour channel whose phase tables the path samples (green without tables)
    ratio: wp.vec3  # the path's direction densities with each channel as hero, over their largest
    lobe_g: float  # the sun lobe's Henyey-Greenstein g (sun_lobe.py); NO_LOBE: the path takes none
    lobe_pdf: float  # the density [1/sr] its direction was drawn with, where the sun lobe shares the next sunlight


@wp.func
def start_path(origin: wp.vec3, direction: wp.vec3, state: wp.uint32, steps: int) -> PathState:
    """A path leaving ``origin`` along ``direction`` with unit throughput and no light yet."""
    out = PathState()
    out.origin = origin
    out.direction = direction
    out.throughput = wp.vec3(1.0)
    out.radiance = wp.vec3(0.0)
    out.state = state
    out.steps = steps
    out.shadow_steps = 0
    out.events = 0
    out.lobe_g = NO_LOBE
    out.lobe_pdf = 0.0
    out.alive = 1
    out.capped = 0
    out.hit = 0
    out.first_t = 0.0
    out.hero = 1
    out.ratio = wp.vec3(1.0)
    return out


@wp.func
def escaped_radiance(air: Air, sun: Sun, environment: wp.vec3, d: wp.vec3, throughput: wp.vec3, bounce: int,
                     sun_on: bool) -> wp.vec3:
    """Light a path of ``throughput`` gains when its flight along ``d`` leaves every medium: none at a black sea
    level (with a flat earth's air, downward), the environment after a bounce, the sun's disk seen directly with
    air (then the path tracer draws it itself: the sky pass is not used). A round earth's path gets here only when
    it left the top of the air, above the planet's horizon."""
    out = wp.vec3(0.0)
    if air.enabled != 0 and air.round == 0 and d[1] < 0.0:
        return out
    if bounce > 0:
        out = wp.cw_mul(throughput, environment)
    elif air.enabled != 0 and sun_on and wp.dot(d, sun.disk_direction) >= sun.cos_radius:
        out = wp.cw_mul(throughput, sun.disk_radiance)  # the horizon (the planet) clips the disk: the ray missed it
    return out


@wp.func
def escaped_dome(air: Air, dome: DomeLight, d: wp.vec3, throughput: wp.vec3, bounce: int) -> wp.vec3:
    """The dome's light on a path of ``throughput`` that escapes along ``d`` after a bounce (with air: upward, out
    of the air). A camera ray that escapes (bounce 0) gains nothing here: the frame's composite draws the dome
    behind the layer's transmittance, as it draws it behind every technique's. A round earth's path gets here only
    when it left the top of the air."""
    out = wp.vec3(0.0)
    if bounce > 0 and not (air.enabled != 0 and air.round == 0 and d[1] < 0.0):
        out = wp.cw_mul(throughput, dome_radiance(dome, d))
    return out


@wp.func
def roulette(path: PathState, bounce: int) -> PathState:
    """Russian roulette once a path is ``ROULETTE_BOUNCE`` bounces deep (one random draw when it may stop)."""
    out = path
    if bounce >= ROULETTE_BOUNCE:
        q = wp.min(wp.max(out.throughput), 1.0)
        if q <= 0.0:
            out.alive = 0
        elif q < 1.0:
            state = out.state
            if wp.randf(state) < q:
                out.throughput = out.throughput / q
            else:
                out.alive = 0
            out.state = state
    return out


@wp.func
def sun_reaches(sun: Sun, air: Air) -> bool:
    """Whether the sun lights the scene: ``lit``, which the host sets from the part of the disk above the
    horizon where a ground or the air is there to hide it (:mod:`warpsky.light.sun`)."""
    return sun.lit != 0


@functools.cache
def sun_transmittance_function(has_detail: bool, has_fog: bool = False):
    """``transmittance_to_sun(media, majorants, air, sun, p, state, reduced) -> Transmittance``, specialised on
    animated detail and analytic fog (whose transmittance is its closed form)."""
    ratio_track = tracking_functions(has_detail)[2]

    @wp.func
    def transmittance_to_sun(media: VoxelMedia, majorants: Majorants, air: Air, sun: Sun, p: wp.vec3,
                             state: wp.uint32, reduced: int) -> Transmittance:
        """Transmittance from ``p`` to the sun (with ``reduced``, through the media after high-order similarity):
        the media ratio-tracked, the air in closed form, its vertical column above ``p`` over ``air_sine`` (exact
        for the flat earth's ray above the grazing elevations, and there the finite grazing air mass every other
        technique uses), or a round earth's from its table (none of the media tracked where the planet hides the
        sun). Tracking the air instead crossed a majorant band every 800 m of height up to 114 km."""
        through_air = air_to_sun(air, sun, p)
        if air.round != 0 and wp.max(through_air) <= 0.0:
            out = Transmittance()
            out.value = through_air
            out.steps = 0
            out.state = state
            return out
        out = ratio_track(media, majorants, no_air(), p, sun.direction, UNBOUNDED, state, reduced)
        out.value = wp.cw_mul(out.value, through_air)
        if wp.static(has_fog):
            out.value = wp.cw_mul(out.value, fog_sun_transmittance(majorants.fog, p, sun.direction, reduced))
        return out

    return transmittance_to_sun


@functools.cache
def reduced_event_function(has_detail: bool, has_fog: bool = False):
    """``reduced_scatter_event(media, majorants, air, sun, sun_on, path, p) -> PathState``: scattering after
    high-order similarity, specialised on animated detail and analytic fog (reduced like the media)."""
    sample_media = media_functions(has_detail)
    transmittance_to_sun = sun_transmittance_function(has_detail, has_fog)

    @wp.func
    def reduced_scatter_event(media: VoxelMedia, majorants: Majorants, air: Air, sun: Sun, sun_on: bool,
                              path: PathState, p: wp.vec3) -> PathState:
        """Scattering at ``p`` after high-order similarity: the media scatter isotropically with their reduced
        coefficients beside the air's Rayleigh phase; the sun through the reduced media times that mixture, then a
        direction drawn uniformly over the sphere (two random draws) weighted by the mixture over 1 / (4 pi)."""
        out = path
        air_s = air_part(air, p)
        media_part = reduced_with_air(media, sample_media(media, p), no_air(), p).scattering
        if wp.static(has_fog):
            media_part = media_part + fog_coefficients(majorants.fog, p, 1).scattering
        total = part_total(air_s) + media_part
        if sun_on:
            tr_sun = transmittance_to_sun(media, majorants, air, sun, p, out.state, 1)
            out.state = tr_sun.state
            out.steps = out.steps + tr_sun.steps
            out.shadow_steps = out.shadow_steps + tr_sun.steps
            phase = reduced_mixture(air_s, media_part, total, wp.dot(sun.direction, out.direction))
            out.radiance = out.radiance + wp.cw_mul(wp.cw_mul(out.throughput, phase),
                                                    wp.cw_mul(sun.irradiance, tr_sun.value))
        state = out.state
        cos_theta = isotropic_sample_cos(wp.randf(state))
        direction = rotate_about(out.direction, cos_theta, 2.0 * wp.pi * wp.randf(state))
        out.throughput = wp.cw_mul(out.throughput, reduced_mixture(air_s, media_part, total, cos_theta)
                                   * (4.0 * wp.pi))
        out.state = state
        out.direction = direction
        out.origin = p
        return out

    return reduced_scatter_event


@functools.cache
def media_first_function(has_detail: bool, has_fog: bool = False):
    """``media_first(media, majorants, air, path, p) -> PathState``, specialised on animated detail and analytic
    fog (which counts with the media: the table holds the air's light alone)."""
    sample_media = media_functions(has_detail)

    @wp.func
    def media_first(media: VoxelMedia, majorants: Majorants, air: Air, path: PathState, p: wp.vec3) -> PathState:
        """The first scattering event of a path whose air-only light a table already holds (the sky pass's
        multiple-scattering table): the event is the air's with probability q = sum of the air's scattering over
        the sum of all (over the channels), and then the path ends, its light being the table's; otherwise it is
        the media's, each channel weighted by its media share over 1 - q, so every channel's expectation is the
        media's share of the event exactly (one random draw when 0 < q < 1). The path then scatters with the
        media's phase alone (``air_weight`` 0)."""
        out = path
        air_s = air_scattering(air, p)
        media_part = sample_media(media, p).scattering
        if wp.static(has_fog):
            media_part = media_part + fog_coefficients(majorants.fog, p, 0).scattering
        total = air_s + media_part
        q = (air_s[0] + air_s[1] + air_s[2]) / wp.max(total[0] + total[1] + total[2], 1.0e-30)
        if q <= 0.0:
            return out
        state = out.state
        if q >= 1.0 or wp.randf(state) < q:
            out.alive = 0
        else:
            weight = wp.vec3(0.0)
            for c in range(3):
                if total[c] > 0.0:
                    weight[c] = media_part[c] / (total[c] * (1.0 - q))
            out.throughput = wp.cw_mul(out.throughput, weight)
        out.state = state
        return out

    return media_first


@functools.cache
def fog_event_function(has_detail: bool, has_fog: bool):
    """``fog_scatter_event(media, majorants, air, sun, sun_on, path, p, g) -> PathState``, specialised on animated
    detail and analytic fog."""
    transmittance_to_sun = sun_transmittance_function(has_detail, has_fog)

    @wp.func
    def fog_scatter_event(media: VoxelMedia, majorants: Majorants, air: Air, sun: Sun, sun_on: bool,
                          path: PathState, p: wp.vec3, g: float) -> PathState:
        """Scattering in a fog at ``p`` (:func:`~warpsky.techniques.path_tracer.fog_media.pick_fog` chose it): the
        sun through everything times its Henyey-Greenstein phase, then a direction drawn from that phase (weight 1:
        the same density in every channel, so the hero ratios stay); two random draws."""
        out = path
        if sun_on:
            tr_sun = transmittance_to_sun(media, majorants, air, sun, p, out.state, 0)
            out.state = tr_sun.state
            out.steps = out.steps + tr_sun.steps
            out.shadow_steps = out.shadow_steps + tr_sun.steps
            phase = phase_hg(wp.dot(sun.direction, out.direction), g)
            out.radiance = out.radiance + wp.cw_mul(out.throughput, wp.cw_mul(sun.irradiance, tr_sun.value)) * phase
        state = out.state
        cos_theta = hg_sample_cos(g, wp.randf(state))
        out.direction = rotate_about(out.direction, cos_theta, 2.0 * wp.pi * wp.randf(state))
        out.state = state
        out.origin = p
        return out

    return fog_scatter_event


@wp.struct
class Sunlight:
    """The sunlight a scattering sends back along a path per unit throughput, the shadow ray's steps and the
    advanced random state."""

    value: wp.vec3
    steps: int
    state: wp.uint32


@wp.func
def direction_share(path: PathState, sun: Sun) -> float:
    """The share of the sunlight at a path's scattering event that its own direction carries: 1, or where the sun
    lobe (sun_lobe.py) also draws that direction at the previous event, the balance heuristic's
    ``lobe_pdf / (lobe_pdf + lobe density)``."""
    if path.lobe_pdf <= 0.0:
        return 1.0
    return path.lobe_pdf / (path.lobe_pdf + phase_hg(wp.dot(sun.direction, path.direction), path.lobe_g))


@functools.cache
def sunlight_function(has_tables: bool, has_detail: bool, has_fog: bool = False):
    """``event_sunlight(media, majorants, tables, air, sun, point, air_s, p, direction, state) -> Sunlight``:
    the sunlight a scattering at ``p`` (the media's ``point``, the air's ``air_s``) sends back along a path that
    arrived along ``direction``, per unit throughput: the sun's irradiance, its ratio-tracked transmittance and the
    mixture's phase (oriented ice's included), with the shadow ray's steps and the advanced state."""
    transmittance_to_sun = sun_transmittance_function(has_detail, has_fog)
    mixture_phase = mixture_functions(has_tables)[0]

    @wp.func
    def event_sunlight(media: VoxelMedia, majorants: Majorants, tables: PhaseTables, air: Air, sun: Sun,
                       point: MediaPoint, air_s: AirPart, p: wp.vec3, direction: wp.vec3,
                       state: wp.uint32) -> Sunlight:
        tr = transmittance_to_sun(media, majorants, air, sun, p, state, 0)
        out = Sunlight()
        out.steps = tr.steps
        out.state = tr.state
        theta = scattering_angle(sun.direction, direction)
        phase = mixture_phase(media, point, tables.values, air_s, theta)
        if wp.static(has_tables):  # oriented crystals are ice, a tabulated species: their sunlit phase
            phase += oriented_mixture_correction(media, point, tables.values, tables.oriented, air_s, direction,
                                                 theta)
        out.value = wp.cw_mul(phase, wp.cw_mul(sun.irradiance, tr.value))
        return out

    return event_sunlight


@functools.cache
def event_functions(has_tables: bool, has_detail: bool, has_fog: bool = False):
    """``(scatter_event, reduced_scatter_event, ground_event)``, specialised on tabulated species, animated detail
    and analytic fog."""
    sample_media = media_functions(has_detail)
    transmittance_to_sun = sun_transmittance_function(has_detail, has_fog)
    sample_mixture = mixture_functions(has_tables)[1]
    fog_scatter_event = fog_event_function(has_detail, has_fog)
    event_sunlight = sunlight_function(has_tables, has_detail, has_fog)

    @wp.func
    def scatter_event(media: VoxelMedia, majorants: Majorants, tables: PhaseTables, air: Air, sun: Sun,
                      sun_on: bool, path: PathState, p: wp.vec3, air_weight: float) -> PathState:
        """Scattering at ``p``: the sun through the media times the mixed phase, then a new direction sampled from
        the mixture (one media lookup serves both); the air's part of the mixture weighs ``air_weight`` (0: the
        media scatter alone, after :func:`media_first`)."""
        out = path
        point = sample_media(media, p)
        air_s = scaled_part(air_part(air, p), air_weight)
        if wp.static(has_fog):
            pick = pick_fog(majorants.fog, p, point.scattering + part_total(air_s), out.state)
            out.state = pick.state
            out.throughput = wp.cw_mul(out.throughput, pick.weight)
            if pick.body >= 0:
                return fog_scatter_event(media, majorants, air, sun, sun_on, out, p, pick.g)
        if sun_on:
            light = event_sunlight(media, majorants, tables, air, sun, point, air_s, p, out.direction, out.state)
            out.state = light.state
            out.steps = out.steps + light.steps
            out.shadow_steps = out.shadow_steps + light.steps
            out.radiance = out.radiance + wp.cw_mul(out.throughput, light.value) * direction_share(out, sun)
        ps = sample_mixture(media, point, tables, air_s, out.direction, out.hero, out.ratio, out.state)
        out.state = ps.state
        out.ratio = ps.ratio
        out.throughput = wp.cw_mul(out.throughput, ps.weight)
        out.direction = ps.direction
        out.origin = p
        out.lobe_pdf = 0.0
        if out.lobe_g != NO_LOBE:
            out.lobe_pdf = ps.density
        return out

    @wp.func
    def ground_event(media: VoxelMedia, majorants: Majorants, air: Air, sun: Sun, ground: Ground, sun_on: bool,
                     path: PathState, p: wp.vec3, reduced: int) -> PathState:
        """Lambertian ground under ``p`` (on a round earth its floor, the local vertical its normal): the sun
        through the media (with ``reduced``, after high-order similarity), then a cosine-weighted bounce."""
        out = path
        if ground.enabled != 0:
            q = ground_point(air, ground, p)
            if sun_on:
                tr_sun = transmittance_to_sun(media, majorants, air, sun, q, out.state, reduced)
                out.state = tr_sun.state
                out.steps = out.steps + tr_sun.steps
                out.shadow_steps = out.shadow_steps + tr_sun.steps
                lit_ground = wp.cw_mul(sun.irradiance, tr_sun.value)
                out.radiance = out.radiance + wp.cw_mul(wp.cw_mul(out.throughput, ground.albedo), lit_ground) * (
                    ground_cosine(air, sun, q) / wp.pi
                )
            out.throughput = wp.cw_mul(out.throughput, ground.albedo)
            if air.round != 0:
                normal = vertical(air, q)
                bounce = cosine_about(normal, out.state)
                out.direction = bounce.direction
                out.state = bounce.state
                out.origin = q + normal * 1.0e-4
            else:
                bounce = cosine_up(out.state)
                out.direction = bounce.direction
                out.state = bounce.state
                out.origin = q + wp.vec3(0.0, 1.0e-4, 0.0)
        return out

    return scatter_event, reduced_event_function(has_detail, has_fog), ground_event
