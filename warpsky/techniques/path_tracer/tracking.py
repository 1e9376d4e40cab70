"""Free flights and transmittance of the path tracer: delta tracking and ratio tracking against local majorants.

Both walk the same sequence of tentative collisions (:func:`next_collision`): a ray advances through majorant
segments (:mod:`~warpsky.techniques.path_tracer.majorants`), drawing exponential steps at the segment's majorant
and restarting at each segment end. Delta tracking decides at each collision whether to scatter; ratio tracking
multiplies the transmittance by the null-collision probability.

RGB: one path carries three channels. Tentative collisions come at the majorant rate; a collision scatters with
probability P = Σ_c w_c σ_t,c / (μ̄ Σ_c w_c), w the path's throughput (history-aware spectral tracking, Kutz et al.
2017), and is null otherwise; each channel's weight is multiplied by its own probability over the one used
(σ_s,c / (μ̄ P) for scattering, (μ̄ - σ_t,c) / (μ̄ (1 - P)) for null collisions). This is unbiased for every
channel, keeps the sum of the weights on null collisions (no blow-up in chromatic air), and is exactly 1 for grey
media.

High-order similarity (Zhao, Wu, Ramamoorthi and Bala 2014): once a path has scattered ``similarity_order`` times,
its flights and its shadow rays run through the media after the order-1 similarity transform, sigma_s* =
sigma_s (1 - g) with an isotropic phase and sigma_t* = sigma_a + sigma_s*, g the phase's mean cosine (the air,
Rayleigh, keeps its own coefficients): ``reduced`` 1 selects those coefficients and their majorants. Light scattered
that often has lost most of its angular structure, so the transform changes it little while cutting the collisions
of a forward-scattering medium by 1 / (1 - g) (6.7 for g = 0.85).

Positions are camera-relative metres (float32-safe far from the origin, as in :mod:`warpsky.media.voxels.voxel`).
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.media.air.medium import Air, air_coefficient, air_scattering
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia, media_functions
from warpsky.techniques.path_tracer.fog_media import fog_coefficients, fog_segment
from warpsky.techniques.path_tracer.majorants import Majorants, majorant_segment

#: Ratio tracking plays Russian roulette once its largest channel falls below this (on the storm, 1e-3 with survival
#: 1/2 left shadow rays 30 tentative collisions long on average).
ROULETTE_TRANSMITTANCE = wp.constant(0.1)
#: Hard cap on tentative collisions per tracking call (guards against non-progress; counted in the stats).
MAX_TRACKING_STEPS = wp.constant(1000000)


@wp.struct
class PointMedia:
    """Summed coefficients of the air and all media at a point [1/m]."""

    extinction: wp.vec3
    scattering: wp.vec3


@wp.func
def with_air(media: VoxelMedia, point: MediaPoint, air: Air, p: wp.vec3) -> PointMedia:
    """Coefficients of the air at the camera-relative point ``p`` plus the media at ``point``, summed air first and
    then each medium in order (the order fixes the float32 rounding every tracking decision sees)."""
    out = PointMedia()
    out.extinction = point.extinction
    out.scattering = point.scattering
    if air.enabled != 0:
        coefficient = air_coefficient(air, p)
        scattering = coefficient
        if air.mixed != 0:
            scattering = air_scattering(air, p)
        if media.count <= 1:
            # one medium: air + (0 + x) is the same float sum as (air + x)
            out.extinction = coefficient + point.extinction
            out.scattering = scattering + point.scattering
        else:
            out = media_sums(media, point, coefficient, scattering, 0)
    return out


@wp.func
def media_sums(media: VoxelMedia, point: MediaPoint, start: wp.vec3, start_scattering: wp.vec3,
               reduced: int) -> PointMedia:
    """``start`` and ``start_scattering`` (the air's extinction and scattering, or zeros) plus each medium's
    extinction and scattering at the densities of
    ``point``, in medium order; with ``reduced`` their coefficients after high-order similarity. ``media`` may
    hold other coefficients for the same fields than the ones ``point`` was sampled from (the cut media)."""
    out = PointMedia()
    out.extinction = start
    out.scattering = start_scattering
    for m in range(media.count):
        value = point.density[m]
        if value > 0.0:
            grid = media.grids[m]
            if reduced != 0:
                out.extinction += grid.reduced_extinction * value
                out.scattering += grid.reduced_scattering * value
            else:
                out.extinction += grid.extinction * value
                out.scattering += grid.scattering * value
    return out


@wp.func
def reduced_with_air(media: VoxelMedia, point: MediaPoint, air: Air, p: wp.vec3) -> PointMedia:
    """:func:`with_air` after high-order similarity: the media's reduced extinction and scattering at ``point``
    (the air's are unchanged)."""
    start = wp.vec3(0.0)
    scattering = wp.vec3(0.0)
    if air.enabled != 0:
        start = air_coefficient(air, p)
        scattering = air_scattering(air, p)
    return media_sums(media, point, start, scattering, 1)


@wp.struct
class Collision:
    """Where :func:`next_collision` stopped: a tentative collision (``found`` 1) or the end of the ray."""

    t: float  # distance along the ray [m]
    majorant: float  # the majorant the collision was drawn with [1/m]
    found: int
    steps: int  # tentative collisions and segment crossings so far
    state: wp.uint32


@functools.cache
def collision_function(has_fog: bool):
    """``next_collision(media, majorants, air, origin, direction, t_start, t_max, steps_start, state, reduced) ->
    Collision``, specialised on analytic fog (inside a fog's slab its majorant joins the media's and the air's, and
    the slab's faces end majorant segments: :func:`~warpsky.techniques.path_tracer.fog_media.fog_segment`)."""

    @wp.func
    def next_collision(media: VoxelMedia, majorants: Majorants, air: Air, origin: wp.vec3, direction: wp.vec3,
                       t_start: float, t_max: float, steps_start: int, state: wp.uint32, reduced: int) -> Collision:
        """The next tentative collision after ``t_start`` (one random draw per exponential step), or ``t_max``;
        with ``reduced`` against the majorants after high-order similarity."""
        t = float(t_start)
        steps = int(steps_start)
        found = int(0)
        majorant = float(0.0)
        while t < t_max and steps < MAX_TRACKING_STEPS:
            seg = majorant_segment(media, majorants, air, origin, direction, t, t_max, reduced)
            if wp.static(has_fog):
                fog = fog_segment(majorants.fog, origin, direction, t, reduced)
                seg.majorant = seg.majorant + fog[0]
                seg.end = wp.min(seg.end, fog[1])
            if seg.majorant <= 0.0:
                if seg.end >= t_max:
                    break
                t = wp.max(seg.end, t)
                steps += 1
                continue
            step = -wp.log(1.0 - wp.randf(state)) / seg.majorant
            steps += 1
            if t + step >= seg.end:
                t = seg.end
                continue
            t = t + step
            found = 1
            majorant = seg.majorant
            break
        out = Collision()
        out.t = t
        out.majorant = majorant
        out.found = found
        out.steps = steps
        out.state = state
        return out

    return next_collision


#: The tentative collisions of media and air (no fog).
next_collision = collision_function(False)


@wp.struct
class Flight:
    """Result of a free flight: where it ended, whether it scattered there, per-channel weight, cost."""

    t: float
    scattered: int
    weight: wp.vec3
    steps: int
    state: wp.uint32


@wp.struct
class Transmittance:
    """A ratio-tracking estimate per channel, its tentative collisions, and the advanced random state."""

    value: wp.vec3
    steps: int
    state: wp.uint32


@wp.func
def positive(v: wp.vec3) -> wp.vec3:
    return wp.vec3(wp.max(v[0], 0.0), wp.max(v[1], 0.0), wp.max(v[2], 0.0))


def tracking_functions(has_detail: bool, has_fog: bool = False):
    """``(media_at, delta_track, ratio_track)``, specialised on animated detail: with it every density lookup is
    multiplied by the medium's detail factor (the majorant grids are scaled by its bound on the host); with
    ``has_fog`` the free flights track the analytic fogs too (ratio tracking never does: their transmittance is
    closed-form, :mod:`~warpsky.techniques.path_tracer.fog_media`)."""
    return (media_at_function(has_detail), delta_track_function(has_detail, has_fog),
            ratio_track_function(has_detail))


@functools.cache
def media_at_function(has_detail: bool):
    """``media_at(media, air, p, reduced) -> PointMedia`` (see :func:`tracking_functions`)."""
    sample_media = media_functions(has_detail)

    @wp.func
    def media_at(media: VoxelMedia, air: Air, p: wp.vec3, reduced: int) -> PointMedia:
        """Summed extinction and scattering of the air and all media at the camera-relative point ``p`` (with
        ``reduced``, after high-order similarity)."""
        point = sample_media(media, p)
        if reduced != 0:
            return reduced_with_air(media, point, air, p)
        return with_air(media, point, air, p)

    return media_at


@functools.cache
def delta_track_function(has_detail: bool, has_fog: bool = False):
    """``delta_track(media, majorants, air, origin, direction, t_max, history, state, reduced) -> Flight`` (see
    :func:`tracking_functions`)."""
    media_at = media_at_function(has_detail)
    collide = collision_function(has_fog)

    @wp.func
    def delta_track(media: VoxelMedia, majorants: Majorants, air: Air, origin: wp.vec3, direction: wp.vec3,
                    t_max: float, history: wp.vec3, state: wp.uint32, reduced: int) -> Flight:
        """Weighted delta tracking from ``origin`` along ``direction`` up to ``t_max`` (see the module docstring);
        one random draw per collision after those of :func:`next_collision`."""
        out = Flight()
        out.scattered = 0
        weight = wp.vec3(1.0)
        t = float(0.0)
        steps = int(0)
        found = int(1)
        while found != 0:
            hit = collide(media, majorants, air, origin, direction, t, t_max, steps, state, reduced)
            t = hit.t
            steps = hit.steps
            state = hit.state
            found = hit.found
            if found != 0:
                point = media_at(media, air, origin + t * direction, reduced)
                if wp.static(has_fog):
                    fog = fog_coefficients(majorants.fog, origin + t * direction, reduced)
                    point.extinction = point.extinction + fog.extinction
                    point.scattering = point.scattering + fog.scattering
                # history-aware spectral tracking (Kutz et al. 2017): scatter with the throughput-weighted
                # probability, so the channels' weights keep their sum on null collisions and cannot blow up
                hw = wp.cw_mul(history, weight)
                total = hw[0] + hw[1] + hw[2]
                p_scatter = float(0.0)
                if total > 0.0:
                    p_scatter = wp.clamp(wp.dot(hw, point.extinction) / (total * hit.majorant), 0.0, 1.0)
                if wp.randf(state) < p_scatter:
                    out.t = t
                    out.scattered = 1
                    out.weight = wp.cw_mul(weight, point.scattering) / (hit.majorant * p_scatter)
                    out.steps = steps
                    out.state = state
                    return out
                null = positive(hit.majorant * wp.vec3(1.0) - point.extinction)
                weight = wp.cw_mul(weight, null) / (hit.majorant * (1.0 - p_scatter))
        out.t = t_max
        out.weight = weight
        out.steps = steps
        out.state = state
        return out

    return delta_track


@functools.cache
def ratio_track_function(has_detail: bool):
    """``ratio_track(media, majorants, air, origin, direction, t_max, state, reduced) -> Transmittance`` (see
    :func:`tracking_functions`)."""
    media_at = media_at_function(has_detail)

    @wp.func
    def ratio_track(media: VoxelMedia, majorants: Majorants, air: Air, origin: wp.vec3, direction: wp.vec3,
                    t_max: float, state: wp.uint32, reduced: int) -> Transmittance:
        """Unbiased transmittance estimate per channel along the segment (ratio tracking); a random draw for
        Russian roulette once the estimate falls below ROULETTE_TRANSMITTANCE."""
        tr = wp.vec3(1.0)
        t = float(0.0)
        steps = int(0)
        found = int(1)
        while found != 0:
            hit = next_collision(media, majorants, air, origin, direction, t, t_max, steps, state, reduced)
            t = hit.t
            steps = hit.steps
            state = hit.state
            found = hit.found
            if found != 0:
                point = media_at(media, air, origin + t * direction, reduced)
                tr = wp.cw_mul(tr, positive(wp.vec3(1.0) - point.extinction / hit.majorant))
                largest = wp.max(tr)
                if largest < ROULETTE_TRANSMITTANCE:
                    # Russian roulette once the estimate is small: it survives with probability
                    # largest / ROULETTE_TRANSMITTANCE and is divided by it, so the estimate stays unbiased and
                    # a ray into an opaque cloud ends after a few collisions
                    q = largest / ROULETTE_TRANSMITTANCE
                    if wp.randf(state) >= q:
                        tr = wp.vec3(0.0)
                        break
                    tr = tr / q
        out = Transmittance()
        out.value = tr
        out.steps = steps
        out.state = state
        return out

    return ratio_track
