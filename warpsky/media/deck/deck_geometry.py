"""Max's height-field clouds on the device: the surfaces, inside tests, ray intervals and exact optical depths.

Kernels work relative to the camera: the host re-expands the quadratic about the eye and folds the eye's offset
from the pattern origin and the time into each wave's phase, both in float64, so a deck 100 km from the origin is
evaluated with the same float32 precision as one at the origin.

Interval finding. With yr = y - H, a point lies inside the cloud exactly when

    S(p) = f(x, z) - level(yr) > 0,   level(yr) = sqrt(c^2 + yr^2) - c                      (yr >= 0, g > yr)
                                      level(yr) = c (sqrt((1 + q) / (1 - q)) - 1), q = (yr/D)^2  (yr < 0, h < yr)

(level inverts g above the plane and h below it; level = +inf for yr <= -D). Along a ray x(t) = o + t d the speed
of S is bounded by |dS/dt| <= |grad poly . d_xz| + sum_i |a_i| |k_i . d_xz| + |level'(yr)| |d_y|, where the
polynomial's directional derivative is affine in t and |level'| grows with |yr| on each side of the plane, so
over a step both bounds are their largest at one of its ends. From a point where S has one sign no crossing can
come within |S| / L (L that bound over the step): the march steps that far (at least ``min_step``), and a sign
change is refined by bisection to ``tolerance``. Accuracy: every crossing found is exact to ``tolerance`` [m]; a
piece of cloud (or a gap in it) is missed only when the ray's chord through it is shorter than ``min_step`` [m].
The march is confined to the band [H + h(f_max), H + g(f_max)] the deck lies in.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.core.errors import UsageError
from warpsky.media.voxels.voxel import slab_interval
from warpsky.model.deck import CloudDeck, surface_heights
from warpsky.model.scene import PhaseKind, PhaseModel, Scene, VoxelMedium

#: A stand-in for +infinity in float32 kernels (level() below -D, lengths of unbounded rays).
HF_INFINITY = wp.constant(1.0e30)
#: Marching steps one interval search may take before it gives up (the rest of the ray counts as clear).
HF_MAX_STEPS = wp.constant(100000)
#: Optical depth beyond which exp(-tau) is 0 in float32 (exp(-104) is below the smallest denormal).
OPAQUE_DEPTH = 104.0


@wp.struct
class HeightField:
    """One height-field cloud deck relative to the camera (built by :func:`deck_struct`)."""

    poly_linear: wp.vec3  # c0 [m], cx, cz [--] of the quadratic about the eye
    poly_quadratic: wp.vec3  # cxx, cxz, czz [1/m]
    waves: wp.array(dtype=wp.vec4)  # (kx, kz) [rad/m], amplitude [m], phase at the eye and time [rad]
    wave_count: int
    cap: float  # f is clamped to at most this [m]
    mean: float  # H minus the eye's y [m]
    rounding: float  # c [m]
    bottom_depth: float  # D [m]
    band_low: float  # lowest cloud base minus the eye's y [m]
    band_high: float  # highest cloud top minus the eye's y [m]
    present: int  # 1 when any cloud exists (f_max > 0)
    extinction: wp.vec3  # [1/m] RGB
    scattering: wp.vec3  # extinction * albedo [1/m] RGB
    g: float  # HG asymmetry
    min_step: float  # smallest march step [m]: shorter chords may be missed
    tolerance: float  # bisection tolerance on crossings [m]
    max_length: float  # longest ray searched [m] (a sun ray along the band)
    opaque_length: float  # cloud length whose optical depth underflows in every channel [m]


@wp.struct
class HazeSlab:
    """The haze below the deck relative to the camera (built by :func:`haze_struct`)."""

    extinction: wp.vec3  # [1/m] RGB
    scattering: wp.vec3  # [1/m] RGB
    g: float
    floor: float  # slab bottom minus the eye's y [m]
    top: float  # slab top minus the eye's y [m]
    present: int


# ------------------------------------------------------------------------------------------------ surfaces
@wp.func
def hf_f(hf: HeightField, p: wp.vec3) -> float:
    """Pattern value f [m] at the camera-relative point ``p`` (its x and z), clamped to the cap."""
    x = p[0]
    z = p[2]
    q = hf.poly_quadratic
    f = hf.poly_linear[0] + hf.poly_linear[1] * x + hf.poly_linear[2] * z + q[0] * x * x + q[1] * x * z + q[2] * z * z
    for i in range(hf.wave_count):
        w = hf.waves[i]
        f += w[2] * wp.sin(w[0] * x + w[1] * z + w[3])
    return wp.min(f, hf.cap)


@wp.func
def hf_top(hf: HeightField, f: float) -> float:
    """g(f) [m] above the mean plane: sign(f) sqrt(|f| (|f| + 2c)); 0 at f = 0 with infinite slope."""
    a = wp.abs(f)
    return wp.sign(f) * wp.sqrt(a) * wp.sqrt(a + 2.0 * hf.rounding)


@wp.func
def hf_bottom(hf: HeightField, f: float) -> float:
    """h(f) [m] relative to the mean plane: -D g / sqrt((|f| + c)^2 + c^2); -> -D as f -> infinity."""
    a = wp.abs(f) + hf.rounding
    return -hf.bottom_depth * hf_top(hf, f) / wp.sqrt(a * a + hf.rounding * hf.rounding)


@wp.func
def hf_level(hf: HeightField, yr: float) -> float:
    """The pattern value a point ``yr`` [m] above the mean plane needs to lie inside the cloud (written without
    cancellation near yr = 0); HF_INFINITY at or below -D."""
    c = hf.rounding
    if yr >= 0.0:
        return yr * yr / (wp.sqrt(c * c + yr * yr) + c)
    if yr <= -hf.bottom_depth:
        return HF_INFINITY
    q = (yr / hf.bottom_depth) * (yr / hf.bottom_depth)
    ratio = (1.0 + q) / (1.0 - q)
    return c * (2.0 * q / (1.0 - q)) / (wp.sqrt(ratio) + 1.0)


@wp.func
def hf_level_slope(hf: HeightField, yr: float) -> float:
    """|d level / d yr| at ``yr`` [m] (< 1 above the plane, growing without bound towards -D)."""
    c = hf.rounding
    if yr >= 0.0:
        return yr / wp.sqrt(c * c + yr * yr)
    if yr <= -hf.bottom_depth:
        return HF_INFINITY
    q = (yr / hf.bottom_depth) * (yr / hf.bottom_depth)
    return c / ((1.0 - q) * wp.sqrt((1.0 - q) * (1.0 + q))) * 2.0 * wp.abs(yr) / (hf.bottom_depth * hf.bottom_depth)


@wp.func
def hf_signed(hf: HeightField, p: wp.vec3) -> float:
    """S(p) = f - level(y - H): > 0 exactly inside the cloud."""
    return hf_f(hf, p) - hf_level(hf, p[1] - hf.mean)


@wp.func
def hf_inside(hf: HeightField, p: wp.vec3) -> bool:
    """Whether the camera-relative point ``p`` lies inside the cloud (f > 0 and h < y - H < g)."""
    f = hf_f(hf, p)
    yr = p[1] - hf.mean
    return f > 0.0 and yr < hf_top(hf, f) and yr > hf_bottom(hf, f)


@wp.func
def hf_column_above(hf: HeightField, p: wp.vec3) -> float:
    """Cloud length [m] straight up from ``p``: g - max(y - H, h) in its column (0 where the column is clear)."""
    f = hf_f(hf, p)
    if f <= 0.0:
        return 0.0
    yr = p[1] - hf.mean
    return wp.max(hf_top(hf, f) - wp.max(yr, hf_bottom(hf, f)), 0.0)


# ------------------------------------------------------------------------------------------------ intervals
@wp.func
def hf_ray_slope(hf: HeightField, d: wp.vec3) -> float:
    """sum_i |a_i| |k_i . d_xz|: the waves' bound on |df/dt| along direction ``d`` [m/m]."""
    s = float(0.0)
    for i in range(hf.wave_count):
        w = hf.waves[i]
        s += wp.abs(w[2] * (w[0] * d[0] + w[1] * d[2]))
    return s


