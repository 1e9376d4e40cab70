"""Kernels of the height-field cloud pass (Max 1986): one thread per pixel marches its ray front to back.

The ray is cut where it enters and leaves the haze slab; within each part the pieces of cloud come from the deck's
interval search (:func:`~warpsky.media.deck.deck_geometry.hf_next_interval`), so the ray runs through a sequence of
pieces of constant extinction: clear haze, cloud, or cloud inside haze. Each piece is integrated in equal steps. Along
the view ray the optical depth is then exactly linear; the optical depth towards the sun is found at the step's ends
(cloud: the exact length of the sun ray inside the deck, or in ``max`` mode Max's thickness rule
:func:`deck_shadow_length`; haze: its closed-form path to the slab's top). In cloud it is taken as linear between them,
and the step's exp(-(tau_view + tau_sun)) is integrated in closed form (:func:`~warpsky.core.numerics.exp_lerp_mean3`),
which keeps any optical depth per step finite. In clear haze the deck's part of the sun's optical depth is not smooth:
it jumps where the step crosses the edge of a cloud's shadow (a shaft), and the exp-lerp mean of a jump is the
logarithmic mean of the two ends' transmittances, always below their average, which is what a step crossing an edge at
an unknown place gives on average. There the view's and the haze's own parts keep their closed form and the deck's
transmittance towards the sun is averaged over the step's ends (trapezoid): on a deck of the scenery family's tune
half the exp-lerp march at the automatic haze step was 3.2 % too dark against a march of 64 steps per feature
(relative RMSE 4.5 %), the trapezoid 0.2 % (2.5 %), and halving the exp-lerp step only halved its bias.

Sources per metre: sigma_s p(theta) E_sun exp(-tau_sun) from the sun (cloud and haze, each with its own
Henyey-Greenstein phase) and sigma_s L_mean exp(-tau_zenith) from the sky's ambient light L_mean
(:func:`~warpsky.light.dome.ambient_radiance`): isotropic, occluded by the cloud and haze straight above the
point (closed forms: the deck is a height field, so the vertical ray from a point meets the cloud of its own
column only). Light scattered more than once and the sky's direction-dependence are left out.

``sexp`` mode (Max §3-4): inside a cloud piece [a, b] the in-scattered sunlight is
integral sigma_s p E sexp(-sigma (t - a)) sexp(-sigma L_col / mu_s) dt with sexp(x) = 0.25 max(x + 2, 0)^2, L_col
the cloud above the point in its own column and mu_s the sine of the sun's elevation (Max's vertical-sun model,
exact for an overhead sun), taken by the midpoint rule in the piece's steps; the transmittance stays exact, as
in Max's algorithm.
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import exp3, exp_lerp_mean3, luminance
from warpsky.light.sun import Sun
from warpsky.media.deck.deck_geometry import (
    HazeSlab,
    HeightField,
    haze_above,
    haze_path,
    hf_bottom,
    hf_column_above,
    hf_f,
    hf_next_interval,
    hf_optical_depth,
    hf_ray_slope,
    hf_top,
)
from warpsky.media.voxels.voxel import slab_interval
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.optics.phase import phase_hg
from warpsky.passes.deck.shadow_map import (
    MIN_SUN_SINE,
    DeckShadowMap,
    deck_sun_transmittance_at,
    map_mark,
    map_point,
    map_texel,
)


@wp.struct
class DeckMarch:
    """Step lengths, mode and ambient light of the march."""

    cloud_step: float  # step inside cloud pieces [m]
    haze_step: float  # shortest step in clear haze [m]
    haze_feature: float  # shortest horizontal feature of the deck's shadow pattern / steps per feature [m]
    haze_step_max: float  # longest step in clear haze, 0.25 / sigma_haze [m]
    shadow: int  # 0: exact optical depth along the sun ray; 1: Max's thickness rule (:func:`deck_shadow_length`)
    max_steps: int  # most steps per piece (a longer piece takes longer steps)
    min_transmittance: float  # stop once the luminance transmittance falls below this
    ambient: wp.vec3  # L_mean, RGB [radiance]
    ambient_on: int
    sexp: int  # 1: Max's quadratic sexp in the cloud integral
    has_limit: int  # 1: ``limit`` holds the depth of an opaque surface per pixel


@wp.struct
class MarchState:
    """What a pixel's march has gathered so far."""

    light: wp.vec3  # radiance towards the eye
    tau: wp.vec3  # optical depth from the eye
    depth_sum: float  # opacity-weighted depth
    weight_sum: float  # opacity
    done: int  # 1 once the view is opaque


