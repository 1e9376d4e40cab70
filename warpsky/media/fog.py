"""Analytic fog on the device: its terms in float64 arrays and the closed-form optical depth of a segment.

Biri et al. 2002 choose functions whose line integrals are known (their Eq. 8), so a ray's transmittance costs one
formula per term instead of a march. Here every integral runs over the segment ``a -> b`` clipped to the fog's
slab, with ``d = b - a``, length ``L`` and ``x(s) = a + s d``:

* constant c0:                 ``c0 L``;
* cosine c cos(k.x + phi):     ``c L cos(theta_a + D/2) sinc(D/2)`` with theta_a = k.a + phi and D = k.d, the
  product form of (sin theta_b - sin theta_a) / D that never divides two small differences (k.d -> 0 gives the
  constant integrand c L cos theta_a; sinc by its series below 1e-4);
* polynomial P on |v| <= h (v measured from the interval's centre):
  ``L (s2 - s1) mean(P over [v(s1), v(s2)])``, the mean being ``sum_n c_n / (n+1) sum_{j<=n} v1^j v2^(n-j)``
  (the divided difference of the antiderivative, written without subtraction); repeated polynomials split the
  segment into the first partial cell, a count of whole cells and the last partial cell (Biri Fig. 3);
* blob c / (1 + r^2/R^2): along the segment r^2 = alpha (t - t0)^2 + rho^2 (alpha = 1 for a point, the squared
  sine of the angle to the line for a line), so the integral is
  ``c R^2 L / h^2 * (atan(z1 + dz) - atan(z1)) / dz`` with h^2 = R^2 + rho^2, z1 the start's offset from the
  closest approach in units of h / sqrt(alpha) and dz = sqrt(alpha) L / h; the quotient is taken as
  atan(dz / (1 + z1 (z1 + dz))) / dz, by its series when that argument is below 1e-3, so a segment parallel to a
  line blob (dz -> 0) gives the constant integrand and a zero-length segment gives 0.

Everything is float64: over 1e6 m rays the integrals keep a relative 1e-5 that float32 loses to the cancellation in
the phases and in (sin b - sin a) / k. Positions are relative to the camera and the wind's displacement is folded
in on the host (:func:`fog_struct`): the device never sees world coordinates or time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from warpsky.model.fog import AnalyticFog, BlobTerm, ConstantTerm, CosineTerm, PolynomialTerm


@wp.struct
class FogBody:
    """One fog: its slab, optics and the ranges of its terms in the shared term arrays."""

    floor: wp.float64  # slab bottom, y relative to the eye at the render time [m]
    top: wp.float64  # slab top, likewise [m]
    constant: wp.float64  # c0 [1/m]
    extinction: wp.vec3d  # extinction_scale, RGB
    scattering: wp.vec3d  # extinction_scale * albedo, RGB
    g: wp.float64  # Henyey-Greenstein asymmetry
    cosine_first: int
    cosine_count: int
    polynomial_first: int
    polynomial_count: int
    blob_first: int
    blob_count: int


@wp.struct
class CosineWave:
    """``amplitude cos(wave . x + phase)``, x relative to the eye."""

    wave: wp.vec3d  # [rad/m]
    amplitude: wp.float64  # [1/m]
    phase: wp.float64  # [rad], reduced to [0, 2 pi)


@wp.struct
class PolynomialBand:
    """P(v) on |v| <= half (or repeated with period 2 half), v = axis . x + offset [m] from the interval's centre."""

    axis: wp.vec3d  # unit
    offset: wp.float64  # [m]
    half: wp.float64  # half the interval [m]
    repeat: int
    coefficient_first: int  # into FogSet.coefficients: c_n about the centre, ascending
    coefficient_count: int


@wp.struct
class Blob:
    """``strength / (1 + r^2 / radius2)``, r the distance to ``centre`` or, for a line, to the line through it."""

    centre: wp.vec3d  # relative to the eye [m]
    direction: wp.vec3d  # unit, line blobs only
    line: int
    strength: wp.float64  # [1/m]
    radius2: wp.float64  # R^2 [m^2]