@wp.func
def hf_speed_bound(hf: HeightField, o: wp.vec3, d: wp.vec3, wave_slope: float, ta: float, tb: float) -> float:
    """Bound on |dS/dt| over [ta, tb] of the ray o + t d (module docstring)."""
    q = hf.poly_quadratic
    pa = o + ta * d
    pb = o + tb * d
    ga = (hf.poly_linear[1] + 2.0 * q[0] * pa[0] + q[1] * pa[2]) * d[0]
    ga += (hf.poly_linear[2] + q[1] * pa[0] + 2.0 * q[2] * pa[2]) * d[2]
    gb = (hf.poly_linear[1] + 2.0 * q[0] * pb[0] + q[1] * pb[2]) * d[0]
    gb += (hf.poly_linear[2] + q[1] * pb[0] + 2.0 * q[2] * pb[2]) * d[2]
    level = wp.max(hf_level_slope(hf, pa[1] - hf.mean), hf_level_slope(hf, pb[1] - hf.mean))
    return wp.max(wp.abs(ga), wp.abs(gb)) + wave_slope + level * wp.abs(d[1]) + 1.0e-12


@wp.func
def hf_crossing(hf: HeightField, o: wp.vec3, d: wp.vec3, wave_slope: float, t: float, t_end: float,
                want_inside: bool) -> float:
    """First t' in (t, t_end] where the ray is inside (``want_inside``) or outside the cloud, refined to the
    tolerance (the returned point lies on the wanted side); ``t_end`` when there is none."""
    s = hf_signed(hf, o + t * d)
    steps = int(0)
    while t < t_end and steps < HF_MAX_STEPS:
        steps += 1
        margin = wp.abs(s)
        trial = wp.max(margin / hf_speed_bound(hf, o, d, wave_slope, t, t), hf.min_step)
        step = wp.max(margin / hf_speed_bound(hf, o, d, wave_slope, t, wp.min(t + trial, t_end)), hf.min_step)
        tn = wp.min(t + step, t_end)
        sn = hf_signed(hf, o + tn * d)
        if (sn > 0.0) == want_inside:
            lo = t
            hi = tn
            for _ in range(40):
                if hi - lo <= hf.tolerance:
                    break
                mid = 0.5 * (lo + hi)
                if (hf_signed(hf, o + mid * d) > 0.0) == want_inside:
                    hi = mid
                else:
                    lo = mid
            return hi
        t = tn
        s = sn
    return t_end


