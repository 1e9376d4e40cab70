"""Opaque Lambertian surfaces given as triangle meshes (``UsdGeomMesh``), e.g. terrain, as plain data.

The surfaces pass (:mod:`warpsky.passes.surfaces`) ray casts them through one Warp BVH
(:mod:`warpsky.surfaces.mesh`). Every visible ``UsdGeomMesh`` of a rendered purpose is read:

=========================================== ========== ============ ===============================================
USD (on the ``Mesh`` prim)                  unit       default      meaning
=========================================== ========== ============ ===============================================
``point3f[] points``                        stage      (required)   vertex positions in the prim's space; time
                                                                    samples allowed (terrain that changes shape)
``int[] faceVertexCounts``                  --         (required)   vertices per face, each >= 3; a face of k
                                                                    vertices becomes k - 2 triangles (a fan from
                                                                    its first vertex: exact for convex faces)
``int[] faceVertexIndices``                 --         (required)   indices into ``points``, sum(counts) of them
``int[] holeIndices``                       --         []           must be empty (holes are refused)
``uniform token orientation``               --         rightHanded  winding; ``leftHanded`` faces are reversed so
                                                                    that every front face is counter-clockwise
``color3f warpsky:albedo``                  --         --           diffuse reflectance RGB in [0, 1]
``color3f[] primvars:displayColor``         --         --           used without ``warpsky:albedo``: its one value
                                                                    (constant), or the plain mean of all its values
                                                                    (per vertex, per face, ...): a mesh has one
                                                                    albedo, or a map
(neither)                                   --         0.3 grey     --
``normal3f[] normals``                      --         (none)       per-vertex shading normals (``vertex`` or
                                                                    ``varying`` interpolation; ``primvars:normals``
                                                                    wins), interpolated across each triangle;
                                                                    other interpolations are ignored (flat faces)
``asset warpsky:albedoMap``                 --         (none)       albedo texture keyed on world (x, z), as the
                                                                    ground plane's (``.npy`` (nx, nz, 3), ``.exr``
                                                                    or ``.png``), values clipped to [0, 1]
``float2 warpsky:albedoMapSize``            stage      (1e4, 1e4) m its extent along world x and z, centred on the
                                                                    prim's world origin
=========================================== ========== ============ ===============================================

The prim's world transform (time-sampled or not, with the stage's upAxis and metersPerUnit) is applied in float64,
so points 100 km from the origin keep millimetres. Shading uses the authored vertex normals where there are any
(turned to the side of the face the ray sees), else the faces' geometric normals; rays hit the flat triangles and
subdivision is ignored (the mesh is drawn as its control cage).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.stratiform import GroundTexture

#: Albedo of a mesh that authors neither ``warpsky:albedo`` nor ``primvars:displayColor``.
DEFAULT_ALBEDO = 0.3


@dataclass(frozen=True)
class TerrainMesh:
    """An opaque two-sided Lambertian triangle mesh in world space.

    Attributes:
        name: Prim path or label, for messages.
        points: (N, 3) float64 vertex positions, world metres (Y up).
        triangles: (M, 3) int32 vertex indices; counter-clockwise seen from the front (the normal's side).
        albedo: Diffuse reflectance, RGB in [0, 1] (used where there is no map).
        albedo_map: Optional albedo texture over world (x, z) (:class:`~warpsky.model.stratiform.GroundTexture`).
        source: Stage file or tool the mesh came from.
        normals: (N, 3) unit world shading normals per vertex, or None (flat faces).
    """

    name: str
    points: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray = field(default_factory=lambda: np.full(3, DEFAULT_ALBEDO))
    albedo_map: GroundTexture | None = None
    source: str = ""
    normals: np.ndarray | None = None

    def __post_init__(self):
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise SceneError(f"mesh {self.name}: points must be a finite (N, 3) array [m], got shape {points.shape}")
        object.__setattr__(self, "points", np.ascontiguousarray(points))
        triangles = np.asarray(self.triangles)
        if triangles.size == 0:
            triangles = np.zeros((0, 3), np.int32)
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
            raise SceneError(f"mesh {self.name}: triangles must be an (M, 3) integer array, got {triangles.shape}")
        if triangles.size and (triangles.min() < 0 or triangles.max() >= len(points)):
            raise SceneError(f"mesh {self.name}: triangle indices must lie in [0, {len(points) - 1}], got "
                             f"[{int(triangles.min())}, {int(triangles.max())}]")
        object.__setattr__(self, "triangles", np.ascontiguousarray(triangles, dtype=np.int32))
        albedo = np.asarray(self.albedo, dtype=np.float64).reshape(-1)
        if albedo.size == 1:
            albedo = np.repeat(albedo, 3)
        if albedo.size != 3 or not np.all(np.isfinite(albedo)) or albedo.min() < 0.0 or albedo.max() > 1.0:
            raise SceneError(f"mesh {self.name}: albedo must be an RGB reflectance in [0, 1], got {albedo.tolist()}")
        object.__setattr__(self, "albedo", albedo)
        if self.albedo_map is not None and not isinstance(self.albedo_map, GroundTexture):
            raise SceneError(f"mesh {self.name}: albedo_map must be a GroundTexture or None")
        if self.normals is not None:
            normals = np.asarray(self.normals, dtype=np.float64)
            length = np.linalg.norm(normals, axis=-1, keepdims=True) if normals.ndim == 2 else None
            if normals.shape != points.shape or not np.all(np.isfinite(normals)) or np.any(length < 1e-12):
                raise SceneError(f"mesh {self.name}: normals must be finite non-zero (N, 3) vectors, one per point "
                                 f"({len(points)}), got shape {normals.shape}")
            object.__setattr__(self, "normals", np.ascontiguousarray(normals / length))

    @property
    def triangle_count(self) -> int:
        return int(len(self.triangles))

    def __repr__(self) -> str:
        lo, hi = (self.points.min(axis=0), self.points.max(axis=0)) if len(self.points) else (np.zeros(3),) * 2
        textured = ", textured" if self.albedo_map is not None else ""
        return (f"TerrainMesh({self.name!r}, {len(self.points)} points, {self.triangle_count} triangles, "
                f"bounds {np.round(lo, 2).tolist()}..{np.round(hi, 2).tolist()} m, "
                f"albedo={np.round(self.albedo, 4).tolist()}{textured})")


def triangulate(counts: np.ndarray, indices: np.ndarray, point_count: int, where: str) -> np.ndarray:
    """(M, 3) int32 triangles from USD faces: face f of counts[f] vertices fans out from its first vertex.

    ``where`` (``"/World/Terrain"``) names the prim in the SceneError for counts < 3, an index count that does not
    match sum(counts), or indices outside [0, point_count)."""
    counts = np.asarray(counts, dtype=np.int64).reshape(-1)
    indices = np.asarray(indices, dtype=np.int64).reshape(-1)
    if counts.size and counts.min() < 3:
        face = int(np.argmax(counts < 3))
        raise SceneError(f"{where}.faceVertexCounts: every face needs at least 3 vertices, face {face} has "
                         f"{int(counts[face])}")
    if int(counts.sum()) != indices.size:
        raise SceneError(f"{where}.faceVertexIndices: has {indices.size} entries, faceVertexCounts sum to "
                         f"{int(counts.sum())}")
    if indices.size and (indices.min() < 0 or indices.max() >= point_count):
        raise SceneError(f"{where}.faceVertexIndices: indices must lie in [0, {point_count - 1}] (points has "
                         f"{point_count}), got [{int(indices.min())}, {int(indices.max())}]")
    fans = counts - 2
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]) if counts.size else np.zeros(0, np.int64)
    face_of = np.repeat(np.arange(counts.size), fans)
    # k-th triangle of a face: vertices 0, k + 1, k + 2 of it
    k = np.arange(int(fans.sum())) - np.repeat(np.concatenate([[0], np.cumsum(fans)[:-1]]) if fans.size else
                                               np.zeros(0, np.int64), fans)
    base = first[face_of]
    tris = np.stack([indices[base], indices[base + k + 1], indices[base + k + 2]], axis=-1)
    return tris.astype(np.int32).reshape(-1, 3)


def _display_albedo(prim, tc) -> np.ndarray | None:
    """``primvars:displayColor`` flattened: its value when it has one, else the mean of its values."""
    from pxr import UsdGeom

    primvar = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
    if not primvar or not primvar.HasAuthoredValue():
        return None
    values = primvar.ComputeFlattened(tc)
    if values is None or len(values) == 0:
        return None
    colors = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    return colors.mean(axis=0)


def _array_attr(prim, name: str, tc, *, required: bool) -> np.ndarray | None:
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        if required:
            raise SceneError(f"{prim.GetPath()}.{name}: must be authored on a mesh")
        return None
    value = attr.Get(tc)
    return np.asarray(value if value is not None else [])


def read_mesh(reader, prim, time_code) -> TerrainMesh:
    """The ``UsdGeomMesh`` ``prim`` at ``time_code`` (a ``Usd.TimeCode``, a float, or None: the earliest sample) as
    a :class:`TerrainMesh` in warpsky's world (the module docstring lists what is read). ``reader`` is a
    :class:`~warpsky.usd.stage.StageReader` (world transforms, attribute readers, albedo maps); visibility is the
    caller's to check (:func:`read_meshes`)."""
    from pxr import Usd, UsdGeom

    tc = time_code if isinstance(time_code, Usd.TimeCode) else reader._time(time_code)
    where = str(prim.GetPath())
    if not prim.IsA(UsdGeom.Mesh):
        raise SceneError(f"{where}: expected a Mesh prim, got {prim.GetTypeName() or 'a typeless prim'}")
    local = _array_attr(prim, "points", tc, required=True)
    local = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(local)):
        raise SceneError(f"{where}.points: {int(np.count_nonzero(~np.isfinite(local)))} values are NaN or Inf")
    holes = _array_attr(prim, "holeIndices", tc, required=False)
    if holes is not None and holes.size:
        raise SceneError(f"{where}.holeIndices: holes are not supported ({holes.size} authored); remove the faces "
                         "instead")
    counts = _array_attr(prim, "faceVertexCounts", tc, required=True)
    indices = _array_attr(prim, "faceVertexIndices", tc, required=True)
    triangles = triangulate(counts, indices, len(local), where)
    world = reader._world(prim, tc)
    points = local @ world[:3, :3].T + world[:3, 3]
    left = reader._token_attr(prim, "orientation", tc, "righthanded") == "lefthanded"
    if left != (np.linalg.det(world[:3, :3]) < 0.0):
        triangles = np.ascontiguousarray(triangles[:, ::-1])
    albedo = reader._color_attr(prim, "warpsky:albedo", tc)
    if albedo is None:
        albedo = _display_albedo(prim, tc)
    if albedo is None:
        albedo = np.full(3, DEFAULT_ALBEDO)
    if not (np.all(np.isfinite(albedo)) and albedo.min() >= 0.0 and albedo.max() <= 1.0):
        raise SceneError(f"{where}: albedo (warpsky:albedo or primvars:displayColor) must lie in [0, 1], got "
                         f"{np.round(albedo, 4).tolist()}")
    albedo_map = reader._albedo_map(prim, tc, world)
    normals = _vertex_normals(prim, tc, world, len(local), where)
    return TerrainMesh(where, points, triangles, albedo, albedo_map, str(reader.path), normals)


