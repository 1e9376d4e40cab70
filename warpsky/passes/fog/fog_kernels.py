"""Kernels of the analytic fog pass: one thread per pixel, transmittance in closed form, single scattering by
Gauss-Legendre quadrature with closed-form optical depths at every node.

Along the view ray x(t) = o + t w (eye-relative, float64) the pass computes

    T = exp(-tau(t0, t1))                                                (closed form, exact: Biri's f)
    L_sun = E_sun * int sigma_s(t) p(theta) T(t0, t) T_sun(t) dt          (quadrature)
    L_sky = L_ambient * (1 - T) * [int sum_f a_f sigma_f T dt / int sum_f sigma_f T dt]

with T_sun(t) the closed-form transmittance from x(t) up to the highest slab top along the sun direction. The sky
term is the in-scattering of an isotropic, unshadowed ambient radiance, whose integral int sigma_s T dt equals
a (1 - T) exactly for one albedo a; the bracket, a quadrature ratio, only weighs the albedos of several fogs.

The quadrature runs from where the ray enters the first slab to where it leaves the last, or to where the optical
depth of its clearest channel reaches ``cut_depth`` (found by bisection on the closed form; what lies beyond is
dimmed by exp(-cut_depth)). That span is split into pieces as long as the shortest feature of the density along
that ray (:func:`ray_feature`: a cosine's wavelength projected on the ray, ...; between ``min_pieces`` and
``max_pieces`` of them) and also at every discontinuity of the density: slab faces,
the ends of bounded polynomials and the cells of repeated ones. Each piece gets ``nodes`` Gauss-Legendre nodes.
"""

from __future__ import annotations

import math

import warp as wp

from warpsky.media.fog import FogSet, fog_density, fogs_optical_depth, slabs_exit_length
from warpsky.media.stratiform.stratiform_shadow import LayerShadows, layers_sun_transmittance
from warpsky.model.camera_rays import PinholeCamera, camera_forward, primary_ray
from warpsky.surfaces.mesh import SurfaceMeshes, mesh_occluded

FOUR_PI = wp.constant(wp.float64(4.0 * math.pi))
#: Luminance transmittance above which a pixel shows no fog (its depth is the far plane).
CLEAR = wp.constant(wp.float64(1.0 - 1.0e-7))


@wp.struct
class FogMarch:
    """How the in-scattering integral is taken, and the light."""

    nodes: wp.array(dtype=wp.float64)  # Gauss-Legendre abscissae on [0, 1]
    weights: wp.array(dtype=wp.float64)  # their weights on [0, 1]
    min_pieces: int
    max_pieces: int
    cut_depth: wp.float64  # optical depth after which the ray's contribution is dropped
    sun_direction: wp.vec3d  # unit, towards the sun
    sun_irradiance: wp.vec3d  # RGB, at normal incidence
    sun_on: int  # 0: no sun term (none, unlit or at/below the horizon)
    ambient: wp.vec3d  # isotropic sky radiance [irradiance/sr], RGB
    occluders: SurfaceMeshes  # meshes that shadow the fog from the sun (terrain), camera-relative
    layers: LayerShadows  # stratiform layers above the fog, whose shadow it lies in


@wp.struct
class FogRay:
    """What a view segment through the fogs gives."""

    radiance: wp.vec3d
    transmittance: wp.vec3d
    distance: wp.float64  # opacity-weighted mean distance along the ray [m] (0 with nothing seen)
    opacity: wp.float64  # luminance of the quadrature's int sigma_t T dt (0: nothing seen)


@wp.func
def one_minus_exp64(tau: wp.float64) -> wp.float64:
    """1 - exp(-tau), by its series below 1e-3 (error < tau^5 / 120)."""
    if tau < wp.float64(1.0e-3):
        sixth = wp.float64(1.0) / wp.float64(6.0)
        return tau * (wp.float64(1.0) - tau * (wp.float64(0.5) - tau * (sixth - tau / wp.float64(24.0))))
    return wp.float64(1.0) - wp.exp(-tau)


@wp.func
def exp3d(tau: wp.vec3d) -> wp.vec3d:
    return wp.vec3d(wp.exp(-tau[0]), wp.exp(-tau[1]), wp.exp(-tau[2]))


@wp.func
def luminance64(c: wp.vec3d) -> wp.float64:
    return wp.float64(0.2126) * c[0] + wp.float64(0.7152) * c[1] + wp.float64(0.0722) * c[2]