@wp.func
def hf_band_span(hf: HeightField, o: wp.vec3, d: wp.vec3, t0: float, t1: float) -> wp.vec2:
    """The part of [t0, t1] where the ray lies in the deck's band (empty: x >= y)."""
    if hf.present == 0:
        return wp.vec2(t1, t1)
    return slab_interval(o[1], d[1], hf.band_low, hf.band_high, t0, t1)


@wp.func
def hf_next_interval(hf: HeightField, o: wp.vec3, d: wp.vec3, wave_slope: float, t0: float, t1: float) -> wp.vec2:
    """The first piece [a, b] of cloud on the ray o + t d within [t0, t1] (a >= t0; a ray starting inside gets
    a = t0); (t1, t1) when there is none. ``wave_slope`` is :func:`hf_ray_slope` of ``d``."""
    span = hf_band_span(hf, o, d, t0, t1)
    if span[0] >= span[1]:
        return wp.vec2(t1, t1)
    a = span[0]
    if hf_signed(hf, o + a * d) <= 0.0:
        a = hf_crossing(hf, o, d, wave_slope, a, span[1], True)
        if a >= span[1]:
            return wp.vec2(t1, t1)
    b = hf_crossing(hf, o, d, wave_slope, a, span[1], False)
    return wp.vec2(a, b)