@wp.struct
class FogSet:
    """Every analytic fog of a scene; their extinctions add."""

    bodies: wp.array(dtype=FogBody)
    body_count: int
    cosines: wp.array(dtype=CosineWave)
    polynomials: wp.array(dtype=PolynomialBand)
    coefficients: wp.array(dtype=wp.float64)
    blobs: wp.array(dtype=Blob)


# ----------------------------------------------------------------------------------------------- closed forms
@wp.func
def sinc64(x: wp.float64) -> wp.float64:
    """sin(x) / x, 1 at 0 (series below 1e-4: error < x^4 / 120)."""
    if wp.abs(x) < wp.float64(1.0e-4):
        return wp.float64(1.0) - x * x / wp.float64(6.0)
    return wp.sin(x) / x


@wp.func
def atan_difference_quotient(z1: wp.float64, dz: wp.float64) -> wp.float64:
    """(atan(z1 + dz) - atan(z1)) / dz for dz >= 0; 1 / (1 + z1^2) at dz = 0."""
    q = wp.float64(1.0) + z1 * (z1 + dz)
    if q > wp.float64(0.0):
        z = dz / q
        if z < wp.float64(1.0e-3):  # atan(z) / z = 1 - z^2/3 + z^4/5 - ..., error < z^6 / 7
            z2 = z * z
            return (wp.float64(1.0) - z2 / wp.float64(3.0) + z2 * z2 / wp.float64(5.0)) / q
        return wp.atan(z) / dz
    return wp.atan2(dz, q) / dz


@wp.func
def slab_span(a_y: wp.float64, d_y: wp.float64, floor: wp.float64, top: wp.float64) -> wp.vec2d:
    """(s0, s1) in [0, 1] of the segment y(s) = a_y + s d_y inside floor <= y <= top (s1 <= s0: none)."""
    if d_y == wp.float64(0.0):
        if a_y >= floor and a_y <= top:
            return wp.vec2d(wp.float64(0.0), wp.float64(1.0))
        return wp.vec2d(wp.float64(1.0), wp.float64(0.0))
    s_floor = (floor - a_y) / d_y
    s_top = (top - a_y) / d_y
    return wp.vec2d(wp.max(wp.float64(0.0), wp.min(s_floor, s_top)), wp.min(wp.float64(1.0), wp.max(s_floor, s_top)))


@wp.func
def cosine_integral(wave: CosineWave, a: wp.vec3d, d: wp.vec3d, length: wp.float64) -> wp.float64:
    """Integral of the cosine over the segment a -> a + d of ``length`` [m]."""
    theta = wp.dot(wave.wave, a) + wave.phase
    half = wp.float64(0.5) * wp.dot(wave.wave, d)
    return wave.amplitude * length * wp.cos(theta + half) * sinc64(half)


@wp.func
def polynomial_value(fogs: FogSet, band: PolynomialBand, v: wp.float64) -> wp.float64:
    """P(v) by Horner."""
    total = wp.float64(0.0)
    for j in range(band.coefficient_count):
        total = total * v + fogs.coefficients[band.coefficient_first + band.coefficient_count - 1 - j]
    return total


@wp.func
def polynomial_mean(fogs: FogSet, band: PolynomialBand, v1: wp.float64, v2: wp.float64) -> wp.float64:
    """Mean of P over [v1, v2] (P(v1) when they coincide): sum_n c_n / (n + 1) h_n(v1, v2), h_n the sum of all
    v1^j v2^(n-j), built as h_n = v2 h_(n-1) + v1^n."""
    total = wp.float64(0.0)
    h = wp.float64(1.0)
    power = wp.float64(1.0)
    for n in range(band.coefficient_count):
        if n > 0:
            power = power * v1
            h = v2 * h + power
        total += fogs.coefficients[band.coefficient_first + n] * h / wp.float64(float(n + 1))
    return total


