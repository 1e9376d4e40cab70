"""Triangle meshes on the device: one Warp BVH (``wp.Mesh``) over every mesh of a frame, with their albedos.

Like the voxel media (:mod:`warpsky.media.voxels.voxel`), kernels never see world coordinates: the host subtracts the
camera position from the float64 world points and uploads float32 camera-relative points, so terrain 100 km from
the origin is hit as precisely as terrain at the origin (float32 spacing at 1 km from the eye is 0.06 mm).

All meshes are concatenated into one ``wp.Mesh``; each triangle carries the index of its material (one per mesh,
plus any the caller adds, such as the ground plane's), and a material is a uniform albedo or an albedo map over
world (x, z) (:class:`~warpsky.model.stratiform.GroundTexture`: texel centres at integer texel coordinates, bilinear,
edge texels continued beyond the map). When only the points move between frames (same triangles, or a camera
that moved: a rigid shift of the camera-relative points), :meth:`MeshBuffers.update` refits the BVH instead of
building it again (a refit keeps a rigid shift's tree as good as a fresh one).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.numerics import bilinear_cell, bilinear_mix
from warpsky.model.stratiform import GroundTexture

#: Rays leaving a surface start this fraction of (1 m + the hit's scale) off it, along its normal; the scale is the
#: largest distance from the eye of the hit point and its triangle's corners, which sets the float32 error of the
#: ray-triangle test. About 170 roundings: a surface never shadows itself; 2 cm for triangles within 1 km.
SHADOW_BIAS = 2.0e-5


@wp.struct
class SurfaceMaterial:
    """A Lambertian surface's albedo: uniform, or a map over camera-relative (x, z)."""

    albedo: wp.vec3  # RGB reflectance where there is no map
    texture_offset: int  # first texel of the map in the flat texel buffer
    texture_shape: wp.vec2i  # texels along x and z
    texture_origin: wp.vec2  # camera-relative (x, z) of the map's corner [m]
    texture_size: wp.vec2  # extent along x and z [m]
    textured: int  # 1: read the map


@wp.struct
class SurfaceMeshes:
    """Every mesh of a frame as kernels see it (built by :class:`MeshBuffers`)."""

    mesh: wp.uint64  # wp.Mesh id over camera-relative points (0 when there are no triangles)
    triangle_material: wp.array(dtype=wp.int32)  # material index per triangle
    materials: wp.array(dtype=SurfaceMaterial)
    texels: wp.array(dtype=wp.vec3)  # every map's texels, (nx, nz) row-major each
    normals: wp.array(dtype=wp.vec3)  # shading normal per vertex (zero for a mesh without authored normals)
    smooth: int  # 1: some mesh has vertex normals
    triangle_count: int  # 0: no mesh, skip every query


@wp.struct
class SurfaceHit:
    """The nearest surface along a ray."""

    t: float  # distance along the (unit) ray [m]
    normal: wp.vec3  # unit geometric normal turned towards the ray's origin (surfaces are two-sided)
    shading: wp.vec3  # unit shading normal: the interpolated vertex normal on the normal's side, else the normal
    albedo: wp.vec3  # RGB reflectance at the hit
    hit: int  # 1: something was hit
    back: int  # 1: the ray met the back of the face (the side its winding turns away from)
    scale: float  # largest distance from the eye of the hit point or the face's corners [m]: sets its float error


@wp.func
def no_hit(t_max: float) -> SurfaceHit:
    """A miss at ``t_max``."""
    out = SurfaceHit()
    out.t = t_max
    out.normal = wp.vec3(0.0, 1.0, 0.0)
    out.shading = wp.vec3(0.0, 1.0, 0.0)
    out.albedo = wp.vec3(0.0)
    out.hit = 0
    out.back = 0
    out.scale = 0.0
    return out


@wp.func
def material_albedo(surfaces: SurfaceMeshes, material: int, p: wp.vec3) -> wp.vec3:
    """Albedo of ``material`` at the camera-relative point ``p`` [m]: its uniform albedo, or its map's bilinear
    value at (p.x, p.z) (texel centres at integer coordinates, clamped to the edge texels)."""
    m = surfaces.materials[material]
    if m.textured == 0:
        return m.albedo
    nx = m.texture_shape[0]
    nz = m.texture_shape[1]
    u = (p[0] - m.texture_origin[0]) / m.texture_size[0] * float(nx) - 0.5
    v = (p[2] - m.texture_origin[1]) / m.texture_size[1] * float(nz) - 0.5
    cell = bilinear_cell(wp.vec2(u, v), m.texture_shape)
    lo = cell.lo
    hi = cell.hi
    b = m.texture_offset
    return bilinear_mix(surfaces.texels[b + lo[0] * nz + lo[1]], surfaces.texels[b + hi[0] * nz + lo[1]],
                        surfaces.texels[b + lo[0] * nz + hi[1]], surfaces.texels[b + hi[0] * nz + hi[1]], cell.frac)