@wp.func
def sexp3(x: wp.vec3) -> wp.vec3:
    """Max's sexp(x) = 0.25 max(x + 2, 0)^2 per channel (the exp of x <= 0 to first order, 0 below -2)."""
    a = wp.max(x[0] + 2.0, 0.0)
    b = wp.max(x[1] + 2.0, 0.0)
    c = wp.max(x[2] + 2.0, 0.0)
    return wp.vec3(0.25 * a * a, 0.25 * b * b, 0.25 * c * c)


@wp.func
def deck_shadow_length(hf: HeightField, p: wp.vec3, sun_dir: wp.vec3) -> float:
    """Cloud length [m] the sunlight crosses to reach ``p`` by Max's thickness rule (§6), on a slant: the cloud
    above the height of ``p`` in the column Q where the ray towards the sun pierces the mean plane (Q = p above the
    plane: his vertical-sun model, §3), g(Q) - max(y - H, h(Q)), over the sine of the sun's elevation (a locally
    flat slab crossed at that elevation). One evaluation of the pattern; exact for an overhead sun."""
    yr = p[1] - hf.mean
    q = p
    if yr < 0.0:
        q = p + sun_dir * (-yr / sun_dir[1])
    f = hf_f(hf, q)
    if f <= 0.0:
        return 0.0
    return wp.max(hf_top(hf, f) - wp.max(yr, hf_bottom(hf, f)), 0.0) / sun_dir[1]


@wp.func
def sun_depth(hf: HeightField, haze: HazeSlab, p: wp.vec3, sun_dir: wp.vec3, shadow: int) -> wp.vec3:
    """Optical depth (RGB) from ``p`` to the sun: the deck's (exact along the sun ray, or by Max's thickness rule
    with ``shadow`` 1 while the sun is above the horizon) plus the haze slab's closed form."""
    tau = haze.extinction * haze_path(haze, p, sun_dir)
    if shadow != 0 and sun_dir[1] > 1.0e-6:
        return tau + hf.extinction * deck_shadow_length(hf, p, sun_dir)
    return tau + hf_optical_depth(hf, p, sun_dir, 0.0, hf.max_length)


@wp.func
def haze_rate(view: wp.vec3, sun_dir: wp.vec3) -> float:
    """How fast [m/m] the point where the ray towards the sun meets a horizontal plane moves along ``view``:
    |view_xz - (view_y / sun_y) sun_xz| (|view_xz| with the sun on or below the horizon)."""
    rate = wp.sqrt(view[0] * view[0] + view[2] * view[2])
    if sun_dir[1] > 1.0e-6:
        k = view[1] / sun_dir[1]
        dx = view[0] - k * sun_dir[0]
        dz = view[2] - k * sun_dir[2]
        rate = wp.sqrt(dx * dx + dz * dz)
    return rate


@wp.func
def haze_step_along(march: DeckMarch, view: wp.vec3, sun_dir: wp.vec3) -> float:
    """Step [m] of clear haze along ``view``: the shadow pattern seen along the ray changes as fast as the point
    where the ray towards the sun meets a horizontal plane moves, |view_xz - (view_y / sun_y) sun_xz| per metre, so
    a feature of the shadow gets ``haze_steps_per_feature`` steps (``haze_feature`` is the feature over that
    count); never below ``haze_step``, nor above ``haze_step_max`` (a
    quarter of the haze's mean free path: the sky light's occlusion is taken at the step's middle)."""
    step = wp.max(march.haze_step, march.haze_feature / wp.max(haze_rate(view, sun_dir), 1.0e-6))
    return wp.min(step, wp.max(march.haze_step_max, march.haze_step))


@wp.func
def zenith_depth(hf: HeightField, haze: HazeSlab, p: wp.vec3) -> wp.vec3:
    """Optical depth (RGB) straight up from ``p``: the cloud of its own column and the haze above it."""
    return hf.extinction * hf_column_above(hf, p) + haze.extinction * haze_above(haze, p)


@wp.func
def record_opacity(state: MarchState, tau_b: wp.vec3, depth: float, min_transmittance: float) -> MarchState:
    """Add the opacity of a step ending at optical depth ``tau_b`` at ``depth`` [m] to the depth average."""
    out = state
    opacity = luminance(exp3(state.tau)) - luminance(exp3(tau_b))
    out.depth_sum = state.depth_sum + opacity * depth
    out.weight_sum = state.weight_sum + opacity
    out.tau = tau_b
    if luminance(exp3(tau_b)) < min_transmittance:
        out.done = 1
    return out


