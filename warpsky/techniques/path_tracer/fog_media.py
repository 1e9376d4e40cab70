"""Analytic fog (Biri et al. 2002) as a participating medium of the path tracer.

The fog's extinction at a point is its density in closed form (:func:`~warpsky.media.fog.fog_density`, the
same function the fog pass's quadrature uses) times its extinction scale; it joins the voxel media and the air in
the free flights' delta tracking:

* majorant: per fog, a bound on its density times its largest extinction channel (with :data:`FOG_MARGIN`), the
  constant plus every cosine's |amplitude| plus each polynomial's largest |P| on its interval plus every blob's peak
  (:func:`density_bound`), held only inside the fog's slab: a flight's majorant segments end at the slab's faces,
  so the fog costs nothing outside it;
* at a tentative collision its extinction and scattering add to those of the media and the air;
* at a scattering event the fog is chosen with probability its mean scattering over the point's total (each channel
  weighted by its own share over that probability, as the air's share is in
  :func:`~warpsky.techniques.path_tracer.events.media_first_function`); then the sun comes through its
  Henyey-Greenstein phase and the new direction is drawn from it (weight 1);
* transmittance toward the sun and along the camera ray is the closed-form optical depth
  (:func:`~warpsky.media.fog.fog_optical_depth`): exact, no tracking, no noise.

After high-order similarity (``reduced``) the fog is reduced like the voxel media: extinction sigma_t - g sigma_s,
isotropic scattering sigma_s (1 - g). Positions are camera-relative, as everywhere in the path tracer; the fog's
terms are evaluated in float64 (:func:`~warpsky.media.fog.fog_struct` folds the wind in on the host).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import warp as wp

from warpsky.core.numerics import mean3
from warpsky.media.fog import (
    FogBody,
    FogSet,
    fog_density,
    fog_optical_depth,
    fog_struct,
    slabs_exit_length,
)
from warpsky.model.fog import AnalyticFog, BlobTerm, ConstantTerm, CosineTerm, PolynomialTerm

#: The fog's majorant is its density bound inflated by this factor (float32 rounding of the summed coefficients).
FOG_MARGIN = 1.0001
#: A horizontal shadow ray is followed this far [m] through the slabs (the fog pass's length).
HORIZONTAL_LENGTH = wp.constant(wp.float64(1.0e9))


@wp.struct
class FogTracking:
    """The scene's analytic fogs for the path tracer: their terms (camera-relative) and per fog its majorant
    [1/m], exact (x) and after high-order similarity (y)."""

    fogs: FogSet
    bounds: wp.array(dtype=wp.vec2)


@wp.struct
class FogCoefficients:
    """The fogs' summed extinction and scattering at a point [1/m]."""

    extinction: wp.vec3
    scattering: wp.vec3


@wp.struct
class FogPick:
    """Which part of a scattering event scatters: fog ``body`` (its asymmetry ``g``) or, with -1, the media and the
    air; the per-channel weight of that choice; the advanced random state."""

    body: int
    g: float
    weight: wp.vec3
    state: wp.uint32


# --------------------------------------------------------------------------------------------------- device
@wp.func
def as64(p: wp.vec3) -> wp.vec3d:
    return wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))


@wp.func
def as32(v: wp.vec3d) -> wp.vec3:
    return wp.vec3(float(v[0]), float(v[1]), float(v[2]))


@wp.func
def body_extinction(body: FogBody, reduced: int) -> wp.vec3d:
    """Extinction per unit density [1/m]; with ``reduced`` after high-order similarity (sigma_t - g sigma_s)."""
    if reduced != 0:
        return body.extinction - body.g * body.scattering
    return body.extinction


@wp.func
def body_scattering(body: FogBody, reduced: int) -> wp.vec3d:
    """Scattering per unit density [1/m]; with ``reduced`` sigma_s (1 - g) (then isotropic)."""
    if reduced != 0:
        return (wp.float64(1.0) - body.g) * body.scattering
    return body.scattering