@wp.func
def hf_cloud_length(hf: HeightField, o: wp.vec3, d: wp.vec3, t0: float, t1: float) -> float:
    """Length [m] of the ray o + t d, t in [t0, t1], inside the cloud (exact to the crossing tolerance per
    crossing); the search stops once the length is opaque in every channel (``opaque_length``)."""
    slope = hf_ray_slope(hf, d)
    total = float(0.0)
    t = t0
    while t < t1 and total < hf.opaque_length:
        piece = hf_next_interval(hf, o, d, slope, t, t1)
        if piece[0] >= t1:
            break
        total += piece[1] - piece[0]
        t = piece[1] + hf.tolerance
    return total


@wp.func
def hf_optical_depth(hf: HeightField, o: wp.vec3, d: wp.vec3, t0: float, t1: float) -> wp.vec3:
    """Cloud optical depth (RGB) along o + t d from t0 to t1: extinction times :func:`hf_cloud_length`."""
    return hf.extinction * hf_cloud_length(hf, o, d, t0, t1)


@wp.func
def haze_path(haze: HazeSlab, p: wp.vec3, d: wp.vec3) -> float:
    """Length [m] of the ray from ``p`` along ``d`` inside the haze slab (HF_INFINITY for a level ray in it)."""
    if haze.present == 0:
        return 0.0
    span = slab_interval(p[1], d[1], haze.floor, haze.top, 0.0, HF_INFINITY)
    return wp.max(span[1] - span[0], 0.0)


@wp.func
def haze_above(haze: HazeSlab, p: wp.vec3) -> float:
    """Length [m] of haze straight above ``p``."""
    if haze.present == 0:
        return 0.0
    return wp.max(haze.top - wp.max(p[1], haze.floor), 0.0)


# ------------------------------------------------------------------------------------------------------ host
def feature_length(clouds: CloudDeck) -> float:
    """The pattern's smallest horizontal feature [m]: the shortest wavelength, the equator's rounding c, and the
    polynomial's curvature length sqrt(f_max / |curvature|), whichever is least."""
    lengths = [clouds.rounding]
    k = np.linalg.norm(clouds.wave_vectors, axis=1) if len(clouds.wave_vectors) else np.zeros(0)
    lengths += [2.0 * math.pi / v for v in k if v > 0.0]
    cxx, cxz, czz = clouds.polynomial[3:]
    curvature = float(np.max(np.abs(np.linalg.eigvalsh(np.array([[2 * cxx, cxz], [cxz, 2 * czz]])))))
    if curvature > 0.0:
        lengths.append(math.sqrt(max(abs(clouds.pattern_peak), clouds.rounding) / curvature))
    return float(min(lengths))


def eye_polynomial(clouds: CloudDeck, eye_xz: np.ndarray) -> np.ndarray:
    """The quadratic's 6 coefficients re-expanded about ``eye_xz`` (world x, z [m]), in float64."""
    c0, cx, cz, cxx, cxz, czz = clouds.polynomial
    ex, ez = float(eye_xz[0]) - clouds.origin[0], float(eye_xz[1]) - clouds.origin[1]
    value = c0 + cx * ex + cz * ez + cxx * ex * ex + cxz * ex * ez + czz * ez * ez
    return np.array([value, cx + 2 * cxx * ex + cxz * ez, cz + cxz * ex + 2 * czz * ez, cxx, cxz, czz])


def wave_table(clouds: CloudDeck, about_xz, time_s: float) -> np.ndarray:
    """(waves, 4) float64 rows (kx, kz [rad/m], amplitude [m], phase [rad]) of ``clouds``' waves at ``time_s`` [s],
    their phases taken about world (x, z) ``about_xz`` [m] (so that offsets from that point enter the sines small);
    one row of zeros without waves."""
    k = np.asarray(clouds.wave_vectors, dtype=np.float64).reshape(-1, 2)
    if not len(k):
        return np.zeros((1, 4))
    ex, ez = float(about_xz[0]) - clouds.origin[0], float(about_xz[1]) - clouds.origin[1]
    phases = np.mod(np.asarray(clouds.phases) + k[:, 0] * ex + k[:, 1] * ez - np.asarray(clouds.speeds) * time_s,
                    2.0 * math.pi)
    return np.column_stack([k, clouds.amplitudes, phases])