@wp.func
def bounded_polynomial_integral(fogs: FogSet, band: PolynomialBand, va: wp.float64, dv: wp.float64,
                                length: wp.float64) -> wp.float64:
    """Integral of P over the part of v(s) = va + s dv, s in [0, 1], with |v| <= half; ``length`` [m] of s."""
    h = band.half
    if dv == wp.float64(0.0):
        if wp.abs(va) <= h:
            return length * polynomial_value(fogs, band, va)
        return wp.float64(0.0)
    s_minus = (-h - va) / dv
    s_plus = (h - va) / dv
    s1 = wp.max(wp.float64(0.0), wp.min(s_minus, s_plus))
    s2 = wp.min(wp.float64(1.0), wp.max(s_minus, s_plus))
    if s2 <= s1:
        return wp.float64(0.0)
    v1 = wp.clamp(va + s1 * dv, -h, h)
    v2 = wp.clamp(va + s2 * dv, -h, h)
    return length * (s2 - s1) * polynomial_mean(fogs, band, v1, v2)


@wp.func
def repeated_polynomial_integral(fogs: FogSet, band: PolynomialBand, va: wp.float64, dv: wp.float64,
                                 length: wp.float64) -> wp.float64:
    """Integral of the periodic P (period 2 half) along v(s) = va + s dv, s in [0, 1]: first partial cell, whole
    cells, last partial cell, each as (its share of the segment) x (mean of P over it)."""
    h = band.half
    period = wp.float64(2.0) * h
    qa = va + h
    qb = va + dv + h
    if dv < wp.float64(0.0):  # the integral is the same walked backwards
        qa = va + dv + h
        qb = va + h
    cell_a = wp.floor(qa / period)
    cell_b = wp.floor(qb / period)
    if cell_a == cell_b:
        return length * polynomial_mean(fogs, band, qa - cell_a * period - h, qb - cell_a * period - h)
    dq = qb - qa
    first = (cell_a + wp.float64(1.0)) * period - qa
    last = qb - cell_b * period
    whole = (cell_b - cell_a - wp.float64(1.0)) * period
    total = first * polynomial_mean(fogs, band, h - first, h)
    total += whole * polynomial_mean(fogs, band, -h, h)
    total += last * polynomial_mean(fogs, band, -h, last - h)
    return length * total / dq


@wp.func
def polynomial_integral(fogs: FogSet, band: PolynomialBand, a: wp.vec3d, d: wp.vec3d,
                        length: wp.float64) -> wp.float64:
    """Integral of the polynomial term over the segment a -> a + d of ``length`` [m]."""
    va = wp.dot(band.axis, a) + band.offset
    dv = wp.dot(band.axis, d)
    if band.repeat != 0:
        return repeated_polynomial_integral(fogs, band, va, dv, length)
    return bounded_polynomial_integral(fogs, band, va, dv, length)


@wp.func
def blob_integral(blob: Blob, a: wp.vec3d, d: wp.vec3d, length: wp.float64) -> wp.float64:
    """Integral of the blob over the segment a -> a + d of ``length`` > 0 [m] (arctangent closed form)."""
    offset = a - blob.centre
    u = d / length
    if blob.line != 0:
        offset = offset - wp.dot(offset, blob.direction) * blob.direction
        u = u - wp.dot(u, blob.direction) * blob.direction
    root_alpha = wp.length(u)
    z_num = wp.float64(0.0)
    rho = offset
    if root_alpha > wp.float64(0.0):
        unit = u / root_alpha
        z_num = wp.dot(offset, unit)
        rho = offset - z_num * unit
    h2 = blob.radius2 + wp.dot(rho, rho)
    h = wp.sqrt(h2)
    quotient = atan_difference_quotient(z_num / h, root_alpha * length / h)
    return blob.strength * blob.radius2 * length / h2 * quotient


@wp.func
def fog_optical_depth(fogs: FogSet, index: int, a: wp.vec3d, b: wp.vec3d) -> wp.float64:
    """Integral of fog ``index``'s density D (before its extinction scale) from ``a`` to ``b`` (eye-relative
    [m]), in closed form, clipped to its slab; 0 for a zero-length segment."""
    body = fogs.bodies[index]
    full = b - a
    span = slab_span(a[1], full[1], body.floor, body.top)
    if span[1] <= span[0]:
        return wp.float64(0.0)
    start = a + span[0] * full
    d = (span[1] - span[0]) * full
    length = wp.length(d)
    if length == wp.float64(0.0):
        return wp.float64(0.0)
    total = body.constant * length
    for i in range(body.cosine_first, body.cosine_first + body.cosine_count):
        total += cosine_integral(fogs.cosines[i], start, d, length)
    for i in range(body.polynomial_first, body.polynomial_first + body.polynomial_count):
        total += polynomial_integral(fogs, fogs.polynomials[i], start, d, length)
    for i in range(body.blob_first, body.blob_first + body.blob_count):
        total += blob_integral(fogs.blobs[i], start, d, length)
    return total