@wp.func
def fog_coefficients(fog: FogTracking, p: wp.vec3, reduced: int) -> FogCoefficients:
    """Summed extinction and scattering of every fog at the camera-relative point ``p`` (with ``reduced``, after
    high-order similarity)."""
    x = as64(p)
    extinction = wp.vec3d()
    scattering = wp.vec3d()
    for f in range(fog.fogs.body_count):
        density = fog_density(fog.fogs, f, x)
        if density > wp.float64(0.0):
            body = fog.fogs.bodies[f]
            extinction += density * body_extinction(body, reduced)
            scattering += density * body_scattering(body, reduced)
    out = FogCoefficients()
    out.extinction = as32(extinction)
    out.scattering = as32(scattering)
    return out


@wp.func
def fog_segment(fog: FogTracking, origin: wp.vec3, direction: wp.vec3, t: float, reduced: int) -> wp.vec2:
    """(majorant [1/m], where it changes [m along the ray]) of the fogs at ``origin + t direction``: each fog's
    bound while the point is inside its slab, 0 outside; the segment ends at the next slab face ahead (3e38 when
    none comes)."""
    majorant = float(0.0)
    end = float(3.0e38)
    y0 = wp.float64(origin[1])
    dy = wp.float64(direction[1])
    for f in range(fog.fogs.body_count):
        body = fog.fogs.bodies[f]
        bound = fog.bounds[f][0]
        if reduced != 0:
            bound = fog.bounds[f][1]
        if dy == wp.float64(0.0):
            if y0 >= body.floor and y0 <= body.top:
                majorant += bound
            continue
        t_floor = (body.floor - y0) / dy
        t_top = (body.top - y0) / dy
        t_in = float(wp.min(t_floor, t_top))
        t_out = float(wp.max(t_floor, t_top))
        if t < t_in:
            end = wp.min(end, t_in)
        elif t < t_out:
            majorant += bound
            end = wp.min(end, t_out)
    return wp.vec2(majorant, end)


@wp.func
def exp_depth(tau: wp.vec3d) -> wp.vec3:
    return wp.vec3(float(wp.exp(-tau[0])), float(wp.exp(-tau[1])), float(wp.exp(-tau[2])))


@wp.func
def fog_depth(fog: FogTracking, a: wp.vec3d, b: wp.vec3d, reduced: int) -> wp.vec3d:
    """RGB optical depth of every fog from ``a`` to ``b`` (camera-relative [m]), closed form."""
    tau = wp.vec3d()
    for f in range(fog.fogs.body_count):
        tau += fog_optical_depth(fog.fogs, f, a, b) * body_extinction(fog.fogs.bodies[f], reduced)
    return tau


@wp.func
def fog_view_transmittance(fog: FogTracking, origin: wp.vec3, direction: wp.vec3, length: float) -> wp.vec3:
    """Transmittance of the fogs over ``length`` [m] from ``origin`` along unit ``direction`` (closed form)."""
    a = as64(origin)
    return exp_depth(fog_depth(fog, a, a + wp.float64(length) * as64(direction), 0))


@wp.func
def fog_sun_transmittance(fog: FogTracking, p: wp.vec3, direction: wp.vec3, reduced: int) -> wp.vec3:
    """Transmittance of the fogs from ``p`` along ``direction`` (toward the sun) until it leaves every slab, in
    closed form (with ``reduced``, through the fogs after high-order similarity)."""
    x = as64(p)
    w = wp.normalize(as64(direction))
    length = slabs_exit_length(fog.fogs, x, w, HORIZONTAL_LENGTH)
    return exp_depth(fog_depth(fog, x, x + length * w, reduced))


