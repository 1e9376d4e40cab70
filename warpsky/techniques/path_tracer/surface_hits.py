"""The path tracer's triangle meshes: where a flight meets one, and the Lambertian bounce there.

The meshes are the surfaces pass's (:mod:`warpsky.surfaces.mesh`): one Warp BVH over float32 points relative to the
camera (subtracted from the world's in float64 on the host, as the media's and the ground's are), a material per
mesh (a uniform albedo or an albedo map over world x, z, read by
:func:`~warpsky.surfaces.mesh.material_albedo`). A path's free flight runs to the nearest of its own end (the far
distance, the ground plane, sea level or a round earth's floor) and the nearest mesh hit (``wp.mesh_query_ray``,
:func:`mesh_flight_end`); a delta-tracking collision before it scatters as before, so media, air, ground and meshes
meet along a path in any order.

A mesh is an opaque two-sided Lambertian surface (:func:`mesh_event_function`): the geometric normal is turned to
face the incoming ray, and the shading normal (the mesh's interpolated vertex normals, else the geometric one) to
its side. There the path takes the sun's light albedo / pi E max(n.l, 0) through the meshes' any-hit shadow ray and
the media and air's transmittance every event takes (:func:`~warpsky.techniques.path_tracer.events.
sun_transmittance_function`), then a cosine-weighted bounce about the shading normal, its throughput times the
albedo; a bounce that falls under the face (a shading normal's lobe can dip below it) ends the path. Rays leaving a
mesh start off it along the geometric normal (:func:`~warpsky.surfaces.mesh.off_surface`), never on their own face.

The shadow rays of scattering events and of the ground plane test the meshes too (:func:`sun_unblocked`): a
binary visibility, so an event in a mesh's shadow takes no sunlight and tracks no transmittance.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.light.sun import Sun
from warpsky.media.air.medium import Air, vertical
from warpsky.media.voxels.voxel import VoxelMedia
from warpsky.surfaces.mesh import (
    SHADOW_BIAS,
    MeshBuffers,
    SurfaceHit,
    SurfaceMeshes,
    mesh_hit,
    mesh_occluded,
    no_surfaces,
    off_surface,
)
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.events import PathState, sun_transmittance_function
from warpsky.techniques.path_tracer.majorants import Majorants
from warpsky.techniques.path_tracer.planet import cosine_about, ground_point
from warpsky.techniques.path_tracer.ray_ends import SURFACE_MESH, UNBOUNDED, RayEnd


@wp.struct
class MeshFlight:
    """Where a flight ends once the meshes are counted, and the mesh hit there (``hit.hit`` 0: none)."""

    end: RayEnd
    hit: SurfaceHit


@wp.func
def ended_on(hit: SurfaceHit, end: RayEnd) -> MeshFlight:
    """``end``, or the mesh ``hit`` where there is one (it lies before ``end``)."""
    stop = end
    if hit.hit != 0:
        stop.t = hit.t
        stop.surface = SURFACE_MESH
    out = MeshFlight()
    out.end = stop
    out.hit = hit
    return out


@wp.func
def mesh_flight_end(surfaces: SurfaceMeshes, origin: wp.vec3, d: wp.vec3, bounce: int, first_hit: SurfaceHit,
                    end: RayEnd) -> MeshFlight:
    """``end`` (the flight's end without meshes), or the nearest mesh hit before it: for the camera ray (bounce 0)
    ``first_hit``, the hit its own query found (:func:`camera_mesh_end`), for later flights the BVH's."""
    hit = first_hit
    if bounce > 0:
        hit = mesh_hit(surfaces, origin, d, end.t)
    return ended_on(hit, end)


@wp.func
def camera_mesh_end(surfaces: SurfaceMeshes, origin: wp.vec3, view: wp.vec3, first: RayEnd) -> MeshFlight:
    """The camera ray's end ``first`` (far distance, ground, sea level), or its nearest mesh hit before that."""
    return ended_on(mesh_hit(surfaces, origin, view, first.t), first)


@wp.func
def sun_unblocked(surfaces: SurfaceMeshes, air: Air, ground: Ground, sun: Sun, p: wp.vec3, on_ground: int) -> bool:
    """Whether no mesh lies on the shadow ray towards the sun from an event at ``p``: a scattering point, or with
    ``on_ground`` the ground plane's (or a round earth floor's) point under it, lifted off it along its normal like
    a mesh's (:data:`~warpsky.surfaces.mesh.SHADOW_BIAS`)."""
    q = p
    if on_ground != 0:
        q = ground_point(air, ground, p)
        up = wp.vec3(0.0, 1.0, 0.0)
        if air.round != 0:
            up = vertical(air, q)
        q = q + up * (SHADOW_BIAS * (1.0 + wp.length(q)))
    return not mesh_occluded(surfaces, q, sun.direction, UNBOUNDED)


@functools.cache
def mesh_event_function(has_detail: bool, has_fog: bool = False):
    """``mesh_event(media, majorants, air, sun, surfaces, sun_on, path, p, hit, reduced) -> PathState``, the
    Lambertian bounce on a mesh, specialised on animated detail and analytic fog (its sunlight through the fogs)."""
    transmittance_to_sun = sun_transmittance_function(has_detail, has_fog)

    @wp.func
    def mesh_event(media: VoxelMedia, majorants: Majorants, air: Air, sun: Sun, surfaces: SurfaceMeshes,
                   sun_on: bool, path: PathState, p: wp.vec3, hit: SurfaceHit, reduced: int) -> PathState:
        """The path's flight ended on a mesh at ``p`` (``hit``): next-event estimation toward the sun (the meshes'
        any-hit shadow ray from the point lifted off the face, then the media, with ``reduced`` after high-order
        similarity, and the air from the hit itself), then a cosine-weighted bounce about the shading normal (two
        random draws) from the lifted point; a bounce under the face ends it."""
        out = path
        start = off_surface(hit, p)
        n = hit.shading
        cosine = wp.dot(n, sun.direction)
        if sun_on and cosine > 0.0 and wp.dot(hit.normal, sun.direction) > 0.0:
            if not mesh_occluded(surfaces, start, sun.direction, UNBOUNDED):
                tr_sun = transmittance_to_sun(media, majorants, air, sun, p, out.state, reduced)  # from the hit
                out.state = tr_sun.state
                out.steps = out.steps + tr_sun.steps
                out.shadow_steps = out.shadow_steps + tr_sun.steps
                lit = wp.cw_mul(sun.irradiance, tr_sun.value)
                out.radiance = out.radiance + wp.cw_mul(wp.cw_mul(out.throughput, hit.albedo), lit) * (
                    cosine / wp.pi)
        out.throughput = wp.cw_mul(out.throughput, hit.albedo)
        bounce = cosine_about(n, out.state)
        out.state = bounce.state
        out.direction = bounce.direction
        out.origin = start
        if wp.dot(bounce.direction, hit.normal) <= 0.0:
            out.alive = 0
        return out

    return mesh_event


#: The meshes the path tracer traced last, per device: a frame with the same triangles (only points or the camera
#: moved) refits their BVH instead of building it again.
_KEPT: dict[str, MeshBuffers] = {}


def traced_meshes(meshes, camera_position, device) -> tuple[SurfaceMeshes, MeshBuffers | None]:
    """The kernels' view of ``meshes`` on ``device`` relative to ``camera_position`` [m] (the points the media and
    the ground are relative to), and the buffers it points into (keep them while it is in use); with no meshes an
    empty view (no BVH) and None."""
    if not meshes:
        return no_surfaces(device), None
    kept = _KEPT.get(str(device))
    buffers = (MeshBuffers.build(meshes, camera_position, device) if kept is None
               else kept.update(meshes, camera_position))
    _KEPT[str(device)] = buffers
    return buffers.surfaces, buffers
