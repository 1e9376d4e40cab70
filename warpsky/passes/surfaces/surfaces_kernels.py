"""Kernels of the surfaces pass: eye rays against the meshes' BVH and the ground plane, then Lambertian shading.

Two launches per frame. :func:`surface_hits` finds, per pixel, the nearest of the mesh hits
(:func:`~warpsky.surfaces.mesh.mesh_hit`) and the ground plane within the camera's clipping range, and records the
hit point, normal and albedo; the host may then evaluate a sun transmittance at those points (fog, height-field
cloud shadows); :func:`shade_kernel`'s kernel shades them:

    L = albedo / pi * (E_sun max(n.l, 0) V_sun T_sun + E_sky(n)),
    E_sky(n) = pi L_sky (1 + n_y) / 2 * exp(-tau_up),

with V_sun the meshes' shadow (a BVH any-hit ray towards the sun), T_sun the transmittance of the voxel media
towards the sun (:func:`~warpsky.media.voxels.shadow.depth_functions`, the march the single-scatter technique uses)
times the host's factor, and E_sky the irradiance a plane of normal n receives from a uniform sky of radiance
L_sky over the upper hemisphere and black below the horizon (the view factor of the sky from a plane tilted by
acos(n_y) is (1 + n_y) / 2), under the voxel media's transmittance towards the zenith exp(-tau_up) as the ground of
the voxel techniques is (:mod:`warpsky.light.dome`).
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3
from warpsky.light.sun import Sun
from warpsky.media.voxels.shadow import depth_functions
from warpsky.media.voxels.voxel import VoxelMedia
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.surfaces.mesh import SurfaceHit, SurfaceMeshes, material_albedo, mesh_hit, mesh_occluded, no_hit


@wp.struct
class SurfacePlane:
    """The horizontal ground plane, when this pass draws it."""

    on: int  # 1: draw it
    offset: float  # plane height minus the camera's [m]
    material: int  # its material in the meshes' material table


@wp.struct
class SurfaceImage:
    """Per pixel, the nearest surface the eye ray meets (``hit`` 0: none within the clipping range)."""

    point: wp.array2d(dtype=wp.vec3)  # camera-relative hit point [m]
    normal: wp.array2d(dtype=wp.vec3)  # unit shading normal facing the eye
    albedo: wp.array2d(dtype=wp.vec3)  # RGB reflectance
    depth: wp.array2d(dtype=float)  # camera-space depth along the view axis [m]; far where nothing is hit
    hit: wp.array2d(dtype=wp.int32)
    scale: wp.array2d(dtype=float)  # the hit's float error scale [m] (:class:`SurfaceHit`)


@wp.struct
class SurfaceLighting:
    """What lights the surfaces besides the sun."""

    sky: wp.vec3  # L_sky: uniform-equivalent sky radiance of the upper hemisphere (its E / pi), RGB
    sky_on: int  # 1: add the sky term (a scene with a dome)
    shadow_step: float  # step of the voxel shadow marches [m]
    shadow_bias: float  # shadow rays start this fraction of (1 m + the hit's scale) off the surface


@wp.func
def plane_hit(surfaces: SurfaceMeshes, plane: SurfacePlane, origin: wp.vec3, direction: wp.vec3, t_min: float,
              t_max: float) -> SurfaceHit:
    """Hit of the ray ``origin + t * direction`` with the ground plane (from above) for t_min < t < t_max."""
    if plane.on == 0 or direction[1] >= 0.0:
        return no_hit(t_max)
    t = (plane.offset - origin[1]) / direction[1]
    if t <= t_min or t >= t_max:
        return no_hit(t_max)
    out = no_hit(t)
    out.hit = 1
    out.scale = wp.length(origin + t * direction)
    out.albedo = material_albedo(surfaces, plane.material, origin + t * direction)
    return out


@wp.func
def nearest_surface(surfaces: SurfaceMeshes, plane: SurfacePlane, origin: wp.vec3, direction: wp.vec3,
                    t_min: float, t_max: float) -> SurfaceHit:
    """The nearest mesh or plane hit with t_min <= t <= t_max (t from ``origin``; the mesh query starts at t_min,
    so what lies nearer is clipped away, not in front)."""
    h = mesh_hit(surfaces, origin + t_min * direction, direction, t_max - t_min)
    h.t = h.t + t_min
    p = plane_hit(surfaces, plane, origin, direction, t_min, t_max)
    if p.hit != 0 and (h.hit == 0 or p.t < h.t):
        return p
    return h


@wp.kernel
def surface_hits(surfaces: SurfaceMeshes, plane: SurfacePlane, cam: PinholeCamera, image: SurfaceImage,
                 row_offset: int):
    """One eye ray per pixel centre against the meshes and the plane, within the camera's clipping range."""
    r, col = wp.tid()
    row = r + row_offset
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    h = nearest_surface(surfaces, plane, ray.origin, ray.direction, ray.t_near, ray.t_far)
    image.hit[row, col] = h.hit
    image.point[row, col] = ray.origin + h.t * ray.direction
    image.normal[row, col] = h.shading
    image.albedo[row, col] = h.albedo
    image.scale[row, col] = h.scale
    image.depth[row, col] = wp.where(h.hit != 0, h.t * ray.cos_axis, cam.far)