@wp.func
def mesh_hit(surfaces: SurfaceMeshes, origin: wp.vec3, direction: wp.vec3, t_max: float) -> SurfaceHit:
    """Nearest mesh hit of the ray ``origin + t * direction`` (camera-relative, ``direction`` unit) with
    0 <= t <= t_max [m], through the BVH (``wp.mesh_query_ray``)."""
    if surfaces.triangle_count == 0:
        return no_hit(t_max)
    q = wp.mesh_query_ray(surfaces.mesh, origin, direction, t_max)
    if not q.result:
        return no_hit(t_max)
    out = SurfaceHit()
    out.t = q.t
    out.hit = 1
    out.back = wp.where(q.sign < 0.0, 1, 0)
    out.normal = wp.where(wp.dot(q.normal, direction) > 0.0, -q.normal, q.normal)
    p = origin + q.t * direction
    out.albedo = material_albedo(surfaces, surfaces.triangle_material[q.face], p)
    out.scale = wp.length(p)
    for k in range(3):
        corner = wp.mesh_get_point(surfaces.mesh, wp.mesh_get_index(surfaces.mesh, q.face * 3 + k))
        out.scale = wp.max(out.scale, wp.length(corner))
    out.shading = shading_normal(surfaces, q.face, q.u, q.v, out.normal)
    return out


@wp.func
def shading_normal(surfaces: SurfaceMeshes, face: int, u: float, v: float, geometric: wp.vec3) -> wp.vec3:
    """The vertex normals of ``face`` interpolated at the barycentric (u, v) (Warp's: p = u p0 + v p1 +
    (1 - u - v) p2), turned to the side of ``geometric``; ``geometric`` itself where the mesh has none."""
    if surfaces.smooth == 0:
        return geometric
    n = wp.vec3(0.0)
    weights = wp.vec3(u, v, 1.0 - u - v)
    for k in range(3):
        n += surfaces.normals[wp.mesh_get_index(surfaces.mesh, face * 3 + k)] * weights[k]
    length = wp.length(n)
    if length < 1.0e-6:  # a mesh without normals (zeros), or opposite normals cancelling
        return geometric
    n = n / length
    return wp.where(wp.dot(n, geometric) < 0.0, -n, n)


@wp.func
def off_surface(hit: SurfaceHit, p: wp.vec3) -> wp.vec3:
    """The hit point ``p`` moved ``SHADOW_BIAS`` (1 m + the hit's scale) along the geometric normal, to the side the
    ray came from: where rays leaving the surface start, so that they never meet its own face."""
    return p + hit.normal * (SHADOW_BIAS * (1.0 + hit.scale))


@wp.func
def mesh_occluded(surfaces: SurfaceMeshes, origin: wp.vec3, direction: wp.vec3, t_max: float) -> bool:
    """Whether any mesh triangle lies on the ray ``origin + t * direction`` with 0 <= t <= t_max (a shadow ray;
    ``wp.mesh_query_ray_anyhit`` stops at the first one found)."""
    if surfaces.triangle_count == 0:
        return False
    return wp.mesh_query_ray_anyhit(surfaces.mesh, origin, direction, t_max)


def _material(albedo, texture: GroundTexture | None, offset: int, eye: np.ndarray) -> SurfaceMaterial:
    out = SurfaceMaterial()
    out.albedo = wp.vec3(*np.asarray(albedo, dtype=np.float64).tolist())
    out.texture_offset = int(offset)
    out.textured = int(texture is not None)
    if texture is None:
        out.texture_shape = wp.vec2i(1, 1)
        out.texture_origin = wp.vec2(0.0, 0.0)
        out.texture_size = wp.vec2(1.0, 1.0)
    else:
        out.texture_shape = wp.vec2i(*texture.albedo.shape[:2])
        out.texture_origin = wp.vec2(float(texture.origin[0] - eye[0]), float(texture.origin[1] - eye[2]))
        out.texture_size = wp.vec2(float(texture.size[0]), float(texture.size[1]))
    return out