def _vertex_normals(prim, tc, world: np.ndarray, point_count: int, where: str) -> np.ndarray | None:
    """World shading normals per vertex from ``primvars:normals`` or ``normals`` (vertex or varying
    interpolation, one per point), transformed by the inverse transpose of the prim's transform; None otherwise."""
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(prim)
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
    if primvar and primvar.HasAuthoredValue():
        values, interpolation, name = primvar.ComputeFlattened(tc), primvar.GetInterpolation(), "primvars:normals"
    else:
        attr = mesh.GetNormalsAttr()
        if not attr.HasAuthoredValue():
            return None
        values, interpolation, name = attr.Get(tc), mesh.GetNormalsInterpolation(), "normals"
    if values is None or str(interpolation) not in ("vertex", "varying"):
        return None
    normals = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    if len(normals) != point_count:
        raise SceneError(f"{where}.{name}: {interpolation} normals need one per point ({point_count}), got "
                         f"{len(normals)}")
    normals = normals @ np.linalg.inv(world[:3, :3])  # rows n^T M^-1: the inverse transpose applied to each
    length = np.linalg.norm(normals, axis=-1)
    if not np.all(np.isfinite(normals)) or np.any(length < 1e-12):
        raise SceneError(f"{where}.{name}: normals must be finite and non-zero")
    return normals


def read_meshes(reader, time=None) -> tuple[TerrainMesh, ...]:
    """Every ``UsdGeomMesh`` of the stage that is visible at ``time`` and of a rendered purpose, in traversal
    order (:func:`read_mesh` each)."""
    from pxr import UsdGeom

    tc = reader._time(time)
    return tuple(read_mesh(reader, prim, tc) for prim in reader._prims_of(UsdGeom.Mesh) if reader._rendered(prim, tc))

