"""A detailed cumulus density built the way production cloud tools build one: a macro shape of soft spheres,
cauliflower billows from inverted cellular (Worley) noise, a wispy edge eroded by Perlin noise, and a flat base.

The field is evaluated by one Warp kernel per voxel (the cellular feature points are a seeded periodic lattice, the
Perlin noise is Warp's ``wp.noise``), so a 192 x 128 x 192 grid takes about a second on one CPU core once the
kernel is compiled. Values lie in [0, 1]. The demo stage's field comes from here (``tools/make_cumulus.py``).

Construction, with every length in metres:

* ``shape``: the depth inside the union of the spheres, ``max(r - |p - c|)``: positive inside, 0 on a surface;
* ``billows``: ``1 - F1`` of cellular noise at three octaves (periods ``billow``, ``billow / 2``, ``billow / 4``,
  weights 1/2, 1/3, 1/6), minus 1/2: bumps where feature points lie, creases between them, scaled by ``bump``;
* ``wisps``: two octaves of Perlin noise at ``wisp`` and ``wisp / 2``, eroding only the outer ``edge`` of the
  shape, twice as strongly at the base as at the top (ragged bases, crisp tops);
* density ``= smoothstep(0, edge, shape + bump * billows - wisps) * base_ramp``, where ``base_ramp`` rises from 0
  to 1 over ``base_ramp`` metres above the grid's floor: a flat base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

#: Cells per axis of the periodic feature-point lattice of the cellular noise.
LATTICE = 32


@wp.struct
class BillowCloud:
    """Inputs of :func:`billow_density`; lengths in metres, positions relative to the grid's lower corner."""

    voxel: wp.vec3  # voxel edge per axis
    spheres: wp.array(dtype=wp.vec4)  # (centre x, y, z, radius)
    features: wp.array3d(dtype=wp.vec3)  # feature point per lattice cell, in cell units [0, 1)^3
    billow: float  # period of the coarsest billow octave
    bump: float  # how far billows push the surface in or out
    edge: float  # depth over which the density rises from 0 to 1 inside the surface
    wisp: float  # period of the coarsest Perlin octave
    erosion: float  # how deeply wisps eat into the edge
    base_ramp: float  # height over which the density rises from 0 at the floor
    height: float  # the grid's height (the top of the shape is there)
    seed: wp.uint32


@wp.func
def cellular_f1(p: wp.vec3, features: wp.array3d(dtype=wp.vec3)) -> float:
    """Distance from ``p`` (in lattice cells) to the nearest feature point of the periodic lattice."""
    n = features.shape[0]
    cell = wp.vec3(wp.floor(p[0]), wp.floor(p[1]), wp.floor(p[2]))
    best = float(3.0)
    for dz in range(-1, 2):
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                c = cell + wp.vec3(float(dx), float(dy), float(dz))
                i = ((int(c[0]) % n) + n) % n
                j = ((int(c[1]) % n) + n) % n
                k = ((int(c[2]) % n) + n) % n
                best = wp.min(best, wp.length(c + features[i, j, k] - p))
    return best


@wp.func
def billows(p: wp.vec3, cloud: BillowCloud) -> float:
    """Inverted cellular noise over three octaves, centred on 0 (about -0.5..0.5)."""
    total = float(0.0)
    period = cloud.billow
    weights = wp.vec3(0.5, 1.0 / 3.0, 1.0 / 6.0)
    for octave in range(3):
        shift = wp.vec3(float(octave) * 7.31, float(octave) * 3.17, float(octave) * 5.53)  # decorrelates octaves
        total += weights[octave] * (1.0 - wp.min(cellular_f1(p / period + shift, cloud.features), 1.0))
        period *= 0.5
    return total - 0.5


@wp.func
def wisps(p: wp.vec3, cloud: BillowCloud) -> float:
    """Two octaves of Perlin noise mapped to [0, 1]."""
    state = wp.rand_init(int(cloud.seed))
    coarse = wp.noise(state, p / cloud.wisp)
    fine = wp.noise(state, p * (2.0 / cloud.wisp) + wp.vec3(17.0, 31.0, 7.0))
    return wp.clamp(0.5 + 0.5 * (0.65 * coarse + 0.35 * fine), 0.0, 1.0)


@wp.func
def macro_shape(p: wp.vec3, spheres: wp.array(dtype=wp.vec4)) -> float:
    """Depth of ``p`` inside the union of the spheres (radius - distance to the centre, largest; negative
    outside all of them)."""
    best = float(-1.0e9)
    for s in range(spheres.shape[0]):
        sphere = spheres[s]
        centre = wp.vec3(sphere[0], sphere[1], sphere[2])
        best = wp.max(best, sphere[3] - wp.length(p - centre))
    return best


@wp.func
def billow_density(p: wp.vec3, cloud: BillowCloud) -> float:
    """Density in [0, 1] at ``p`` (construction in the module docstring)."""
    field = macro_shape(p, cloud.spheres) + cloud.bump * billows(p, cloud)
    if field <= 0.0:
        return 0.0
    height = wp.clamp(p[1] / cloud.height, 0.0, 1.0)
    rim = 1.0 - wp.smoothstep(0.0, 2.0 * cloud.edge, field)
    field -= cloud.erosion * (2.0 - height) * rim * wisps(p, cloud)
    ramp = wp.clamp(p[1] / cloud.base_ramp, 0.0, 1.0)
    return wp.smoothstep(0.0, cloud.edge, field) * ramp


@wp.kernel
def billow_grid(cloud: BillowCloud, density: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    p = wp.vec3((float(i) + 0.5) * cloud.voxel[0], (float(j) + 0.5) * cloud.voxel[1],
                (float(k) + 0.5) * cloud.voxel[2])
    density[i, j, k] = billow_density(p, cloud)


@dataclass(frozen=True)
class BillowParams:
    """Lengths of a :class:`BillowCloud` [m] and its unitless amounts (defaults: a cumulus 2-3 km across)."""

    billow: float = 420.0
    bump: float = 260.0
    edge: float = 30.0
    wisp: float = 90.0
    erosion: float = 40.0
    base_ramp: float = 30.0


def billow_grid_numpy(shape: tuple[int, int, int], size: np.ndarray, spheres: np.ndarray, seed: int,
                      params: BillowParams = BillowParams(), device: str = "cpu") -> np.ndarray:
    """Evaluate the density on a ``shape`` grid spanning ``size`` metres from its lower corner (float32 [x, y, z]).

    ``spheres`` is an (N, 4) array of (centre x, y, z, radius) relative to the lower corner."""
    rng = np.random.default_rng(seed)
    cloud = BillowCloud()
    cloud.voxel = wp.vec3(*(np.asarray(size, dtype=np.float64) / np.array(shape)))
    cloud.spheres = wp.array(np.asarray(spheres, dtype=np.float32), dtype=wp.vec4, device=device)
    cloud.features = wp.array(rng.random((LATTICE, LATTICE, LATTICE, 3)).astype(np.float32), dtype=wp.vec3,
                              device=device)
    cloud.billow, cloud.bump, cloud.edge = params.billow, params.bump, params.edge
    cloud.wisp, cloud.erosion, cloud.base_ramp = params.wisp, params.erosion, params.base_ramp
    cloud.height = float(size[1])
    cloud.seed = wp.uint32(seed)
    out = wp.zeros(shape, dtype=float, device=device)
    wp.launch(billow_grid, dim=shape, inputs=[cloud, out], device=device)
    return out.numpy()


__all__ = ["BillowCloud", "BillowParams", "billow_density", "billow_grid", "billow_grid_numpy", "cellular_f1"]
