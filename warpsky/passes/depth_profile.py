"""Depth profiles for deep output: where along each camera ray a volume layer's opacity builds up.

A frame that writes a deep EXR asks its volume passes for a :class:`~warpsky.output.deep_bins.DepthProfile` of K
bins per pixel beside their layer; :mod:`warpsky.output.deep_bins` turns it into K volume samples. Two kernels, one
thread per pixel, each on the rays its pass rendered:

* :func:`media_profile_kernel`, the voxel media (every technique): the camera ray, clipped to the media's boxes
  (:func:`~warpsky.media.voxels.voxel.media_span`), to the ground plane where the technique drew it and to the nearest
  opaque surface another pass drew, is marched twice in equal steps of at most :data:`STEP_VOXELS` of the smallest
  voxel edge, the extinction from the media's own lookup (:func:`~warpsky.media.voxels.voxel.media_functions`) at each
  step's midpoint: first to its end (the exit, or the step after which the luminance transmittance is below
  :data:`CUT`: the rest is hidden), then again to place the edges, each inside the step that crosses its level by
  bisection on the step's (linear) optical depth. It costs two lookups per step and medium, where the techniques
  march a shadow ray per step.
* :data:`fog_profile`, analytic fog (Biri 2002): its closed-form optical depth
  (:func:`~warpsky.media.fog.fogs_optical_depth`) over the slabs' span, each edge placed by bisection on
  the distance to 2^-24 of the span.

Where the edges go sets the error. A compositor splits a bin's alpha as if its extinction were uniform, so an
object placed inside a bin sees a visibility off by at most the bin's share of the opacity, and by less the shorter
the bin is where the extinction varies. Voxel media: edge k sits where u(t) = k / K, u the mean of three fractions of
the march up to distance t: of its luminance opacity, of its visible length (the integral of the luminance
transmittance from the entry) and of its length. Every bin then holds at most 3/K of each. Measured against the
closed form on a density ramp rising 20-fold along the ray (optical depth 1 and 21, dense side in front or behind;
``tests/test_deep_bins.py``), the largest visibility error of a point anywhere in it is 4e-3 to 9e-3 at K = 8 and
7e-4 to 4e-3 at K = 16; with the edges at equal shares of the opacity alone it was 1.1e-2 to 3.3e-2 at K = 8 (a
sparse tail then sits in one long bin), and it is second order in 1/K here against first order there. A homogeneous
medium is exact (float32 rounding, 3e-6) at any K. Fog: edges at equal shares of the luminance opacity alone (exact
for uniform fog; its rays often run to the far clip, where equal lengths would spend bins on hidden fog).

Stratiform layers and height-field decks draw no profile and stay one sample per pixel each.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3, exp_lerp_mean3, luminance
from warpsky.media.fog import FogSet, fog_struct, fogs_optical_depth
from warpsky.media.voxels.voxel import MAX_MEDIA, VoxelMedia, VoxelMediaBuffers, media_functions, media_span
from warpsky.model.camera_rays import PinholeCamera, PrimaryRay, pinhole_camera, primary_ray
from warpsky.output.deep_bins import DepthProfile
from warpsky.passes.fog.fog_kernels import exp3d, fog_eye_ray, luminance64, slabs_span
from warpsky.surfaces.plane import Ground, ground_end, ground_struct

#: Step of the voxel media's optical-depth march, in units of the smallest voxel edge.
STEP_VOXELS = 0.5
#: The march stops once the luminance transmittance is below this: the media hide what lies behind.
CUT = 1.0e-6
#: Halvings that place a quantile inside a march step (its position to 2^-24 of the step).
STEP_BISECTIONS = 24
#: Halvings that place a fog edge along the fog's span (to 2^-24 of it: 6 mm over 100 km).
FOG_BISECTIONS = 24


@wp.struct
class ProfileMarch:
    """How each camera ray's optical depth is cut into bins."""

    count: int  # bins per ray (K)
    step: float  # longest step of the voxel media's march [m]
    cut: float  # luminance transmittance below which the march stops


@wp.struct
class RayPoint:
    """A point of a camera ray's march and what lies between the media's entry and it."""

    t: float  # distance along the ray [m]
    tau: wp.vec3  # RGB optical depth from the entry
    seen: float  # visible length: the integral of the luminance transmittance from the entry [m]


@wp.func
def ray_step(a: RayPoint, tau: wp.vec3, dt: float) -> RayPoint:
    """The point ``dt`` [m] beyond ``a`` across a step of RGB optical depth ``tau``, uniform inside the step."""
    out = RayPoint()
    out.t = a.t + dt
    out.tau = a.tau + tau
    out.seen = a.seen + dt * luminance(exp_lerp_mean3(a.tau, out.tau))
    return out


