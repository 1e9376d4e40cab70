"""The deck's shadow on the haze below it as a per-frame map: one exact sun-ray optical depth per texel instead of
one per march step.

Below the plane y = P (the deck's lowest cloud base, or the haze's top when that is lower), no cloud lies on the sun
ray from a point p before the ray reaches P, at

    q(p) = p_xz + sun_xz (P - p_y) / sun_y,

so the deck's transmittance towards the sun there is a function of q alone, T(q) = exp(-sigma L(q)), L the cloud
length of the sun ray from (q, P). Along a view ray o + t v the point q moves on a straight line,
q - c = t (v_xz - (v_y / sun_y) sun_xz) with c = q(o), at the rate ``r`` = |v_xz - (v_y / sun_y) sun_xz| per metre.

The map is a stack of square levels centred on c (a clipmap): level k has N x N texels of edge s_0 2^k, and a point
is read, bilinearly, from the finest level whose square holds it with a texel to spare. s_0 is a quarter of the haze
march's shortest step in q (the deck's shortest shadow feature over ``haze_steps_per_feature``), so near the camera
a read is as good as the exact depth at the step. At a distance t along a ray a texel of the level in use is about
2 t r / N wide in q, where the pixel's own footprint is about t r times its angle: with N = 2 / (pixel angle) a texel
is about a pixel's footprint wide, and details finer than that are not resolved; once a texel is longer than the
shortest step the march's step grows with it (a step per texel), so a ray takes O(N log(range)) steps instead of
O(range / s_0).

The map holds transmittance (per channel), not optical depth, so that where a texel spans several shadow features
its bilinear blend is a mean transmittance rather than the transmittance of a mean depth. Points outside every level,
above P, or a sun within about 0.06 deg of the horizon read the exact optical depth instead. Only the texels the
frame's marches will read are computed: a first pass walks each pixel's steps and marks them (a texel another read
needs and no walk marked falls back to the exact depth too).
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.core.numerics import exp3
from warpsky.media.deck.deck_geometry import HeightField, hf_optical_depth

#: Most texels per level side (the map is levels x N x N RGB transmittances).
MAX_TEXELS = 2048
#: Most levels (each doubles the square's edge).
MAX_LEVELS = 20
#: The map is not used with the sun this close to the horizon (sine of its elevation): q runs off to infinity.
MIN_SUN_SINE = wp.constant(1.0e-3)


@wp.struct
class DeckShadowMap:
    """The deck's transmittance towards the sun on the plane P, per level (camera-relative coordinates)."""

    on: int
    levels: int
    texels: int  # N per side
    texel: float  # s_0 [m], level 0's texel edge
    plane: float  # P minus the eye's y [m]
    centre: wp.vec2  # c: q of the eye [m]
    transmittance: wp.array2d(dtype=wp.vec3)  # (levels * N, N): level k's row i at k * N + i
    marks: wp.array2d(dtype=wp.int32)  # 1 where a march will read the texel (only those are computed)


@wp.func
def map_point(m: DeckShadowMap, p: wp.vec3, sun_dir: wp.vec3) -> wp.vec2:
    """q(p) - c: where the sun ray from ``p`` crosses the plane, relative to the eye's crossing."""
    s = (m.plane - p[1]) / sun_dir[1]
    return wp.vec2(p[0] + sun_dir[0] * s - m.centre[0], p[2] + sun_dir[2] * s - m.centre[1])


@wp.func
def map_level(m: DeckShadowMap, q: wp.vec2) -> int:
    """The finest level whose square holds ``q`` (relative to c) with a texel to spare; ``levels`` when none."""
    d = wp.max(wp.abs(q[0]), wp.abs(q[1]))
    half = (0.5 * float(m.texels) - 1.0) * m.texel
    k = int(0)
    if d > half:
        k = int(wp.ceil(wp.log2(d / half)))
    return wp.min(k, m.levels)


@wp.func
def map_texel(m: DeckShadowMap, q: wp.vec2) -> float:
    """Edge [m] of the texels ``q`` is read from (the level's; 0 where the map does not reach)."""
    k = map_level(m, q)
    if k >= m.levels:
        return 0.0
    return m.texel * wp.pow(2.0, float(k))


@wp.func
def map_read(m: DeckShadowMap, k: int, q: wp.vec2) -> wp.vec4:
    """Bilinear transmittance (RGB) of level ``k`` at ``q`` (relative to c), and 1 where all four texels were
    computed (0: one was not marked, and the transmittance must come from elsewhere)."""
    s = m.texel * wp.pow(2.0, float(k))
    n = m.texels
    u = q[0] / s + 0.5 * float(n) - 0.5
    v = q[1] / s + 0.5 * float(n) - 0.5
    i = wp.clamp(int(wp.floor(u)), 0, n - 2)
    j = wp.clamp(int(wp.floor(v)), 0, n - 2)
    row = k * n + i
    if m.marks[row, j] * m.marks[row, j + 1] * m.marks[row + 1, j] * m.marks[row + 1, j + 1] == 0:
        return wp.vec4(0.0)
    fu = wp.clamp(u - float(i), 0.0, 1.0)
    fv = wp.clamp(v - float(j), 0.0, 1.0)
    a = m.transmittance[row, j] * (1.0 - fv) + m.transmittance[row, j + 1] * fv
    b = m.transmittance[row + 1, j] * (1.0 - fv) + m.transmittance[row + 1, j + 1] * fv
    t = a * (1.0 - fu) + b * fu
    return wp.vec4(t[0], t[1], t[2], 1.0)