@wp.func
def polynomial_density(fogs: FogSet, band: PolynomialBand, x: wp.vec3d) -> wp.float64:
    v = wp.dot(band.axis, x) + band.offset
    h = band.half
    if band.repeat != 0:
        period = wp.float64(2.0) * h
        q = v + h
        v = q - wp.floor(q / period) * period - h
    elif wp.abs(v) > h:
        return wp.float64(0.0)
    return polynomial_value(fogs, band, v)


@wp.func
def blob_density(blob: Blob, x: wp.vec3d) -> wp.float64:
    offset = x - blob.centre
    if blob.line != 0:
        offset = offset - wp.dot(offset, blob.direction) * blob.direction
    return blob.strength * blob.radius2 / (blob.radius2 + wp.dot(offset, offset))


@wp.func
def fog_density(fogs: FogSet, index: int, x: wp.vec3d) -> wp.float64:
    """Fog ``index``'s density D [1/m before its extinction scale] at eye-relative ``x`` [m]; 0 outside its slab."""
    body = fogs.bodies[index]
    if x[1] < body.floor or x[1] > body.top:
        return wp.float64(0.0)
    total = body.constant
    for i in range(body.cosine_first, body.cosine_first + body.cosine_count):
        wave = fogs.cosines[i]
        total += wave.amplitude * wp.cos(wp.dot(wave.wave, x) + wave.phase)
    for i in range(body.polynomial_first, body.polynomial_first + body.polynomial_count):
        total += polynomial_density(fogs, fogs.polynomials[i], x)
    for i in range(body.blob_first, body.blob_first + body.blob_count):
        total += blob_density(fogs.blobs[i], x)
    return total


@wp.func
def fogs_optical_depth(fogs: FogSet, a: wp.vec3d, b: wp.vec3d) -> wp.vec3d:
    """RGB optical depth of every fog from ``a`` to ``b``: sum of extinction_scale x :func:`fog_optical_depth`."""
    total = wp.vec3d()
    for i in range(fogs.body_count):
        total += fog_optical_depth(fogs, i, a, b) * fogs.bodies[i].extinction
    return total


@wp.func
def slabs_exit_length(fogs: FogSet, x: wp.vec3d, direction: wp.vec3d, horizontal: wp.float64) -> wp.float64:
    """Length [m] along unit ``direction`` from ``x`` after which the ray is out of every slab for good (up to the
    highest top, down to the lowest floor; ``horizontal`` for a horizontal ray)."""
    top = fogs.bodies[0].top
    floor = fogs.bodies[0].floor
    for f in range(fogs.body_count):
        top = wp.max(top, fogs.bodies[f].top)
        floor = wp.min(floor, fogs.bodies[f].floor)
    length = horizontal
    if direction[1] > wp.float64(0.0):
        length = wp.max(top - x[1], wp.float64(0.0)) / direction[1]
    elif direction[1] < wp.float64(0.0):
        length = wp.max(x[1] - floor, wp.float64(0.0)) / -direction[1]
    return length


# ------------------------------------------------------------------------------------------------------- host
def centred_coefficients(coefficients, centre: float) -> np.ndarray:
    """Coefficients of P(centre + v) in ascending powers of v: c'_j = sum_n c_n C(n, j) centre^(n - j)."""
    c = np.asarray(coefficients, dtype=np.float64)
    out = np.zeros_like(c)
    for n, value in enumerate(c):
        for j in range(n + 1):
            out[j] += value * math.comb(n, j) * centre ** (n - j)
    return out


def _vec3d(v) -> wp.vec3d:
    return wp.vec3d(*np.asarray(v, dtype=np.float64).tolist())