def deck_struct(clouds: CloudDeck, camera_position, time_s: float, device, *,
                       max_length: float = 1.0e6) -> HeightField:
    """Kernel view of ``clouds`` at ``time_s`` [s] seen from ``camera_position`` (world [m], float64); sun rays
    and other searches stop after ``max_length`` [m]. Marching resolution: ``min_step`` = 1/64 of
    :func:`feature_length`, crossings bisected to 1e-3 of that."""
    eye = np.asarray(camera_position, dtype=np.float64)
    poly = eye_polynomial(clouds, eye[[0, 2]])
    out = HeightField()
    out.poly_linear = wp.vec3(*poly[:3].tolist())
    out.poly_quadratic = wp.vec3(*poly[3:].tolist())
    out.waves = wp.array(wave_table(clouds, eye[[0, 2]], time_s).astype(np.float32), dtype=wp.vec4, device=device)
    out.wave_count = int(len(clouds.wave_vectors))
    out.cap = float(min(clouds.pattern_cap, 1.0e30))
    out.mean = float(clouds.mean_altitude - eye[1])
    out.rounding = float(clouds.rounding)
    out.bottom_depth = float(clouds.bottom_depth)
    low, high = clouds.band
    out.band_low = float(low - eye[1])
    out.band_high = float(high - eye[1])
    out.present = int(clouds.pattern_peak > 0.0 and high > low)
    out.extinction = wp.vec3(*clouds.extinction.tolist())
    out.scattering = wp.vec3(*(clouds.extinction * clouds.albedo).tolist())
    out.g = float(clouds.g)
    out.min_step = feature_length(clouds) / 64.0
    out.tolerance = out.min_step * 1.0e-3
    out.max_length = float(max_length)
    weakest = float(np.min(clouds.extinction))
    out.opaque_length = OPAQUE_DEPTH / weakest if weakest > 0.0 else 1.0e30
    return out


def haze_struct(clouds: CloudDeck, camera_position) -> HazeSlab:
    """Kernel view of the haze below ``clouds`` seen from ``camera_position`` (a zero slab without haze)."""
    out = HazeSlab()
    eye_y = float(np.asarray(camera_position, dtype=np.float64)[1])
    haze = clouds.haze
    out.present = int(haze is not None)
    density = haze.density if haze is not None else np.zeros(3)
    out.extinction = wp.vec3(*density.tolist())
    out.scattering = wp.vec3(*(density * (haze.albedo if haze is not None else 0.0)).tolist())
    out.g = float(haze.g) if haze is not None else 0.0
    out.floor = float(haze.floor - eye_y) if haze is not None else 0.0
    out.top = float(max(clouds.haze_top, haze.floor) - eye_y) if haze is not None else 0.0
    return out