@wp.func
def phase_hg64(cos_theta: wp.float64, g: wp.float64) -> wp.float64:
    """Henyey-Greenstein phase function [1/sr], normalised over the sphere."""
    denominator = wp.float64(1.0) + g * g - wp.float64(2.0) * g * cos_theta
    return (wp.float64(1.0) - g * g) / (FOUR_PI * denominator * wp.sqrt(denominator))


@wp.func
def line_crossing(value: wp.float64, rate: wp.float64, level: wp.float64, t: wp.float64,
                  best: wp.float64) -> wp.float64:
    """min(best, the ray distance > t at which value + rate * t' reaches ``level``)."""
    if rate != wp.float64(0.0):
        crossing = (level - value) / rate
        if crossing > t:
            return wp.min(best, crossing)
    return best


@wp.func
def next_break(fogs: FogSet, o: wp.vec3d, w: wp.vec3d, t: wp.float64, best: wp.float64) -> wp.float64:
    """The first discontinuity of any fog's density along o + t' w beyond t (``best`` when none comes sooner)."""
    for f in range(fogs.body_count):
        body = fogs.bodies[f]
        best = line_crossing(o[1], w[1], body.floor, t, best)
        best = line_crossing(o[1], w[1], body.top, t, best)
        for i in range(body.polynomial_first, body.polynomial_first + body.polynomial_count):
            band = fogs.polynomials[i]
            v0 = wp.dot(band.axis, o) + band.offset
            dv = wp.dot(band.axis, w)
            if band.repeat == 0:
                best = line_crossing(v0, dv, -band.half, t, best)
                best = line_crossing(v0, dv, band.half, t, best)
            elif dv != wp.float64(0.0):
                period = wp.float64(2.0) * band.half
                q = (v0 + dv * t + band.half) / period
                cell = wp.floor(q) + wp.float64(1.0)  # the next boundary strictly ahead
                if dv < wp.float64(0.0):
                    cell = wp.ceil(q) - wp.float64(1.0)
                best = line_crossing(v0, dv, cell * period - band.half, t, best)
    return best


@wp.func
def ray_feature(fogs: FogSet, w: wp.vec3d, longest: wp.float64) -> wp.float64:
    """The shortest length over which the density changes along direction ``w`` [m] (``longest`` when nothing
    varies): a cosine's wavelength along the ray 2 pi / |k . w|, a polynomial band's interval along the ray
    2 half / |axis . w|, a blob's radius (its profile along any line through it)."""
    best = longest
    for f in range(fogs.body_count):
        body = fogs.bodies[f]
        for i in range(body.cosine_first, body.cosine_first + body.cosine_count):
            rate = wp.abs(wp.dot(fogs.cosines[i].wave, w))
            if rate * best > wp.float64(2.0 * math.pi):
                best = wp.float64(2.0 * math.pi) / rate
        for i in range(body.polynomial_first, body.polynomial_first + body.polynomial_count):
            band = fogs.polynomials[i]
            rate = wp.abs(wp.dot(band.axis, w))
            if rate * best > wp.float64(2.0) * band.half:
                best = wp.float64(2.0) * band.half / rate
        for i in range(body.blob_first, body.blob_first + body.blob_count):
            best = wp.min(best, wp.sqrt(fogs.blobs[i].radius2))
    return best


@wp.func
def slabs_span(fogs: FogSet, o: wp.vec3d, w: wp.vec3d, t0: wp.float64, t1: wp.float64) -> wp.vec2d:
    """The part of [t0, t1] from the first slab entry to the last slab exit (empty: x >= y)."""
    lo = t1
    hi = t0
    for f in range(fogs.body_count):
        body = fogs.bodies[f]
        a = t0
        b = t1
        if w[1] == wp.float64(0.0):
            if o[1] < body.floor or o[1] > body.top:
                a = t1
                b = t0
        else:
            t_floor = (body.floor - o[1]) / w[1]
            t_top = (body.top - o[1]) / w[1]
            a = wp.max(t0, wp.min(t_floor, t_top))
            b = wp.min(t1, wp.max(t_floor, t_top))
        if b > a:
            lo = wp.min(lo, a)
            hi = wp.max(hi, b)
    return wp.vec2d(lo, hi)


@wp.func
def clearest_depth(tau: wp.vec3d, total: wp.vec3d) -> wp.float64:
    """The smallest channel of ``tau`` among those the fogs dim at all (``total`` > 0)."""
    best = wp.float64(1.0e300)
    for c in range(3):
        if total[c] > wp.float64(0.0):
            best = wp.min(best, tau[c])
    return best