@wp.func
def pick_fog(fog: FogTracking, p: wp.vec3, others: wp.vec3, state: wp.uint32) -> FogPick:
    """Choose what scatters at ``p``: a fog, with probability its mean scattering over the mean of the total (the
    fogs' plus ``others``, the media's and the air's), else the media and the air; each channel weighted by its
    share of the point's scattering over that probability, so every channel's expectation is each part's share
    exactly. One random draw when the fogs scatter at ``p``, none otherwise."""
    out = FogPick()
    out.body = -1
    out.g = 0.0
    out.weight = wp.vec3(1.0)
    x = as64(p)
    fogs = wp.vec3(0.0)
    for f in range(fog.fogs.body_count):
        fogs += as32(fog_density(fog.fogs, f, x) * fog.fogs.bodies[f].scattering)
    fog_mean = mean3(fogs)
    if fog_mean <= 0.0:
        out.state = state
        return out
    total = others + fogs
    target = wp.randf(state) * (mean3(others) + fog_mean)
    part = others
    running = mean3(others)
    if target >= running:
        for f in range(fog.fogs.body_count):
            body = fog.fogs.bodies[f]
            part = as32(fog_density(fog.fogs, f, x) * body.scattering)
            running += mean3(part)
            out.body = f
            out.g = float(body.g)
            if target < running:
                break
    probability = mean3(part) / (mean3(others) + fog_mean)
    weight = wp.vec3(0.0)
    for c in range(3):
        if total[c] > 0.0 and probability > 0.0:
            weight[c] = part[c] / (total[c] * probability)
    out.weight = weight
    out.state = state
    return out


# ----------------------------------------------------------------------------------------------------- host
def polynomial_peak(term: PolynomialTerm) -> float:
    """The largest |P| on the term's interval: at its ends or where P' vanishes inside it."""
    lo, hi = term.interval
    candidates = [lo, hi]
    derivative = np.polynomial.polynomial.polyder(term.coefficients)
    if derivative.size > 1 and np.any(derivative != 0.0):
        roots = np.polynomial.polynomial.polyroots(derivative)
        candidates += [r.real for r in roots if abs(r.imag) <= 1e-9 * max(1.0, abs(r)) and lo < r.real < hi]
    return float(np.max(np.abs(term(np.array(candidates)))))


def density_bound(fog: AnalyticFog) -> float:
    """An upper bound on the fog's density D [1/m before its extinction scale]: the constants, every cosine's
    |amplitude|, each polynomial's largest |P| on its interval and every blob's peak, summed."""
    return float(sum(t.value for t in fog.of_type(ConstantTerm))
                 + sum(abs(t.amplitude) for t in fog.of_type(CosineTerm))
                 + sum(polynomial_peak(t) for t in fog.of_type(PolynomialTerm))
                 + sum(t.strength for t in fog.of_type(BlobTerm)))


def fog_majorants(fog: AnalyticFog) -> tuple[float, float]:
    """(exact, after high-order similarity) majorant of ``fog`` [1/m]: :func:`density_bound` times its largest
    extinction channel, and times its largest reduced one (sigma_t - g sigma_s), with :data:`FOG_MARGIN`."""
    bound = density_bound(fog) * FOG_MARGIN
    extinction = np.asarray(fog.extinction_scale, dtype=np.float64)
    reduced = extinction - fog.g * extinction * np.asarray(fog.albedo, dtype=np.float64)
    return bound * float(np.max(extinction)), bound * float(max(np.max(reduced), 0.0))


def fog_tracking(fogs: Sequence[AnalyticFog], camera_position, time_s: float, device) -> FogTracking:
    """The kernel view of ``fogs`` at ``time_s`` [s] relative to the camera at ``camera_position`` [m] with their
    majorants (no fog: an empty set, never read by the kernels without fog)."""
    fogs = list(fogs)
    out = FogTracking()
    out.fogs = fog_struct(fogs, camera_position, time_s, device)
    bounds = [fog_majorants(f) for f in fogs] or [(0.0, 0.0)]
    out.bounds = wp.array(np.asarray(bounds, dtype=np.float32), dtype=wp.vec2, device=device)
    return out
