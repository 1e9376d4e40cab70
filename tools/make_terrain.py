"""A seeded fractal terrain as a ``UsdGeomMesh``: fBm hills around a valley, a few kilometres across.

The height field is analytic (:class:`TerrainField`), so tests can compare ray hits on the mesh with it and bound
the mesh's interpolation error from its curvature:

    h(x, z) = sum over 5 octaves o, 3 directions each, of a_o sin(k_o . (x, z) + phi)       (fBm, a_o ~ 2^-o)
            + sum of 3 Gaussian hills  H exp(-|p - c|^2 / (2 s^2))
            - a straight valley        V exp(-d^2 / (2 w^2)),  d the distance to a line through the centre.

The stage (Y up, metres) holds /World/Terrain (the mesh: ``warpsky:albedo`` and a matching constant
``primvars:displayColor``), a camera looking along the valley and a sun:

    python tools/make_terrain.py --size 4000 --resolution 257 --seed 1 --out usd_scenes/terrain.usda

From Python: ``terrain_heights(x, z, seed, size)``, ``terrain_mesh(size, resolution, seed)`` (points, triangles)
and ``make_terrain_stage(path, ...)``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Albedo of the terrain (dry grass and rock), RGB.
TERRAIN_ALBEDO = (0.22, 0.24, 0.16)


@dataclass(frozen=True)
class TerrainField:
    """The analytic height field [m] of one seed over a square ``size`` [m] centred on the origin."""

    seed: int = 0
    size: float = 4000.0
    valley_angle: float | None = None  # [deg] direction of the valley's axis from +x towards +z; None: seeded

    def _parts(self):
        rng = np.random.default_rng(self.seed)
        waves = []  # (amplitude [m], kx, kz [rad/m], phase)
        for octave in range(5):
            wavelength = 0.5 * self.size / 2.0**octave
            amplitude = 60.0 * 0.5**octave * self.size / 4000.0
            for _ in range(3):
                angle = rng.uniform(0.0, 2.0 * math.pi)
                k = 2.0 * math.pi / wavelength
                waves.append((amplitude / math.sqrt(3.0), k * math.cos(angle), k * math.sin(angle),
                              rng.uniform(0.0, 2.0 * math.pi)))
        hills = [(rng.uniform(150.0, 300.0) * self.size / 4000.0, *rng.uniform(-self.size / 3, self.size / 3, 2),
                  rng.uniform(0.08, 0.15) * self.size) for _ in range(3)]  # (height, cx, cz, sigma)
        angle = rng.uniform(0.0, math.pi)
        if self.valley_angle is not None:
            angle = math.radians(self.valley_angle)
        valley = (120.0 * self.size / 4000.0, -math.sin(angle), math.cos(angle), 0.08 * self.size)  # (V, nx, nz, w)
        return waves, hills, valley

    def heights(self, x, z) -> np.ndarray:
        """Height [m] at world (x, z) [m] (any broadcastable arrays), float64."""
        x = np.asarray(x, dtype=np.float64)
        z = np.asarray(z, dtype=np.float64)
        waves, hills, valley = self._parts()
        h = np.zeros(np.broadcast(x, z).shape)
        for a, kx, kz, phase in waves:
            h += a * np.sin(kx * x + kz * z + phase)
        for height, cx, cz, sigma in hills:
            h += height * np.exp(-((x - cx) ** 2 + (z - cz) ** 2) / (2.0 * sigma**2))
        depth, nx, nz, width = valley
        h -= depth * np.exp(-((nx * x + nz * z) ** 2) / (2.0 * width**2))
        return h

    def curvature_bound(self) -> float:
        """An upper bound [1/m] of the spectral norm of the Hessian of h anywhere: a |k|^2 per wave, H / s^2 per
        hill and V / w^2 for the valley (a Gaussian's second derivative peaks at its centre)."""
        waves, hills, valley = self._parts()
        bound = sum(abs(a) * (kx * kx + kz * kz) for a, kx, kz, _ in waves)
        bound += sum(height / sigma**2 for height, _, _, sigma in hills)
        return float(bound + valley[0] / valley[3] ** 2)


def terrain_heights(x, z, seed: int = 0, size: float = 4000.0, valley_angle: float | None = None) -> np.ndarray:
    """Height [m] of the seed's terrain at world (x, z) [m] (``valley_angle`` [deg]: see :class:`TerrainField`)."""
    return TerrainField(seed, size, valley_angle).heights(x, z)


def terrain_mesh(size: float = 4000.0, resolution: int = 129, seed: int = 0,
                 offset=(0.0, 0.0, 0.0), valley_angle: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(points (n^2, 3) float64 [m], triangles (2 (n-1)^2, 3) int32) of the height field sampled on an n x n
    vertex grid over [-size/2, size/2]^2, shifted by ``offset`` [m]; every triangle counter-clockwise seen from
    above (normals up). Vertex (i, j) sits at x_i, z_j; cell (i, j) splits along its (i, j)-(i+1, j+1) diagonal."""
    n = int(resolution)
    if n < 2:
        raise ValueError(f"resolution must be >= 2 vertices per side, got {resolution}")
    axis = np.linspace(-0.5 * size, 0.5 * size, n)
    x, z = np.meshgrid(axis, axis, indexing="ij")
    y = terrain_heights(x, z, seed, size, valley_angle)
    points = np.stack([x, y, z], axis=-1).reshape(-1, 3) + np.asarray(offset, dtype=np.float64)
    return points, grid_triangles(n)


def grid_triangles(n: int) -> np.ndarray:
    """(2 (n-1)^2, 3) int32 triangles of an n x n vertex grid indexed i * n + j (i along x, j along z), wound
    counter-clockwise seen from +y."""
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i, i + n, i + 1, i + n + 1  # (i, j), (i+1, j), (i, j+1), (i+1, j+1)
    return np.stack([a, c, d, a, d, b], axis=-1).reshape(-1, 3).astype(np.int32)


def vertex_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N, 3) unit area-weighted vertex normals (the sum of the cross products of the faces around each vertex)."""
    p0, p1, p2 = (points[triangles[:, k]] for k in range(3))
    face = np.cross(p1 - p0, p2 - p0)  # length: twice the area
    normals = np.zeros_like(points, dtype=np.float64)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals / np.where(length > 0.0, length, 1.0)


def write_mesh(stage, path: str, points: np.ndarray, triangles: np.ndarray, albedo=TERRAIN_ALBEDO, *,
               smooth: bool = True):
    """Define a ``UsdGeomMesh`` at ``path`` of ``stage`` with these points (stage units) and triangles, and with
    ``smooth`` its area-weighted vertex normals (shading interpolates them across the triangles)."""
    from pxr import Gf, Sdf, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(triangles, np.int32).reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if smooth:
        normals = vertex_normals(np.asarray(points, np.float64), np.asarray(triangles))
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals, dtype=np.float32)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    lo, hi = points.min(axis=0), points.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*lo.tolist()), Gf.Vec3f(*hi.tolist())]))
    mesh.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*albedo)]))
    mesh.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*albedo))
    return mesh