@wp.func
def cut_distance(fogs: FogSet, march: FogMarch, o: wp.vec3d, w: wp.vec3d, t0: wp.float64, t1: wp.float64,
                 total: wp.vec3d) -> wp.float64:
    """Where the clearest channel's optical depth from t0 reaches ``march.cut_depth`` (t1 if it never does)."""
    if clearest_depth(total, total) <= march.cut_depth:
        return t1
    lo = t0
    hi = t1
    for _ in range(60):
        mid = wp.float64(0.5) * (lo + hi)
        if clearest_depth(fogs_optical_depth(fogs, o + t0 * w, o + mid * w), total) < march.cut_depth:
            lo = mid
        else:
            hi = mid
    return hi


@wp.func
def sun_optical_depth(fogs: FogSet, march: FogMarch, x: wp.vec3d) -> wp.vec3d:
    """RGB optical depth of the fogs from x towards the sun, up to the highest slab top (closed form)."""
    top = fogs.bodies[0].top
    for f in range(fogs.body_count):
        top = wp.max(top, fogs.bodies[f].top)
    length = wp.max(top - x[1], wp.float64(0.0)) / march.sun_direction[1]
    return fogs_optical_depth(fogs, x, x + length * march.sun_direction)


@wp.func
def sun_blocked(march: FogMarch, x: wp.vec3d) -> bool:
    """Whether a mesh (terrain) lies between the eye-relative point ``x`` and the sun: a BVH any-hit ray, started
    2e-5 (1 m + |x|) towards the sun so that float32 rounding near a surface does not hide the point."""
    if march.occluders.triangle_count == 0:
        return False
    p = wp.vec3(float(x[0]), float(x[1]), float(x[2]))
    d = wp.vec3(float(march.sun_direction[0]), float(march.sun_direction[1]), float(march.sun_direction[2]))
    return mesh_occluded(march.occluders, p + d * (2.0e-5 * (1.0 + wp.length(p))), d, 1.0e30)


@wp.struct
class FogPoint:
    """The fogs' coefficients at one point, RGB [1/m]."""

    extinction: wp.vec3d
    scattering: wp.vec3d
    sun_scattering: wp.vec3d  # sum_f sigma_s,f p_f(theta) [1/(m sr)]


@wp.func
def fog_point(fogs: FogSet, x: wp.vec3d, cos_theta: wp.float64) -> FogPoint:
    out = FogPoint()
    for f in range(fogs.body_count):
        body = fogs.bodies[f]
        density = fog_density(fogs, f, x)
        out.extinction += density * body.extinction
        out.scattering += density * body.scattering
        out.sun_scattering += (density * phase_hg64(cos_theta, body.g)) * body.scattering
    return out


@wp.func
def fog_ray(fogs: FogSet, march: FogMarch, o: wp.vec3d, w: wp.vec3d, t0: wp.float64, t1: wp.float64) -> FogRay:
    """Transmittance, single-scattered sun and sky light, and mean distance of the view segment o + t w,
    t in [t0, t1] (eye-relative [m], w unit)."""
    out = FogRay()
    out.transmittance = wp.vec3d(wp.float64(1.0), wp.float64(1.0), wp.float64(1.0))
    span = slabs_span(fogs, o, w, t0, t1)
    if span[1] <= span[0]:
        return out
    total = fogs_optical_depth(fogs, o + span[0] * w, o + span[1] * w)
    out.transmittance = exp3d(total)
    end = cut_distance(fogs, march, o, w, span[0], span[1], total)
    pieces = wp.ceil((end - span[0]) / ray_feature(fogs, w, end - span[0] + wp.float64(1.0)))
    pieces = wp.clamp(pieces, wp.float64(march.min_pieces), wp.float64(march.max_pieces))
    step = (end - span[0]) / pieces
    cos_theta = wp.dot(w, march.sun_direction)
    tau = wp.vec3d()
    sky_num = wp.vec3d()
    sky_den = wp.vec3d()
    sun = wp.vec3d()
    distance = wp.float64(0.0)
    t = span[0]
    count = int(0)
    while t < end:
        t_next = next_break(fogs, o, w, t, wp.min(end, t + step))
        if count >= 2 * march.max_pieces or t_next <= t:  # too many breaks, or a step below rounding: finish
            t_next = end
        length = t_next - t
        for j in range(march.nodes.shape[0]):
            s = t + length * march.nodes[j]
            x = o + s * w
            point = fog_point(fogs, x, cos_theta)
            view = exp3d(tau + fogs_optical_depth(fogs, o + t * w, x))
            weight = length * march.weights[j]
            seen = wp.cw_mul(point.extinction, view)
            sky_num += weight * wp.cw_mul(point.scattering, view)
            sky_den += weight * seen
            out.opacity += weight * luminance64(seen)
            distance += weight * luminance64(seen) * s
            if march.sun_on != 0 and not sun_blocked(march, x):
                lit = exp3d(sun_optical_depth(fogs, march, x)) * layers_sun_transmittance(march.layers, x,
                                                                                           march.sun_direction)
                sun += weight * wp.cw_mul(wp.cw_mul(point.sun_scattering, view), lit)
        tau += fogs_optical_depth(fogs, o + t * w, o + t_next * w)
        t = t_next
        count += 1
    out.radiance = wp.cw_mul(sun, march.sun_irradiance)
    for c in range(3):
        if sky_den[c] > wp.float64(0.0):
            out.radiance[c] += march.ambient[c] * one_minus_exp64(total[c]) * sky_num[c] / sky_den[c]
    if out.opacity > wp.float64(0.0):
        out.distance = distance / out.opacity
    return out


