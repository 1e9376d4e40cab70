"""Kernels of half-angle slicing with multiple-scattering phase functions (Riley 2004 §4.2, §5; Kniss et al.).

Positions are camera-relative metres. Slices are the planes dot(s, x) = c_k perpendicular to the slice axis s; the
host walks them in increasing c, which always moves away from the sun. Per slice, the eye composites the slice's
slab (half a spacing either side of its plane) into the eye buffer (front to back or back to front, Eq. 26) reading
the light buffer as it reaches that plane, and the light buffer is carried on to the next slice (Eq. 25). The eye
samples each slab's piece of its ray, cut to the media's boxes, at a fraction of a voxel: one sample per plane
would count a thin sheet in whole slices, a count that changes from one image row to the next. The light buffer
is a square grid in the plane perpendicular to the light, so a texel follows its own light ray from slice to slice
(no resampling) and no texel reads another.

That independence lets the sweep run in chunks of planes rather than slice by slice: :func:`slice_light_kernel`
carries each texel through a chunk's planes, keeping a copy of the buffer at every plane, then
:func:`slice_eye_kernel` composites every pixel through the chunk's slabs, each reading its plane's copy. The
arithmetic per texel and per pixel is the same, in the same order, as alternating one eye step and one light step
per slice; the frame takes two launches per chunk instead of two per slice, and each launch is large enough to
split over CPU cores.

Every medium has a table of multiple-scattering distributions Ams_n (n = 0..N) and forward fractions F_n: species
from :mod:`warpsky.optics.tables`, analytic phases in closed form (HG(g)^{*n} = HG(g^n)). Several media at a
point mix their Ams and F by scattering weight (Riley Eq. 6 applied per order).

The sky (the dome, the analytic sky of a frame with a sky pass, the ground they light: :mod:`warpsky.techniques.
skylight`) lights the media as an environment on two spherical-harmonic bands per hemisphere: each eye sample adds
S(v) = T_up max(0, m_up + 3 g M_up . v) + T_down max(0, m_down + 3 g M_down . v), g mixed over the media at the
sample by scattering weight, times its scattering integrated over the sample, (1 - e^-tau) albedo. T_up and T_down
are the media's transmittances straight up and down from the sample, interpolated from a grid of column optical
depths computed once per frame (:mod:`~warpsky.techniques.slicing.occlusion`), as the march takes them per sample.
With ``skylight`` off the dome's mean radiance lights every sample unoccluded (the white furnace's answer for an
albedo-1 medium; too bright deep inside thick clouds). The ground reflects albedo E / pi of the sky above it,
occluded towards the zenith.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import bilinear_cell, bilinear_mix, exp3, one_minus_exp
from warpsky.light.skylight import AmbientLobes, SkyEnvironment, ambient_inscatter, ambient_lobes, mixed_asymmetry
from warpsky.light.sun import Sun
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia, media_functions, media_span
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.optics.kernels import scattering_angle
from warpsky.optics.oriented_phase import OrientedPhases
from warpsky.techniques.slicing.ams import AmsTables, mixed_ams_scattering, mixed_forward, oriented_ams_correction
from warpsky.techniques.slicing.occlusion import SkyShadow, sky_transmittances


@wp.struct
class SliceFrame:
    """Geometry of the slicing pass (camera-relative)."""

    axis: wp.vec3  # slice normal s
    light_dir: wp.vec3  # direction light travels (-sun)
    light_u: wp.vec3  # light-buffer axes, perpendicular to light_dir
    light_v: wp.vec3
    light_origin: wp.vec3  # light-space origin (corner of the light buffer's square, on the plane c = 0)
    light_size: float  # edge of the light buffer's square [m]
    light_res: int
    spacing: float  # distance between slices along s [m]
    front_to_back: int  # 1: the eye composites front to back; 0: back to front


@wp.func
def light_texel(frame: SliceFrame, p: wp.vec3) -> wp.vec2:
    """Continuous light-buffer coordinates (texel units) of point p."""
    rel = p - frame.light_origin
    scale = float(frame.light_res) / frame.light_size
    return wp.vec2(wp.dot(rel, frame.light_u) * scale - 0.5, wp.dot(rel, frame.light_v) * scale - 0.5)


@wp.func
def light_lookup(buffer: wp.array2d(dtype=wp.vec3), frame: SliceFrame, p: wp.vec3) -> wp.vec3:
    """Bilinear light-buffer value at p (clamped at the edges)."""
    cell = bilinear_cell(light_texel(frame, p), wp.vec2i(frame.light_res, frame.light_res))
    lo = cell.lo
    hi = cell.hi
    return bilinear_mix(buffer[lo[1], lo[0]], buffer[lo[1], hi[0]], buffer[hi[1], lo[0]], buffer[hi[1], hi[0]],
                        cell.frac)


#: Most samples of the eye ray inside one slice's slab (bounds the cost of few, thick slices).
MAX_EYE_SAMPLES = wp.constant(64)

#: Scattering events of one light step evaluated one by one; the rest use the last order's forward fraction.
MAX_EVENTS = wp.constant(64)


@wp.func
def light_attenuated(point: MediaPoint, media: VoxelMedia, tables: AmsTables, intensity: float, n: float,
                     tau: float, c: int) -> float:
    """Low-albedo mode (Riley Fig. 13): the light buffer is attenuated by extinction, nothing scattered is kept."""
    return intensity * wp.exp(-tau)


@wp.func
def light_continuous(point: MediaPoint, media: VoxelMedia, tables: AmsTables, intensity: float, n: float,
                     tau: float, c: int) -> float:
    """Channel ``c`` of the light after a step of optical depth ``tau`` by the limit both of Riley's equations
    discretise: dI/dtau = -(1 - alpha F_{n+1}) I while n grows by alpha per unit optical depth, integrated over the
    step by the midpoint rule on <= 64 chunks (exact for thin steps to O(tau^3): second order in the slice
    spacing). It is also the expectation of (alpha F)^K over a Poisson number K of scattering events, where Eq. 24
    takes K = ceil(tau)."""
    if point.extinction[c] <= 0.0:
        return intensity * wp.exp(-tau)
    chunks = int(wp.ceil(wp.min(tau, float(MAX_EVENTS))))
    chunk = tau / float(chunks)
    albedo = point.scattering[c] / point.extinction[c]
    exponent = float(0.0)
    for e in range(chunks):
        order = n + 1.0 + albedo * chunk * (float(e) + 0.5)
        exponent += (1.0 - mixed_forward(point, media, tables, order, c)) * chunk
    return intensity * wp.exp(-exponent)


@wp.func
def light_riley24(point: MediaPoint, media: VoxelMedia, tables: AmsTables, intensity: float, n: float,
                  tau: float, c: int) -> float:
    """Riley Eq. 24: the light scattered within the step keeps, per scattering event, its forward part alpha F_i,
    over ceil(beta Delta) events n+1 .. n+ceil(tau) (first order in the slice spacing; beyond 64 events the rest
    share the last one's factor)."""
    kept = float(0.0)
    if point.scattering[c] > 0.0:
        events = int(wp.ceil(wp.min(tau, 1.0e6)))
        first = n + 1.0
        log_kept = float(0.0)
        for e in range(wp.min(events, MAX_EVENTS)):
            log_kept += wp.log(wp.max(mixed_forward(point, media, tables, first + float(e), c), 1.0e-30))
        if events > MAX_EVENTS:
            last = mixed_forward(point, media, tables, first + float(MAX_EVENTS - 1), c)
            log_kept += float(events - MAX_EVENTS) * wp.log(wp.max(last, 1.0e-30))
        kept = one_minus_exp(tau) * wp.exp(log_kept)
    return intensity * (wp.exp(-tau) + kept)


@wp.func
def light_riley25(point: MediaPoint, media: VoxelMedia, tables: AmsTables, intensity: float, n: float,
                  tau: float, c: int) -> float:
    """Riley Eq. 25, his GPU shortcut: the scattered light keeps (alpha F)^(beta Delta). It loses only O(Delta^2)
    per step against Eq. 24, so it tends to no attenuation as slices are added instead of converging."""
    kept = float(0.0)
    if point.scattering[c] > 0.0:
        alpha_f = wp.clamp(mixed_forward(point, media, tables, n + 1.0 + tau, c), 0.0, 1.0)
        if alpha_f > 0.0:
            kept = one_minus_exp(tau) * wp.exp(tau * wp.log(alpha_f))
    return intensity * (wp.exp(-tau) + kept)


def light_update(low_albedo: bool, equation: int):
    """The light-buffer update of one channel for the slicing settings (see :func:`slicing_kernels`)."""
    if low_albedo:
        return light_attenuated
    return {0: light_continuous, 24: light_riley24, 25: light_riley25}[equation]


def slicing_kernels(low_albedo: bool, equation: int = 0, has_detail: bool = False, has_dome: bool = False):
    """(eye_kernel, light_kernel), specialised on Riley's low-albedo comparison mode (Fig. 13: Ams_1 only, light
    attenuated by extinction, no multiple scattering), on the light-buffer update: 0, the continuous limit of
    Riley's model solved per step (second order in the slice spacing); Riley's Eq. 24 (per-event forward
    fractions, first order) or Eq. 25 (his GPU shortcut (alpha F)^(beta Delta), which does not converge); and on
    whether any medium has animated detail (without it the samplers never touch ``details``); the eye kernel also
    on ambient light (a dome or sky light)."""
    return slice_eye_kernel(low_albedo, has_detail, has_dome), slice_light_kernel(low_albedo, equation, has_detail)


@wp.struct
class EyeBuffers:
    """The eye's accumulators over the image (height, width)."""

    radiance: wp.array2d(dtype=wp.vec3)  # radiance towards the eye, RGB
    transmittance: wp.array2d(dtype=wp.vec3)  # transmittance of the media along the eye ray, RGB
    depth_sum: wp.array2d(dtype=wp.vec2)  # (sum of weight * depth [m], sum of weight)
    spans: wp.array2d(dtype=wp.vec2)  # each eye ray's interval [m] inside the media's boxes


@wp.struct
class LightBuffers:
    """The light buffer (res, res) as it leaves the last slice done, and its copies at each slice plane of the
    chunk of planes being swept (chunk, res, res)."""

    intensity: wp.array2d(dtype=wp.vec3)  # irradiance, RGB
    count: wp.array2d(dtype=wp.vec3)  # expected scattering count, RGB
    stack_intensity: wp.array3d(dtype=wp.vec3)
    stack_count: wp.array3d(dtype=wp.vec3)


@wp.struct
class PlaneRange:
    """Slice planes ``first .. first + count - 1`` of the sweep, positions along the slice axis [m] in sweep
    order; ``entry``: the chunk starts the sweep (the light first enters the media's extent)."""

    planes: wp.array(dtype=float)
    first: int
    count: int
    entry: int


@functools.cache
def gather_function(low_albedo: bool, has_detail: bool = False, has_dome: bool = False):
    """``gather_sample(...) -> (vec3, vec3)``, one sample of the eye gather, specialised as
    :func:`slice_eye_kernel` is."""

    sample_media = media_functions(has_detail)

    @wp.func
    def gather_sample(media: VoxelMedia, tables: AmsTables, oriented: OrientedPhases, shadow: SkyShadow,
                      frame: SliceFrame, light_i: wp.array2d(dtype=wp.vec3), light_n: wp.array2d(dtype=wp.vec3),
                      p: wp.vec3, view: wp.vec3, theta: float, length: float, ambient: AmbientLobes,
                      asymmetry: wp.array(dtype=wp.vec3)):
        """(light scattered towards the eye, optical depth), RGB, of the piece of the eye ray of ``length`` [m]
        centred on ``p``."""
        point = sample_media(media, p)
        extinction = point.extinction
        scattering = point.scattering
        tau = extinction * length
        out = wp.vec3(0.0)
        if wp.max(extinction) <= 0.0:
            return out, tau
        light = light_lookup(light_i, frame, p)
        n = light_lookup(light_n, frame, p)
        # Riley Eq. 26: Ams of one more scattering than the light has had, mixed over media by scattering
        order = wp.vec3(n[0] + 1.0, n[1] + 1.0, n[2] + 1.0)
        if wp.static(low_albedo):
            order = wp.vec3(1.0)
        phase = mixed_ams_scattering(point, media, tables, order, theta)
        phase += oriented_ams_correction(point, media, tables, oriented, order, view, theta)
        sky = wp.vec3(0.0)
        if wp.static(has_dome):
            t_up, t_down = sky_transmittances(shadow, p)
            sky = ambient_inscatter(ambient, mixed_asymmetry(media, point, asymmetry), t_up, t_down)
        for c in range(3):
            if scattering[c] > 0.0:
                p_c = phase[c] / scattering[c]  # xi included, per medium
                # scattering integrated exactly over the piece: (1 - e^-tau) albedo instead of beta_s * length
                out[c] = light[c] * p_c * (scattering[c] / extinction[c]) * one_minus_exp(tau[c])
                if wp.static(has_dome):
                    out[c] = out[c] + sky[c] * (scattering[c] / extinction[c]) * one_minus_exp(tau[c])
        return out, tau

    return gather_sample


@wp.struct
class EyePixel:
    """One pixel's eye accumulators (see :class:`EyeBuffers`)."""

    radiance: wp.vec3
    transmittance: wp.vec3
    depth_sum: wp.vec2


@wp.func
def composite_slab(frame: SliceFrame, pixel: EyePixel, contribution: wp.vec3, keep: wp.vec3, t: float,
                   cos_axis: float) -> EyePixel:
    """``pixel`` with a slab composited in sweep order: ``contribution`` the light it sends towards the eye, ``keep``
    its transmittance, RGB, ``t`` [m] the distance along the eye ray to its plane, ``cos_axis`` the ray's cosine to
    the view axis (its depth is weighted by its opacity, front to back also by the transmittance before it)."""
    out = pixel
    before = pixel.transmittance
    if frame.front_to_back != 0:
        out.radiance = pixel.radiance + wp.cw_mul(before, contribution)
    else:
        out.radiance = wp.cw_mul(pixel.radiance, keep) + contribution
    out.transmittance = wp.cw_mul(before, keep)
    opacity = 1.0 - (keep[0] + keep[1] + keep[2]) / 3.0
    weight = opacity * (before[0] + before[1] + before[2]) / 3.0
    if frame.front_to_back == 0:
        weight = opacity
    out.depth_sum = pixel.depth_sum + wp.vec2(weight * t * cos_axis, weight)
    return out


@kernel_variants(low_albedo=(False, True), has_detail=(False, True), has_dome=(False, True))
@functools.cache
def slice_eye_kernel(low_albedo: bool, has_detail: bool = False, has_dome: bool = False):
    """The eye gather of a chunk of slices (see :func:`slicing_kernels`)."""

    gather_sample = gather_function(low_albedo, has_detail, has_dome)

    @wp.kernel(module="unique")
    def eye_kernel(
        media: VoxelMedia,
        tables: AmsTables,
        oriented: OrientedPhases,
        shadow: SkyShadow,
        cam: PinholeCamera,
        frame: SliceFrame,
        chunk: PlaneRange,
        light: LightBuffers,
        sun: Sun,
        sample_length: float,
        ambient: SkyEnvironment,
        eye: EyeBuffers,
        row_offset: int,
    ):
        """Composite the slabs of the chunk's slice planes (half a spacing either side of each), in sweep order,
        into the eye buffers (Riley Eq. 26), each reading the light buffer kept at its plane and sampling the
        pixel's eye ray inside the slab and inside its ``spans`` at most ``sample_length`` [m] apart."""
        r, col = wp.tid()
        row = r + row_offset
        ray = primary_ray(cam, row, col, 0.5, 0.5)
        view = ray.direction
        along = wp.dot(frame.axis, view)
        if wp.abs(along) < 1.0e-6:
            return
        half = 0.5 * frame.spacing / wp.abs(along)
        theta = scattering_angle(sun.direction, view)
        lobes = ambient_lobes(ambient, view)
        inside = eye.spans[row, col]
        pixel = EyePixel()
        pixel.radiance = eye.radiance[row, col]
        pixel.transmittance = eye.transmittance[row, col]
        pixel.depth_sum = eye.depth_sum[row, col]
        for k in range(chunk.count):
            t = chunk.planes[chunk.first + k] / along
            # the slab's piece of the eye ray, relative to the plane (an uncut slab's one sample lies on the plane)
            lo = wp.max(-half, inside[0] - t)
            hi = wp.min(half, inside[1] - t)
            if hi <= lo:
                continue
            count = wp.min(int(wp.ceil((hi - lo) / sample_length)), MAX_EYE_SAMPLES)
            length = (hi - lo) / float(count)
            contribution = wp.vec3(0.0)
            keep = wp.vec3(1.0)
            for s in range(count):  # front to back inside the slab
                p = view * (t + (lo + (float(s) + 0.5) * length))
                scattered, tau = gather_sample(media, tables, oriented, shadow, frame, light.stack_intensity[k],
                                               light.stack_count[k], p, view, theta, length, lobes,
                                               ambient.asymmetry)
                contribution += wp.cw_mul(keep, scattered)
                keep = wp.cw_mul(keep, exp3(tau))
            if keep[0] >= 1.0 and keep[1] >= 1.0 and keep[2] >= 1.0:
                continue
            pixel = composite_slab(frame, pixel, contribution, keep, t, ray.cos_axis)
        eye.radiance[row, col] = pixel.radiance
        eye.transmittance[row, col] = pixel.transmittance
        eye.depth_sum[row, col] = pixel.depth_sum

    return eye_kernel


@wp.kernel
def eye_span_kernel(media: VoxelMedia, cam: PinholeCamera, spans: wp.array2d(dtype=wp.vec2)):
    """Each pixel's eye-ray interval [m] inside the media's boxes and the clipping range (empty: y <= x). The eye
    gather samples only there, so a box face cuts a slab's samples where it lies instead of at whole samples."""
    row, col = wp.tid()
    ray = primary_ray(cam, row, col, 0.5, 0.5)  # a pinhole's: from the eye
    spans[row, col] = media_span(media, ray.origin, ray.direction, ray.t_near, ray.t_far)


@kernel_variants(low_albedo=(False, True), equation=(0, 24, 25), has_detail=(False, True))
@functools.cache
def slice_light_kernel(low_albedo: bool, equation: int = 0, has_detail: bool = False):
    """The light buffer carried through a chunk of slices (see :func:`slicing_kernels`)."""

    sample_media = media_functions(has_detail)
    carry_light = light_update(low_albedo, equation)

    @wp.func
    def carry(media: VoxelMedia, tables: AmsTables, frame: SliceFrame, base: wp.vec3, plane: float,
              advance: float, intensity: wp.vec3, n: wp.vec3):
        """(irradiance, scattering count) of the texel whose light ray passes ``base``, carried from the slice
        plane ``plane`` to ``plane + advance`` (along the slice axis)."""
        along = wp.dot(frame.axis, frame.light_dir)
        # the texel's light ray meets this slice at base + a l with dot(s, .) = plane; step to the next slice
        a = (plane - wp.dot(frame.axis, base)) / along
        step = advance / along
        point = sample_media(media, base + frame.light_dir * (a + 0.5 * step))
        extinction = point.extinction
        scattering = point.scattering
        if wp.max(extinction) <= 0.0:
            return intensity, n
        out = wp.vec3(0.0)
        count = n
        for c in range(3):
            tau = extinction[c] * step
            out[c] = carry_light(point, media, tables, intensity[c], n[c], tau, c)
            count[c] = n[c] + (scattering[c] / extinction[c]) * tau  # Eq. 22: n = -alpha ln T
        return out, count

    @wp.kernel(module="unique")
    def light_kernel(
        media: VoxelMedia,
        tables: AmsTables,
        frame: SliceFrame,
        chunk: PlaneRange,
        light: LightBuffers,
        row_offset: int,
    ):
        """Keep the texel's light at each of the chunk's slice planes and carry it through their slabs; the chunk
        that starts the sweep first carries the light from half a spacing before its first plane, where it enters
        the media's extent."""
        r, i = wp.tid()
        j = r + row_offset
        scale = frame.light_size / float(frame.light_res)
        base = frame.light_origin + frame.light_u * ((float(i) + 0.5) * scale) + frame.light_v * (
            (float(j) + 0.5) * scale)
        intensity = light.intensity[j, i]
        n = light.count[j, i]
        spacing = frame.spacing
        if chunk.entry != 0:
            intensity, n = carry(media, tables, frame, base, chunk.planes[chunk.first] - 0.5 * spacing,
                                 0.5 * spacing, intensity, n)
        for k in range(chunk.count):
            light.stack_intensity[k, j, i] = intensity
            light.stack_count[k, j, i] = n
            intensity, n = carry(media, tables, frame, base, chunk.planes[chunk.first + k], spacing, intensity, n)
        light.intensity[j, i] = intensity
        light.count[j, i] = n

    return light_kernel