@wp.func
def ray_share(p: RayPoint, entry: float, whole: RayPoint) -> float:
    """Where ``p`` lies between the entry (0) at ``entry`` [m] and the march's end ``whole`` (1): the mean of its
    fractions of the luminance opacity, of the visible length and of the length."""
    opacity = (1.0 - luminance(exp3(p.tau))) / (1.0 - luminance(exp3(whole.tau)))
    return (opacity + p.seen / whole.seen + (p.t - entry) / (whole.t - entry)) / 3.0


@wp.func
def level_crossing(a: RayPoint, tau: wp.vec3, dt: float, entry: float, whole: RayPoint, level: float) -> RayPoint:
    """The point of the step from ``a`` (``dt`` [m] long, optical depth ``tau``) whose :func:`ray_share` is
    ``level`` (which the step crosses), by bisection on the fraction of the step."""
    lo = float(0.0)
    hi = float(1.0)
    for _ in range(STEP_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if ray_share(ray_step(a, mid * tau, mid * dt), entry, whole) < level:
            lo = mid
        else:
            hi = mid
    return ray_step(a, hi * tau, hi * dt)


@kernel_variants(has_detail=(False, True))
@functools.cache
def media_profile_kernel(has_detail: bool = False) -> wp.Kernel:
    """The voxel media's profile per pixel, specialised on animated detail (the density the technique saw); a
    ground plane (``ground.enabled``, a runtime test) ends the rays."""

    sample_media = media_functions(has_detail)

    @wp.func
    def step_depth(media: VoxelMedia, ray: PrimaryRay, t: float, dt: float) -> wp.vec3:
        """RGB optical depth of the step [t, t + dt] [m] of ``ray``: the extinction at its midpoint times dt."""
        return sample_media(media, ray.origin + (t + 0.5 * dt) * ray.direction).extinction * dt

    @wp.func
    def march_end(media: VoxelMedia, ray: PrimaryRay, march: ProfileMarch, start: RayPoint, dt: float,
                  count: int) -> RayPoint:
        """The march from ``start`` in ``count`` steps of ``dt`` [m], to the last or to the first that takes the
        luminance transmittance below ``march.cut``."""
        p = start
        for _ in range(count):
            p = ray_step(p, step_depth(media, ray, p.t, dt), dt)
            if luminance(exp3(p.tau)) < march.cut:
                break
        return p

    @wp.kernel(module="unique")
    def media_profile(media: VoxelMedia, cam: PinholeCamera, ground: Ground, march: ProfileMarch,
                      edges: wp.array3d(dtype=float), depths: wp.array3d(dtype=wp.vec3),
                      end: wp.array2d(dtype=float), row_offset: int):
        r, col = wp.tid()
        row = r + row_offset
        ray = primary_ray(cam, row, col, 0.5, 0.5)
        t_end = ray.t_far
        hit = int(0)
        if ground.enabled != 0:
            t_end, hit = ground_end(ground, ray.origin, ray.direction, ray.t_near, t_end)
        end[row, col] = t_end * ray.cos_axis
        span = media_span(media, ray.origin, ray.direction, ray.t_near, t_end)
        if span[1] <= span[0]:
            return
        count = wp.max(int(wp.ceil((span[1] - span[0]) / march.step)), 1)
        dt = (span[1] - span[0]) / float(count)
        p = RayPoint()
        p.t = span[0]
        whole = march_end(media, ray, march, p, dt, count)
        if hit == 0:
            end[row, col] = whole.t * ray.cos_axis
        if luminance(exp3(whole.tau)) >= 1.0:
            return
        edges[row, col, 0] = span[0] * ray.cos_axis
        k = int(1)
        while p.t < whole.t and k < march.count:  # the same steps again: each edge in the step crossing its level
            tau = step_depth(media, ray, p.t, dt)
            b = ray_step(p, tau, dt)
            while k < march.count and ray_share(b, span[0], whole) >= float(k) / float(march.count):
                q = level_crossing(p, tau, dt, span[0], whole, float(k) / float(march.count))
                edges[row, col, k] = q.t * ray.cos_axis
                depths[row, col, k] = q.tau
                k += 1
            p = b
        for j in range(k, march.count + 1):  # the end, and levels that rounding left unplaced
            edges[row, col, j] = whole.t * ray.cos_axis
            depths[row, col, j] = whole.tau

    return media_profile


@wp.kernel
def fog_profile(fogs: FogSet, cam: PinholeCamera, limit: wp.array2d(dtype=float), has_limit: int,
                march: ProfileMarch, edges: wp.array3d(dtype=float), depths: wp.array3d(dtype=wp.vec3),
                end: wp.array2d(dtype=float), row_offset: int):
    """The fogs' profile per pixel, on the rays of the fog pass (near plane to the nearer of the far plane and
    ``limit``)."""
    tid_row, col = wp.tid()
    row = row_offset + tid_row
    eye = fog_eye_ray(cam, limit, has_limit, row, col)
    o = eye.origin
    w = eye.direction
    cos_axis = eye.cos_axis
    span = slabs_span(fogs, o, w, eye.t_near, eye.t_far)
    if span[1] <= span[0]:
        return
    a = o + span[0] * w
    total = fogs_optical_depth(fogs, a, o + span[1] * w)
    end[row, col] = float(span[1] * cos_axis)
    fall = wp.float64(1.0) - luminance64(exp3d(total))
    if fall <= wp.float64(0.0):
        return
    edges[row, col, 0] = float(span[0] * cos_axis)
    lo = span[0]
    for k in range(1, march.count):
        level = wp.float64(1.0) - wp.float64(k) * fall / wp.float64(march.count)
        hi = span[1]
        for _ in range(FOG_BISECTIONS):
            mid = wp.float64(0.5) * (lo + hi)
            if luminance64(exp3d(fogs_optical_depth(fogs, a, o + mid * w))) > level:
                lo = mid
            else:
                hi = mid
        tau = fogs_optical_depth(fogs, a, o + hi * w)
        edges[row, col, k] = float(hi * cos_axis)
        depths[row, col, k] = wp.vec3(float(tau[0]), float(tau[1]), float(tau[2]))
    edges[row, col, march.count] = float(span[1] * cos_axis)
    depths[row, col, march.count] = wp.vec3(float(total[0]), float(total[1]), float(total[2]))


def profile_march(count: int, step: float = 1.0) -> ProfileMarch:
    """The kernels' :class:`ProfileMarch` for ``count`` bins and voxel steps of at most ``step`` [m]."""
    march = ProfileMarch()
    march.count = int(count)
    march.step = float(step)
    march.cut = CUT
    return march


def _outputs(width: int, height: int, count: int) -> tuple[wp.array, wp.array, wp.array]:
    return (wp.zeros((height, width, count + 1), dtype=float), wp.zeros((height, width, count + 1), dtype=wp.vec3),
            wp.zeros((height, width), dtype=float))


def media_profile(scene, width: int, height: int, count: int, device: str) -> DepthProfile | None:
    """The voxel media's :class:`DepthProfile` of ``count`` bins on the rays a technique rendered ``scene`` with
    (the camera conformed to ``width`` x ``height``, its ground plane and opaque depths); None without media or
    with more than :data:`~warpsky.media.voxels.voxel.MAX_MEDIA` of them (the layer then stays one sample)."""
    if not scene.media or len(scene.media) > MAX_MEDIA:
        return None
    camera = scene.camera.conformed(width, height)
    with wp.ScopedDevice(device):
        media = VoxelMediaBuffers.upload(scene.media, camera.position, device, scene.species, time_s=scene.time_s)
        edges, depths, end = _outputs(width, height, count)
        kernel = media_profile_kernel(media.has_detail)
        launch_rows(kernel, height, width, [media.media, pinhole_camera(camera, width, height),
                                            ground_struct(scene.ground, camera.position),
                                            profile_march(count, STEP_VOXELS * media.min_voxel_size),
                                            edges, depths, end], device)
        return DepthProfile(edges.numpy(), depths.numpy(), end.numpy())


def fog_depth_profile(scene, width: int, height: int, count: int, device: str,
                      limit: np.ndarray | None = None) -> DepthProfile | None:
    """The analytic fogs' :class:`DepthProfile` of ``count`` bins on the fog pass's rays (``limit``: the
    (height, width) depths [m] of the nearest opaque surface, or None); None without fog."""
    if not scene.fogs:
        return None
    camera = scene.camera.conformed(width, height)
    with wp.ScopedDevice(device):
        fogs = fog_struct(scene.fogs, camera.position, scene.time_s, device)
        limits = wp.array(np.ascontiguousarray(limit, dtype=np.float32) if limit is not None
                          else np.zeros((1, 1), np.float32), dtype=float)
        edges, depths, end = _outputs(width, height, count)
        launch_rows(fog_profile, height, width, [fogs, pinhole_camera(camera, width, height), limits,
                                                 int(limit is not None), profile_march(count), edges, depths, end],
                    device)
        return DepthProfile(edges.numpy(), depths.numpy(), end.numpy())