@wp.func
def map_mark(m: DeckShadowMap, q: wp.vec2):
    """Mark the texels :func:`map_read` reads at ``q`` (relative to c), if the map reaches it."""
    k = map_level(m, q)
    if k < m.levels:
        s = m.texel * wp.pow(2.0, float(k))
        n = m.texels
        i = wp.clamp(int(wp.floor(q[0] / s + 0.5 * float(n) - 0.5)), 0, n - 2)
        j = wp.clamp(int(wp.floor(q[1] / s + 0.5 * float(n) - 0.5)), 0, n - 2)
        row = k * n + i
        m.marks[row, j] = 1
        m.marks[row, j + 1] = 1
        m.marks[row + 1, j] = 1
        m.marks[row + 1, j + 1] = 1


@wp.func
def deck_sun_transmittance_at(hf: HeightField, m: DeckShadowMap, p: wp.vec3, sun_dir: wp.vec3) -> wp.vec3:
    """The deck's transmittance (RGB) towards the sun from ``p``: read from the map below its plane, else the
    exact optical depth along the sun ray."""
    if m.on != 0 and p[1] <= m.plane and sun_dir[1] > MIN_SUN_SINE:
        q = map_point(m, p, sun_dir)
        k = map_level(m, q)
        if k < m.levels:
            t = map_read(m, k, q)
            if t[3] > 0.0:
                return wp.vec3(t[0], t[1], t[2])
    return exp3(hf_optical_depth(hf, p, sun_dir, 0.0, hf.max_length))


@wp.kernel
def shadow_map_kernel(hf: HeightField, m: DeckShadowMap, sun_dir: wp.vec3, row_offset: int):
    """One texel (row = level * N + i, column j): the exact transmittance of the sun ray from (q, P)."""
    r, j = wp.tid()
    row = r + row_offset
    if m.marks[row, j] == 0:
        return
    k = row // m.texels
    i = row - k * m.texels
    s = m.texel * wp.pow(2.0, float(k))
    half = 0.5 * float(m.texels)
    x = m.centre[0] + (float(i) + 0.5 - half) * s
    z = m.centre[1] + (float(j) + 0.5 - half) * s
    m.transmittance[row, j] = exp3(hf_optical_depth(hf, wp.vec3(x, m.plane, z), sun_dir, 0.0, hf.max_length))


# ------------------------------------------------------------------------------------------------------ host
def map_shape(texel: float, texels: int, reach: float) -> tuple[int, int]:
    """(levels, N): enough doubling levels of ``texels`` texels of edge ``texel`` [m] for the square to reach
    ``reach`` [m] from its centre."""
    n = int(min(max(texels, 4), MAX_TEXELS))
    n += n % 2
    half = (0.5 * n - 1.0) * texel
    levels = 1 if reach <= half else 1 + math.ceil(math.log2(reach / half))
    return min(levels, MAX_LEVELS), n


def auto_texels(pixel_angle: float) -> int:
    """N for texels about a pixel's footprint wide (module docstring): 2 / ``pixel_angle`` [rad]."""
    return int(min(MAX_TEXELS, max(16, math.ceil(2.0 / max(pixel_angle, 1.0e-6)))))


def off_map(device) -> DeckShadowMap:
    """A map that is not used (every point reads the exact optical depth)."""
    m = DeckShadowMap()
    m.on, m.levels, m.texels, m.texel, m.plane = 0, 0, 2, 1.0, 0.0
    m.centre = wp.vec2(0.0, 0.0)
    m.transmittance = wp.zeros((2, 2), dtype=wp.vec3, device=device)
    m.marks = wp.zeros((2, 2), dtype=wp.int32, device=device)
    return m


def build_shadow_map(hf: HeightField, plane: float, sun_dir, texel: float, texels: int, reach: float,
                     device, launch, mark=None) -> DeckShadowMap:
    """The map over the plane ``plane`` (camera-relative y [m]) for the sun direction ``sun_dir`` (towards the
    sun), texels of ``texel`` [m] at level 0, ``texels`` per side, levels out to ``reach`` [m] in q; ``launch`` is
    :func:`~warpsky.core.device.launch_rows` (rows in parallel bands on the CPU). ``mark(m)``, when given, marks
    the texels the frame will read (:func:`map_mark`) and only those are computed; without it every texel is."""
    sun = np.asarray(sun_dir, dtype=np.float64)
    if sun[1] <= float(MIN_SUN_SINE) or not (texel > 0.0 and math.isfinite(texel)) or hf.present == 0:
        return off_map(device)
    levels, n = map_shape(texel, texels, reach)
    m = DeckShadowMap()
    m.on, m.levels, m.texels, m.texel, m.plane = 1, levels, n, float(texel), float(plane)
    m.centre = wp.vec2(float(sun[0] * plane / sun[1]), float(sun[2] * plane / sun[1]))
    m.transmittance = wp.zeros((levels * n, n), dtype=wp.vec3, device=device)
    if mark is None:
        m.marks = wp.ones((levels * n, n), dtype=wp.int32, device=device)
    else:
        m.marks = wp.zeros((levels * n, n), dtype=wp.int32, device=device)
        mark(m)
    launch(shadow_map_kernel, levels * n, n, [hf, m, wp.vec3(*sun.tolist())], device)
    return m