@wp.func
def march_piece(hf: HeightField, haze: HazeSlab, sun: Sun, march: DeckMarch, state: MarchState,
                o: wp.vec3, view: wp.vec3, a: float, b: float, cloud_on: float, haze_on: float,
                cos_axis: float) -> MarchState:
    """Integrate the piece [a, b] of the view ray, of constant extinction (cloud if ``cloud_on``, haze if
    ``haze_on``), front to back from ``state``."""
    out = state
    step = haze_step_along(march, view, sun.direction)
    if cloud_on > 0.0:
        step = march.cloud_step
    count = wp.min(wp.max(int(wp.ceil((b - a) / step)), 1), march.max_steps)
    dt = (b - a) / float(count)
    cos_theta = wp.dot(sun.direction, view)
    sigma_t = hf.extinction * cloud_on + haze.extinction * haze_on
    sigma_amb = hf.scattering * cloud_on + haze.scattering * haze_on
    sigma_cloud = hf.scattering * (cloud_on * phase_hg(cos_theta, hf.g))
    sigma_haze = haze.scattering * (haze_on * phase_hg(cos_theta, haze.g))
    sunlit = sun.lit != 0 and wp.max(sigma_cloud + sigma_haze) > 0.0
    use_sexp = march.sexp != 0 and cloud_on > 0.0
    tau_start = state.tau
    tau_sun_a = wp.vec3(0.0)
    haze_sun_a = wp.vec3(0.0)
    # node j = 0 .. count at a + j dt: the sun's optical depth at each node (one call site: it inlines the whole
    # interval search), step j - 1 integrated once both its ends are known
    for j in range(count + 1):
        tau_sun_b = wp.vec3(0.0)
        haze_sun_b = wp.vec3(0.0)
        if sunlit and not use_sexp:
            node = o + (a + float(j) * dt) * view
            tau_sun_b = sun_depth(hf, haze, node, sun.direction, march.shadow)
            haze_sun_b = haze.extinction * haze_path(haze, node, sun.direction)
        if j == 0:
            tau_sun_a = tau_sun_b
            haze_sun_a = haze_sun_b
            continue
        ta = a + float(j - 1) * dt
        tm = ta + 0.5 * dt
        tau_b = out.tau + sigma_t * dt
        if sunlit and not use_sexp:
            mean = exp_lerp_mean3(out.tau + tau_sun_a, tau_b + tau_sun_b)
            if cloud_on == 0.0:  # clear haze: the deck's part of the sun's depth jumps at the shafts' edges
                deck_a = tau_sun_a - haze_sun_a
                deck_b = tau_sun_b - haze_sun_b
                mean = wp.cw_mul(exp_lerp_mean3(out.tau + haze_sun_a, tau_b + haze_sun_b),
                                 0.5 * (exp3(deck_a) + exp3(deck_b)))
            out.light += wp.cw_mul(wp.cw_mul(sigma_cloud + sigma_haze, sun.irradiance), mean) * dt
            tau_sun_a = tau_sun_b
            haze_sun_a = haze_sun_b
        if sunlit and use_sexp and sun.direction[1] > 0.0:
            p = o + tm * view
            column = hf_column_above(hf, p) / sun.direction[1]
            haze_sun = haze.extinction * haze_path(haze, p, sun.direction)
            factor = wp.cw_mul(sexp3(-sigma_t * (tm - a)), sexp3(-hf.extinction * column))
            factor = wp.cw_mul(factor, exp3(tau_start + haze_sun))
            out.light += wp.cw_mul(wp.cw_mul(sigma_cloud + sigma_haze, sun.irradiance), factor) * dt
        if march.ambient_on != 0:
            occlusion = exp3(zenith_depth(hf, haze, o + tm * view))
            source = wp.cw_mul(wp.cw_mul(sigma_amb, march.ambient), occlusion)
            out.light += wp.cw_mul(source, exp_lerp_mean3(out.tau, tau_b)) * dt
        out = record_opacity(out, tau_b, tm * cos_axis, march.min_transmittance)
        if out.done != 0:
            break
    return out