@wp.struct
class FogEyeRay:
    """A pixel's camera ray in float64, as the fog's closed forms take it: origin, unit direction, the distances
    [m] along it of the near plane and of the nearer of the far plane and the opaque limit, and the cosine to
    the camera's axis (camera-space depth = distance x ``cos_axis``)."""

    origin: wp.vec3d
    direction: wp.vec3d
    t_near: wp.float64
    t_far: wp.float64
    cos_axis: wp.float64


@wp.func
def fog_eye_ray(cam: PinholeCamera, limit: wp.array2d(dtype=float), has_limit: int, row: int,
                col: int) -> FogEyeRay:
    """The pixel centre's camera ray, from the near plane to the nearer of the far plane and ``limit``."""
    eye_ray = primary_ray(cam, row, col, 0.5, 0.5)
    d32 = eye_ray.direction
    o32 = eye_ray.origin
    out = FogEyeRay()
    out.direction = wp.normalize(wp.vec3d(wp.float64(d32[0]), wp.float64(d32[1]), wp.float64(d32[2])))
    out.origin = wp.vec3d(wp.float64(o32[0]), wp.float64(o32[1]), wp.float64(o32[2]))
    forward = camera_forward(cam)
    out.cos_axis = wp.dot(out.direction, wp.vec3d(wp.float64(forward[0]), wp.float64(forward[1]),
                                                  wp.float64(forward[2])))
    far = wp.float64(cam.far)
    if has_limit != 0:
        far = wp.min(far, wp.float64(limit[row, col]))
    out.t_near = wp.float64(cam.near) / out.cos_axis
    out.t_far = far / out.cos_axis
    return out


@wp.kernel
def fog_kernel(fogs: FogSet, march: FogMarch, cam: PinholeCamera, limit: wp.array2d(dtype=float), has_limit: int,
               radiance: wp.array2d(dtype=wp.vec3), transmittance: wp.array2d(dtype=wp.vec3),
               depth: wp.array2d(dtype=float), row_offset: int):
    """One pixel: the fogs between the near plane and the nearer of the far plane and ``limit`` (camera-space
    depths [m])."""
    tid_row, col = wp.tid()
    row = row_offset + tid_row
    eye = fog_eye_ray(cam, limit, has_limit, row, col)
    cos_axis = eye.cos_axis
    ray = fog_ray(fogs, march, eye.origin, eye.direction, eye.t_near, eye.t_far)
    radiance[row, col] = wp.vec3(float(ray.radiance[0]), float(ray.radiance[1]), float(ray.radiance[2]))
    transmittance[row, col] = wp.vec3(float(ray.transmittance[0]), float(ray.transmittance[1]),
                                      float(ray.transmittance[2]))
    depth[row, col] = cam.far
    if luminance64(ray.transmittance) < CLEAR and ray.opacity > wp.float64(0.0):
        depth[row, col] = float(ray.distance * cos_axis)


@wp.kernel
def sun_transmittance_kernel(fogs: FogSet, direction: wp.vec3d, horizontal_length: wp.float64,
                             points: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.vec3d)):
    """Transmittance of the fogs from each eye-relative point along ``direction`` until it leaves every slab (a
    horizontal direction: ``horizontal_length`` metres)."""
    i = wp.tid()
    x = points[i]
    length = slabs_exit_length(fogs, x, direction, horizontal_length)
    out[i] = exp3d(fogs_optical_depth(fogs, x, x + length * direction))