@dataclass
class MeshBuffers:
    """Every mesh of a frame on one device, relative to one camera position; :attr:`surfaces` is the kernels' view.

    Materials 0 .. len(meshes) - 1 are the meshes'; ``extra_materials`` (``(albedo, GroundTexture | None)``
    pairs, e.g. the ground plane's) follow them, at :attr:`extra_material_base`.
    """

    device: str
    mesh: wp.Mesh | None
    points: wp.array | None  # camera-relative float32 vertex positions [m]
    triangle_material: wp.array
    materials: wp.array
    texels: wp.array
    normals: wp.array
    triangle_count: int
    extra_material_base: int
    build_seconds: float  # wall time of the last BVH build or refit [s]
    refitted: bool  # whether the last update refitted the BVH instead of building it
    _topology: tuple = ()

    @classmethod
    def build(cls, meshes, camera_position, device, *, extra_materials=()) -> MeshBuffers:
        """Upload ``meshes`` (:class:`~warpsky.model.terrain.TerrainMesh`) relative to ``camera_position`` [m]
        and build the BVH."""
        out = cls(str(device), None, None, None, None, None, None, 0, len(meshes), 0.0, False)
        out._upload_materials(meshes, camera_position, extra_materials)
        triangles = [m.triangles + offset for m, offset in zip(meshes, _offsets(meshes), strict=True)]
        count = int(sum(len(t) for t in triangles))
        out.triangle_count = count
        material = np.repeat(np.arange(len(meshes), dtype=np.int32), [len(m.triangles) for m in meshes])
        out.triangle_material = wp.array(material if count else np.zeros(1, np.int32), dtype=wp.int32, device=device)
        if count:
            started = time.perf_counter()
            out.points = wp.array(_relative_points(meshes, camera_position), dtype=wp.vec3, device=device)
            indices = wp.array(np.concatenate(triangles).reshape(-1), dtype=wp.int32, device=device)
            out.mesh = wp.Mesh(out.points, indices)
            out._upload_normals(meshes)
            wp.synchronize_device(device)
            out.build_seconds = time.perf_counter() - started
        out._topology = tuple(m.triangles for m in meshes)
        return out

    def update(self, meshes, camera_position, *, extra_materials=()) -> MeshBuffers:
        """These buffers for ``meshes`` seen from ``camera_position``: refitted in place when the meshes have the
        same triangles as before (only points or the camera moved), else built anew (the returned object)."""
        same = len(meshes) == len(self._topology) and all(
            a is b.triangles or np.array_equal(a, b.triangles) for a, b in zip(self._topology, meshes, strict=True))
        if not same:
            return MeshBuffers.build(meshes, camera_position, self.device, extra_materials=extra_materials)
        self._upload_materials(meshes, camera_position, extra_materials)
        if self.triangle_count:
            started = time.perf_counter()
            self.points.assign(_relative_points(meshes, camera_position))
            self.mesh.refit()
            self._upload_normals(meshes)
            wp.synchronize_device(self.device)
            self.build_seconds = time.perf_counter() - started
        self.refitted = True
        return self

    def _upload_normals(self, meshes) -> None:
        """Vertex shading normals of every mesh (zeros for a mesh without them), or one zero when none has any."""
        if not any(m.normals is not None for m in meshes):
            self.normals = None
            return
        rows = [m.normals if m.normals is not None else np.zeros_like(m.points) for m in meshes]
        self.normals = wp.array(np.ascontiguousarray(np.concatenate(rows), dtype=np.float32), dtype=wp.vec3,
                                device=self.device)

    def _upload_materials(self, meshes, camera_position, extra_materials) -> None:
        eye = np.asarray(camera_position, dtype=np.float64)
        specs = [(m.albedo, m.albedo_map) for m in meshes] + [(a, t) for a, t in extra_materials]
        structs, chunks, offset = [], [], 0
        for albedo, texture in specs:
            structs.append(_material(albedo, texture, offset, eye))
            if texture is not None:
                chunks.append(texture.albedo.reshape(-1, 3))
                offset += len(chunks[-1])
        texels = np.concatenate(chunks) if chunks else np.zeros((1, 3), np.float32)
        self.materials = wp.array(structs or [SurfaceMaterial()], dtype=SurfaceMaterial, device=self.device)
        self.texels = wp.array(np.ascontiguousarray(texels, dtype=np.float32), dtype=wp.vec3, device=self.device)
        self.extra_material_base = len(meshes)

    @property
    def surfaces(self) -> SurfaceMeshes:
        """The kernels' view of these buffers."""
        out = SurfaceMeshes()
        out.mesh = wp.uint64(self.mesh.id if self.mesh is not None else 0)
        out.triangle_material = self.triangle_material
        out.materials = self.materials
        out.texels = self.texels
        out.smooth = int(self.normals is not None)
        out.normals = self.normals if self.normals is not None else wp.zeros(1, dtype=wp.vec3, device=self.device)
        out.triangle_count = self.triangle_count
        return out


def _offsets(meshes) -> list[int]:
    """Index of each mesh's first vertex in the concatenated points."""
    sizes = [len(m.points) for m in meshes]
    return [int(s) for s in np.concatenate([[0], np.cumsum(sizes)[:-1]])] if sizes else []


def _relative_points(meshes, camera_position) -> np.ndarray:
    """(N, 3) float32 camera-relative points of all meshes, subtracted in float64."""
    eye = np.asarray(camera_position, dtype=np.float64)
    return np.ascontiguousarray(np.concatenate([m.points - eye for m in meshes]), dtype=np.float32)


def no_surfaces(device) -> SurfaceMeshes:
    """A :class:`SurfaceMeshes` with no triangles (every query misses), for kernels that take occluders and a frame
    without meshes."""
    out = SurfaceMeshes()
    out.mesh = wp.uint64(0)
    out.triangle_material = wp.zeros(1, dtype=wp.int32, device=device)
    out.materials = wp.zeros(1, dtype=SurfaceMaterial, device=device)
    out.texels = wp.zeros(1, dtype=wp.vec3, device=device)
    out.normals = wp.zeros(1, dtype=wp.vec3, device=device)
    out.smooth = 0
    out.triangle_count = 0
    return out