@wp.func
def mapped_step(march: DeckMarch, smap: DeckShadowMap, sun_dir: wp.vec3, o: wp.vec3, view: wp.vec3, t: float,
                a: float, b: float) -> float:
    """The step [m] from ``t`` of the mapped clear-haze march over [a, b]: one texel of the map's level there, never
    shorter than :func:`haze_step_along`'s nor longer than the haze's bound, nor shorter than a ``max_steps``-th of
    the piece; the rest of the piece where less than 1.25 steps are left (no sliver)."""
    rate = wp.max(haze_rate(view, sun_dir), 1.0e-6)
    texel = map_texel(smap, map_point(smap, o + t * view, sun_dir))
    dt = wp.max(wp.max(haze_step_along(march, view, sun_dir), texel / rate), (b - a) / float(march.max_steps))
    dt = wp.min(dt, wp.max(march.haze_step_max, march.haze_step))
    if b - t < 1.25 * dt:
        dt = b - t
    return dt


@wp.func
def march_haze_mapped(hf: HeightField, haze: HazeSlab, sun: Sun, march: DeckMarch, smap: DeckShadowMap,
                      state: MarchState, o: wp.vec3, view: wp.vec3, a: float, b: float, cos_axis: float
                      ) -> MarchState:
    """Integrate the clear-haze piece [a, b] front to back with the deck's transmittance towards the sun read from
    the shadow map (:mod:`~warpsky.passes.deck.shadow_map`): one step per texel of the level in use, never shorter
    than :func:`haze_step_along`'s nor longer than the haze's bound; sources and quadrature as in
    :func:`march_piece`'s clear haze (the deck's transmittance averaged over the step's ends)."""
    out = state
    sigma_haze = haze.scattering * phase_hg(wp.dot(sun.direction, view), haze.g)
    sunlit = sun.lit != 0 and wp.max(sigma_haze) > 0.0
    deck_a = wp.vec3(1.0)
    haze_a = wp.vec3(0.0)
    if sunlit:
        deck_a = deck_sun_transmittance_at(hf, smap, o + a * view, sun.direction)
        haze_a = haze.extinction * haze_path(haze, o + a * view, sun.direction)
    t = a
    while t < b and out.done == 0:
        dt = mapped_step(march, smap, sun.direction, o, view, t, a, b)
        tau_b = out.tau + haze.extinction * dt
        if sunlit:
            p = o + (t + dt) * view
            deck_b = deck_sun_transmittance_at(hf, smap, p, sun.direction)
            haze_b = haze.extinction * haze_path(haze, p, sun.direction)
            mean = wp.cw_mul(exp_lerp_mean3(out.tau + haze_a, tau_b + haze_b), 0.5 * (deck_a + deck_b))
            out.light += wp.cw_mul(wp.cw_mul(sigma_haze, sun.irradiance), mean) * dt
            deck_a = deck_b
            haze_a = haze_b
        tm = t + 0.5 * dt
        if march.ambient_on != 0:
            occlusion = exp3(zenith_depth(hf, haze, o + tm * view))
            source = wp.cw_mul(wp.cw_mul(haze.scattering, march.ambient), occlusion)
            out.light += wp.cw_mul(source, exp_lerp_mean3(out.tau, tau_b)) * dt
        out = record_opacity(out, tau_b, tm * cos_axis, march.min_transmittance)
        t = t + dt
    return out


@wp.func
def march_segment(hf: HeightField, haze: HazeSlab, sun: Sun, march: DeckMarch, smap: DeckShadowMap,
                  state: MarchState, o: wp.vec3, view: wp.vec3, a: float, b: float, in_haze: float,
                  cos_axis: float) -> MarchState:
    """March [a, b], which lies wholly inside (``in_haze`` 1) or outside the haze slab: its clear gaps (haze
    only; read from the shadow map where it is on) and its pieces of cloud in order."""
    out = state
    mapped = smap.on != 0 and march.shadow == 0 and march.sexp == 0 and sun.direction[1] > MIN_SUN_SINE
    slope = hf_ray_slope(hf, view)
    t = a
    while t < b and out.done == 0:
        piece = hf_next_interval(hf, o, view, slope, t, b)
        for k in range(2):  # the clear gap before the piece (haze only), then the piece; one call site
            lo = t
            hi = piece[0]
            cloud = 0.0
            if k == 1:
                lo = piece[0]
                hi = piece[1]
                cloud = 1.0
            run = (k == 0 and in_haze > 0.0 and hi > lo) or (k == 1 and piece[0] < b)
            if run and out.done == 0:
                if k == 0 and mapped:
                    out = march_haze_mapped(hf, haze, sun, march, smap, out, o, view, lo, hi, cos_axis)
                else:
                    out = march_piece(hf, haze, sun, march, out, o, view, lo, hi, cloud, in_haze, cos_axis)
        if piece[0] >= b:
            break
        t = wp.max(piece[1], piece[0] + hf.tolerance)
    return out