def _struct_array(items: list, dtype, device) -> wp.array:
    """``items`` as a device array (one zero element when empty: struct fields cannot hold None)."""
    return wp.array(items or [dtype()], dtype=dtype, device=device)


def _polynomial(term: PolynomialTerm, shift: np.ndarray, first: int) -> tuple[PolynomialBand, np.ndarray]:
    lo, hi = term.interval
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    band = PolynomialBand()
    band.axis = _vec3d(term.axis)
    offset = float(term.axis @ (shift - term.origin)) - centre
    if term.repeat:  # keep the device's numbers small: v only matters modulo the period
        offset = math.fmod(offset + half, 2.0 * half)
        offset = offset + 2.0 * half if offset < 0.0 else offset
        offset -= half
    band.offset = wp.float64(offset)
    band.half = wp.float64(half)
    band.repeat = int(term.repeat)
    band.coefficient_first = first
    band.coefficient_count = len(term.coefficients)
    return band, centred_coefficients(term.coefficients, centre)


def _blob(term: BlobTerm, shift: np.ndarray) -> Blob:
    blob = Blob()
    blob.centre = _vec3d(term.centre - shift)
    blob.direction = _vec3d(term.direction if term.is_line else np.zeros(3))
    blob.line = int(term.is_line)
    blob.strength = wp.float64(term.strength)
    blob.radius2 = wp.float64(term.radius * term.radius)
    return blob


def fog_struct(fogs: AnalyticFog | Sequence[AnalyticFog], camera_position, time_s: float, device) -> FogSet:
    """Kernel view of ``fogs`` at time ``time_s`` [s] relative to the eye at ``camera_position`` [m, world].

    The fog at time t is the fog at 0 moved by wind * t, so a point x relative to the eye sees D_0(x + shift) with
    shift = camera - wind t: slabs, cosine phases (reduced mod 2 pi), polynomial offsets (modulo the period when
    repeated) and blob centres take the shift here, in float64.
    """
    fogs = [fogs] if isinstance(fogs, AnalyticFog) else list(fogs)
    camera = np.asarray(camera_position, dtype=np.float64).reshape(3)
    bodies, cosines, bands, coefficients, blobs = [], [], [], [], []
    for fog in fogs:
        shift = camera - fog.wind * float(time_s)
        body = FogBody()
        body.floor = wp.float64(fog.floor - shift[1])
        body.top = wp.float64(fog.top - shift[1])
        body.constant = wp.float64(sum(t.value for t in fog.of_type(ConstantTerm)))
        body.extinction = _vec3d(fog.extinction_scale)
        body.scattering = _vec3d(fog.extinction_scale * fog.albedo)
        body.g = wp.float64(fog.g)
        body.cosine_first, body.polynomial_first, body.blob_first = len(cosines), len(bands), len(blobs)
        for term in fog.of_type(CosineTerm):
            wave = CosineWave()
            wave.wave = _vec3d(term.wave_vector)
            wave.amplitude = wp.float64(term.amplitude)
            wave.phase = wp.float64(np.mod(term.phase + float(term.wave_vector @ shift), 2.0 * np.pi))
            cosines.append(wave)
        for term in fog.of_type(PolynomialTerm):
            band, centred = _polynomial(term, shift, sum(len(c) for c in coefficients))
            bands.append(band)
            coefficients.append(centred)
        blobs += [_blob(term, shift) for term in fog.of_type(BlobTerm)]
        body.cosine_count = len(cosines) - body.cosine_first
        body.polynomial_count = len(bands) - body.polynomial_first
        body.blob_count = len(blobs) - body.blob_first
        bodies.append(body)
    out = FogSet()
    out.bodies = _struct_array(bodies, FogBody, device)
    out.body_count = len(bodies)
    out.cosines = _struct_array(cosines, CosineWave, device)
    out.polynomials = _struct_array(bands, PolynomialBand, device)
    flat = np.concatenate(coefficients) if coefficients else np.zeros(1)
    out.coefficients = wp.array(flat, dtype=wp.float64, device=device)
    out.blobs = _struct_array(blobs, Blob, device)
    return out