def make_terrain_stage(path, *, size: float = 4000.0, resolution: int = 129, seed: int = 0,
                       valley_angle: float | None = None) -> Path:
    """Write the seed's terrain (with a camera at its south end looking north along it, and a sun) to ``path``."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    path = Path(path)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, triangles = terrain_mesh(size, resolution, seed, valley_angle=valley_angle)
    write_mesh(stage, "/World/Terrain", points, triangles)
    eye = np.array([0.0, 0.0, 0.45 * size])
    eye[1] = float(terrain_heights(eye[0], eye[2], seed, size, valley_angle)) + 0.06 * size
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.CreateFocalLengthAttr(24.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(24.0)
    camera.CreateClippingRangeAttr(Gf.Vec2f(1.0, 10.0 * size))
    xform = camera.AddTranslateOp()
    xform.Set(Gf.Vec3d(*eye.tolist()))
    camera.AddRotateXOp().Set(-12.0)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun.CreateAngleAttr(0.53)
    sun.AddRotateXYZOp().Set(Gf.Vec3f(-20.0, 75.0, 0.0))
    stage.GetRootLayer().Save()
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=float, default=4000.0, help="side of the square terrain [m]")
    parser.add_argument("--resolution", type=int, default=129, help="vertices per side (2 (n-1)^2 triangles)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the fBm, hills and valley")
    parser.add_argument("--valley-angle", type=float, default=None,
                        help="direction of the valley's axis [deg from +x towards +z] (default: from the seed)")
    parser.add_argument("--out", type=Path, required=True, help="stage to write (.usda, .usdc, .usd)")
    args = parser.parse_args(argv)
    if not (args.size > 0.0 and math.isfinite(args.size)):
        parser.error(f"--size must be a positive length [m], got {args.size}")
    if args.resolution < 2:
        parser.error(f"--resolution must be >= 2, got {args.resolution}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    make_terrain_stage(args.out, size=args.size, resolution=args.resolution, seed=args.seed,
                       valley_angle=args.valley_angle)
    print(f"wrote {args.out}: {2 * (args.resolution - 1) ** 2} triangles over {args.size:g} m, seed {args.seed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