@wp.kernel
def deck_kernel(
    hf: HeightField,
    haze: HazeSlab,
    cam: PinholeCamera,
    sun: Sun,
    march: DeckMarch,
    smap: DeckShadowMap,
    limit: wp.array2d(dtype=float),
    radiance: wp.array2d(dtype=wp.vec3),
    transmittance: wp.array2d(dtype=wp.vec3),
    depth: wp.array2d(dtype=float),
    row_offset: int,
):
    r, col = wp.tid()
    row = r + row_offset
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    view = ray.direction
    o = ray.origin
    t_near = ray.t_near
    t_end = ray.t_far
    if march.has_limit != 0:
        t_end = wp.min(t_end, limit[row, col] / ray.cos_axis)
    state = MarchState()
    state.light = wp.vec3(0.0)
    state.tau = wp.vec3(0.0)
    state.depth_sum = 0.0
    state.weight_sum = 0.0
    state.done = 0
    if t_end > t_near:
        span = wp.vec2(t_end, t_end)
        if haze.present != 0:
            span = slab_interval(o[1], view[1], haze.floor, haze.top, t_near, t_end)
        if span[0] >= span[1]:
            span = wp.vec2(t_end, t_end)
        # before, inside and after the haze slab, through one call site (each inlines the whole march)
        cuts = wp.vec4(t_near, span[0], span[1], t_end)
        for k in range(3):
            if state.done == 0 and cuts[k + 1] > cuts[k]:
                in_haze = wp.where(k == 1, 1.0, 0.0)
                state = march_segment(hf, haze, sun, march, smap, state, o, view, cuts[k], cuts[k + 1],
                                      in_haze, ray.cos_axis)
    radiance[row, col] = state.light
    transmittance[row, col] = exp3(state.tau)
    if state.weight_sum > 1.0e-6:
        depth[row, col] = state.depth_sum / state.weight_sum
    else:
        depth[row, col] = cam.far


@wp.kernel
def mark_kernel(haze: HazeSlab, cam: PinholeCamera, sun: Sun, march: DeckMarch, smap: DeckShadowMap,
                limit: wp.array2d(dtype=float), row_offset: int):
    """Mark the map's texels the pixel's mapped clear-haze march will read: its nodes where the march is mapped
    (the haze slab below the map's plane; the deck's pieces above it are not mapped)."""
    r, col = wp.tid()
    row = r + row_offset
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    t_end = ray.t_far
    if march.has_limit != 0:
        t_end = wp.min(t_end, limit[row, col] / ray.cos_axis)
    span = slab_interval(ray.origin[1], ray.direction[1], haze.floor, haze.top, ray.t_near, t_end)
    t = span[0]
    if t < span[1]:
        map_mark(smap, map_point(smap, ray.origin + t * ray.direction, sun.direction))
    while t < span[1]:
        t = t + mapped_step(march, smap, sun.direction, ray.origin, ray.direction, t, span[0], span[1])
        map_mark(smap, map_point(smap, ray.origin + t * ray.direction, sun.direction))


@wp.kernel
def sun_transmittance_kernel(
    hf: HeightField,
    haze: HazeSlab,
    sun_dir: wp.vec3,
    points: wp.array(dtype=wp.vec3),
    exact: int,
    smap: DeckShadowMap,
    out: wp.array(dtype=wp.vec3),
):
    """Transmittance (RGB) of the sunlight reaching camera-relative ``points``: Max's thickness rule
    (:func:`deck_shadow_length`), or with ``exact`` the exact sun-ray optical depth (read from the frame's shadow
    map where it holds the point); times the haze's along the sun ray."""
    i = wp.tid()
    p = points[i]
    if exact != 0:
        haze_depth = haze.extinction * haze_path(haze, p, sun_dir)
        out[i] = wp.cw_mul(deck_sun_transmittance_at(hf, smap, p, sun_dir), exp3(haze_depth))
    else:
        out[i] = exp3(sun_depth(hf, haze, p, sun_dir, 1))