def voxelize(clouds: CloudDeck, bounds, shape, *, time_s: float = 0.0, supersample: int = 4) -> VoxelMedium:
    """The cloud as a :class:`~warpsky.model.scene.VoxelMedium` over the world box ``bounds`` ((x0, y0, z0),
    (x1, y1, z1)) [m] with ``shape`` (nx, ny, nz) voxels: each voxel holds the fraction of its volume inside the
    cloud (``supersample``^3 points per voxel), extinction_scale rho * extinction_scale, the cloud's albedo and HG
    phase. The haze is not included."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    n = np.asarray(shape, dtype=int)
    size = (hi - lo) / n
    offsets = (np.arange(supersample) + 0.5) / supersample
    axes = [lo[a] + (np.arange(n[a])[:, None] + offsets[None, :]).reshape(-1) * size[a] for a in range(3)]
    x, z = np.meshgrid(axes[0], axes[2], indexing="ij")
    f = clouds.pattern(x, z, time_s)
    g, h = surface_heights(f, clouds.rounding, clouds.bottom_depth)
    y = axes[1][None, :, None] - clouds.mean_altitude
    inside = (f[:, None, :] > 0.0) & (y > h[:, None, :]) & (y < g[:, None, :])
    s = supersample
    fraction = inside.reshape(n[0], s, n[1], s, n[2], s).mean(axis=(1, 3, 5))
    world_from_index = np.eye(4)
    world_from_index[:3, :3] = np.diag(size)
    world_from_index[:3, 3] = lo + 0.5 * size
    return VoxelMedium(f"{clouds.name} (voxelized)", fraction.astype(np.float32), world_from_index,
                       clouds.extinction, clouds.albedo, PhaseModel(PhaseKind.HG, clouds.g))


# ------------------------------------------------------------------------------------------- probes (tests, tools)
@wp.kernel
def hf_probe_kernel(hf: HeightField, points: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec4)):
    """(f, g, h, inside) at camera-relative ``points``."""
    i = wp.tid()
    f = hf_f(hf, points[i])
    out[i] = wp.vec4(f, hf_top(hf, f), hf_bottom(hf, f), wp.where(hf_inside(hf, points[i]), 1.0, 0.0))


@wp.kernel
def hf_intervals_kernel(hf: HeightField, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                        t_max: float, pieces: wp.array2d(dtype=wp.vec2), counts: wp.array(dtype=int),
                        lengths: wp.array(dtype=float)):
    """The cloud pieces of each ray origin + t direction, t in [0, t_max] (at most ``pieces.shape[1]`` kept),
    their count and :func:`hf_cloud_length`."""
    i = wp.tid()
    o = origins[i]
    d = directions[i]
    slope = hf_ray_slope(hf, d)
    t = float(0.0)
    n = int(0)
    while t < t_max:
        piece = hf_next_interval(hf, o, d, slope, t, t_max)
        if piece[0] >= t_max:
            break
        if n < pieces.shape[1]:
            pieces[i, n] = piece
        n += 1
        t = wp.max(piece[1], piece[0] + hf.tolerance)
    counts[i] = n
    lengths[i] = hf_cloud_length(hf, o, d, 0.0, t_max)


def probe(clouds: CloudDeck, points, camera_position, time_s: float, device) -> np.ndarray:
    """(N, 4) f, g, h [m] and inside (0/1) at world ``points`` as the kernels evaluate them."""
    eye = np.asarray(camera_position, dtype=np.float64)
    rel = wp.array((np.asarray(points, np.float64).reshape(-1, 3) - eye).astype(np.float32), dtype=wp.vec3,
                   device=device)
    out = wp.zeros(rel.shape[0], dtype=wp.vec4, device=device)
    wp.launch(hf_probe_kernel, dim=rel.shape[0], inputs=[deck_struct(clouds, eye, time_s, device), rel, out],
              device=device)
    return out.numpy()


def ray_intervals(clouds: CloudDeck, origins, directions, t_max: float, time_s: float, device, *,
                  max_pieces: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pieces (N, max_pieces, 2), counts (N,), cloud lengths (N,)) of rays from world ``origins`` along unit
    ``directions`` up to ``t_max`` [m], found by the kernels' interval search (relative to the first origin)."""
    origins = np.asarray(origins, np.float64).reshape(-1, 3)
    eye = origins[0]
    rel = wp.array((origins - eye).astype(np.float32), dtype=wp.vec3, device=device)
    dirs = wp.array(np.asarray(directions, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)
    pieces = wp.zeros((len(origins), max_pieces), dtype=wp.vec2, device=device)
    counts = wp.zeros(len(origins), dtype=int, device=device)
    lengths = wp.zeros(len(origins), dtype=float, device=device)
    wp.launch(hf_intervals_kernel, dim=len(origins), inputs=[deck_struct(clouds, eye, time_s, device), rel,
                                                             dirs, float(t_max), pieces, counts, lengths],
              device=device)
    return pieces.numpy(), counts.numpy(), lengths.numpy()


def the_deck(scene: Scene) -> CloudDeck | None:
    """The scene's one height-field deck (None without); more than one is refused."""
    decks = scene.decks
    if len(decks) > 1:
        raise UsageError(f"one height-field deck per scene is rendered, got {len(decks)}: "
                         f"{', '.join(d.name for d in decks)}")
    return decks[0] if decks else None