@wp.kernel
def camera_buried(surfaces: SurfaceMeshes, plane: SurfacePlane, out: wp.array(dtype=wp.int32)):
    """out[0] = the material whose back face the ray straight up from the eye meets first (the eye is under that
    surface), the plane's material when the eye is below the plane, else -1."""
    out[0] = -1
    if plane.on != 0 and plane.offset > 0.0:
        out[0] = plane.material
    up = wp.vec3(0.0, 1.0, 0.0)
    if surfaces.triangle_count > 0:
        q = wp.mesh_query_ray(surfaces.mesh, wp.vec3(0.0), up, 1.0e30)
        if q.result and q.sign < 0.0:
            out[0] = surfaces.triangle_material[q.face]


@kernel_variants(has_detail=(False, True))
@functools.cache
def shade_kernel(has_detail: bool) -> wp.Kernel:
    """The shading launch, specialised on the voxel media's animated detail (their shadow march samples it)."""
    sun_optical_depth, vertical_optical_depth = depth_functions(has_detail)

    @wp.func
    def sun_term(surfaces: SurfaceMeshes, media: VoxelMedia, sun: Sun, lighting: SurfaceLighting, p: wp.vec3,
                 n: wp.vec3, scale: float) -> wp.vec3:
        """E_sun max(n.l, 0) V_sun exp(-tau_media) at the camera-relative point ``p`` of normal ``n``."""
        l = sun.direction
        cosine = wp.dot(n, l)
        if sun.lit == 0 or cosine <= 0.0:
            return wp.vec3(0.0)
        start = p + n * (lighting.shadow_bias * (1.0 + scale))
        if mesh_occluded(surfaces, start, l, 1.0e30):
            return wp.vec3(0.0)
        tau = sun_optical_depth(media, p, 0.0, l, l, lighting.shadow_step)
        return wp.cw_mul(sun.irradiance, exp3(wp.vec3(tau[0], tau[1], tau[2]))) * cosine

    @wp.kernel(module="unique")
    def shade_surfaces(surfaces: SurfaceMeshes, media: VoxelMedia, sun: Sun, lighting: SurfaceLighting,
                       image: SurfaceImage, sun_factor: wp.array2d(dtype=wp.vec3),
                       radiance: wp.array2d(dtype=wp.vec3), transmittance: wp.array2d(dtype=wp.vec3),
                       row_offset: int):
        r, col = wp.tid()
        row = r + row_offset
        if image.hit[row, col] == 0:
            radiance[row, col] = wp.vec3(0.0)
            transmittance[row, col] = wp.vec3(1.0)
            return
        p = image.point[row, col]
        n = image.normal[row, col]
        direct = sun_term(surfaces, media, sun, lighting, p, n, image.scale[row, col])
        light = wp.cw_mul(direct, sun_factor[row, col]) / wp.pi
        if lighting.sky_on != 0:
            up = vertical_optical_depth(media, p, 0.0, wp.vec3(0.0, 1.0, 0.0), 0, lighting.shadow_step)
            light += wp.cw_mul(lighting.sky, exp3(wp.vec3(up[0], up[1], up[2]))) * (0.5 * (1.0 + n[1]))
        radiance[row, col] = wp.cw_mul(image.albedo[row, col], light)
        transmittance[row, col] = wp.vec3(0.0)

    return shade_surfaces
