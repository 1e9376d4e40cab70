"""Bouthors 2006 §5 on the device: MIP pyramids, the three-ring gather, an exact form-factor gather, sun shadows.

Both planes (cloud base and ground, parallel, ``h`` apart) share one grid: texel (i, j) of level 0 covers
[i p, (i+1) p] x [j p, (j+1) p] in plane coordinates (x along the first array axis... see ``texel``), p the pixel
size. Level k texels are 2^k p wide. Lookups are bilinear on texel centres with clamp-to-edge addressing, so a
uniform buffer stands for a uniform infinite plane.
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import bilinear_cell, bilinear_mix, luminance

#: Ring weights v1, v2, v3 at MIP levels m, m + 1, m + 3 (§5.3, from f = 0.5, 0.3, 0.2).
RING_W0 = wp.constant(0.4)
RING_W1 = wp.constant(0.387)
RING_W3 = wp.constant(0.213)
INV_2PI = wp.constant(0.15915494309189535)


@wp.kernel
def downsample_kernel(src: wp.array2d(dtype=wp.vec3), dst: wp.array2d(dtype=wp.vec3)):
    """2x2 box average (src dimensions are even)."""
    i, j = wp.tid()
    a = src[2 * i, 2 * j] + src[2 * i + 1, 2 * j] + src[2 * i, 2 * j + 1] + src[2 * i + 1, 2 * j + 1]
    dst[i, j] = a * 0.25


@wp.func
def bilinear(level: wp.array2d(dtype=wp.vec3), u: float, v: float) -> wp.vec3:
    """Bilinear lookup at continuous texel coordinates (u, v) (texel centres at integers), clamped to the edge."""
    cell = bilinear_cell(wp.vec2(u, v), wp.vec2i(level.shape[0], level.shape[1]))
    lo = cell.lo
    hi = cell.hi
    return bilinear_mix(level[lo[0], lo[1]], level[hi[0], lo[1]], level[lo[0], hi[1]], level[hi[0], hi[1]], cell.frac)


@wp.func
def level_coord(i: int, k_scale: float) -> float:
    """Continuous texel coordinate, at a level whose texels are ``k_scale`` level-0 texels wide, of the centre
    of level-0 texel ``i``."""
    return (float(i) + 0.5) / k_scale - 0.5


@wp.kernel
def ring_gather_kernel(
    level_a: wp.array2d(dtype=wp.vec3),
    level_b: wp.array2d(dtype=wp.vec3),
    level_c: wp.array2d(dtype=wp.vec3),
    scale_a: float,
    scale_b: float,
    scale_c: float,
    reflectance: wp.array2d(dtype=wp.vec3),
    received: wp.array2d(dtype=wp.vec3),
    emitted: wp.array2d(dtype=wp.vec3),
    exchanged: wp.array(dtype=float),
):
    """E = 0.4 dE(A1) + 0.387 dE(A2) + 0.213 dE(A3) from MIP levels of the other plane's exitance (squares of h, 2h,
    8h centred on the receiver); R += E; dR = ρ E; the luminance of E is summed into ``exchanged``."""
    i, j = wp.tid()
    e = RING_W0 * bilinear(level_a, level_coord(i, scale_a), level_coord(j, scale_a))
    e += RING_W1 * bilinear(level_b, level_coord(i, scale_b), level_coord(j, scale_b))
    e += RING_W3 * bilinear(level_c, level_coord(i, scale_c), level_coord(j, scale_c))
    received[i, j] = received[i, j] + e
    emitted[i, j] = wp.cw_mul(reflectance[i, j], e)
    wp.atomic_add(exchanged, 0, luminance(e))


@wp.func
def corner_factor(x: float, y: float) -> float:
    """Form factor from a point to the rectangle [0, x] x [0, y] of a parallel plane at unit distance (signed, odd
    in x and y): (X atan(Y/√(1+X²))/√(1+X²) + Y atan(X/√(1+Y²))/√(1+Y²)) / 2π."""
    ax = wp.sqrt(1.0 + x * x)
    ay = wp.sqrt(1.0 + y * y)
    return (x / ax * wp.atan(y / ax) + y / ay * wp.atan(x / ay)) * INV_2PI


@wp.kernel
def exact_gather_kernel(
    source: wp.array2d(dtype=wp.vec3),
    pixel_over_h: float,
    reflectance: wp.array2d(dtype=wp.vec3),
    received: wp.array2d(dtype=wp.vec3),
    emitted: wp.array2d(dtype=wp.vec3),
    exchanged: wp.array(dtype=float),
):
    """Reference gather: E(p) = Σ over every texel of the other plane of its exitance times the exact form factor
    from p's centre to the texel's square (outside the buffer: nothing)."""
    i, j = wp.tid()
    nu = source.shape[0]
    nv = source.shape[1]
    e = wp.vec3(0.0)
    for a in range(nu):
        x0 = (float(a - i) - 0.5) * pixel_over_h
        x1 = x0 + pixel_over_h
        for b in range(nv):
            s = source[a, b]
            if wp.max(s) > 0.0:
                y0 = (float(b - j) - 0.5) * pixel_over_h
                y1 = y0 + pixel_over_h
                f = corner_factor(x1, y1) - corner_factor(x0, y1) - corner_factor(x1, y0) + corner_factor(x0, y0)
                e += s * f
    received[i, j] = received[i, j] + e
    emitted[i, j] = wp.cw_mul(reflectance[i, j], e)
    wp.atomic_add(exchanged, 0, luminance(e))


@wp.kernel
def ground_direct_kernel(
    cloud_transmittance: wp.array2d(dtype=wp.vec3),
    shift_u: float,
    shift_v: float,
    sun_on_ground: wp.vec3,
    out: wp.array2d(dtype=wp.vec3),
):
    """S_G^d: sun irradiance on the horizontal ground (``sun_on_ground`` = E_sun μ_l) through the cloud's directional
    transmittance T_C at the point the sun ray crossed the cloud base, ``(shift_u, shift_v)`` texels away
    (h tan θ_l towards the sun)."""
    i, j = wp.tid()
    t = bilinear(cloud_transmittance, float(i) + shift_u, float(j) + shift_v)
    out[i, j] = wp.cw_mul(sun_on_ground, t)
