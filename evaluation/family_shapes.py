"""Density fields of the validation family's cloud kinds, procedural and seeded.

Each kind is a dense grid indexed ``[x, y, z]`` with values in [0, 1] (the maximum is exactly 1), zero on the
outermost voxels so the clamped ``.npy`` lookup and a background-padded VDB agree at the edges, placed in a
world box (Y up, metres) whose lower corner sits at the cloud base:

============== =====================================================================================
kind           shape
============== =====================================================================================
cumulus        soft spheres piled on a flat base, eroded by fractal value noise (tools/make_cumulus.py)
stratocumulus  a wide sheet with a bumpy top and holes where a low-frequency noise falls below a threshold
towering       a column of stacked bulges under a wide, flat anvil pushed downwind
cirrus         a thin sheet of streaks (noise stretched along one direction), high up and tenuous
inside         a broad, dense blob the camera is placed inside
storm          a towering cell (the thick family's): its anvil ice (``field:ice``), the rest cloud droplets,
               with a rain shaft below the base in a Volume of its own (:func:`storm_species`)
============== =====================================================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The kinds of the family, in the order their descriptions appear above.
KINDS = ("cumulus", "stratocumulus", "towering", "cirrus", "inside")
#: Fewest voxels along an axis (thin sheets keep at least this many across).
MIN_CELLS = 8


@dataclass(frozen=True)
class CloudShape:
    """One member's field and where it sits.

    Attributes:
        density: float32 grid ``[x, y, z]`` in [0, 1], maximum 1.
        lower: World position of the grid's lower corner [m] (x, y, z; y is the cloud base).
        upper: World position of the grid's upper corner [m].
    """

    density: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @property
    def voxel_size(self) -> np.ndarray:
        """Voxel edge per axis [m]."""
        return (self.upper - self.lower) / np.array(self.density.shape, dtype=np.float64)

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)


def value_noise(points: np.ndarray, rng: np.random.Generator, cells: int) -> np.ndarray:
    """Smooth periodic value noise in [0, 1] at ``points`` in [0, 1]^3 with ``cells`` lattice cells per axis (also
    the demo cumulus's, through :func:`fbm`, in ``tools/make_cumulus.py``)."""
    lattice = rng.random((cells, cells, cells))
    scaled = points * cells
    base = np.floor(scaled).astype(np.int64)
    frac = scaled - base
    smooth = frac * frac * (3.0 - 2.0 * frac)
    result = np.zeros(points.shape[:-1])
    for corner in np.ndindex(2, 2, 2):
        idx = (base + np.array(corner)) % cells
        weight = np.ones(points.shape[:-1])
        for axis, bit in enumerate(corner):
            weight = weight * (smooth[..., axis] if bit else 1.0 - smooth[..., axis])
        result += weight * lattice[idx[..., 0], idx[..., 1], idx[..., 2]]
    return result


def fbm(points: np.ndarray, rng: np.random.Generator, cells: int, octaves: int = 4) -> np.ndarray:
    """Fractal sum of ``octaves`` value-noise octaves (each twice the frequency, half the amplitude), in [0, 1]."""
    total = sum(0.5**o * value_noise(points, rng, cells * 2**o) for o in range(octaves))
    return total / sum(0.5**o for o in range(octaves))


def _grid(size: np.ndarray, resolution: int):
    """Cell counts (the longest axis gets ``resolution``) and cell-centre coordinates [m] from the lower corner."""
    voxel = float(size.max()) / resolution
    shape = tuple(int(np.clip(round(s / voxel), MIN_CELLS, resolution)) for s in size)
    axes = [(np.arange(n) + 0.5) * (s / n) for n, s in zip(shape, size, strict=True)]
    return shape, np.meshgrid(*axes, indexing="ij")


def _finish(density: np.ndarray, lower: np.ndarray, size: np.ndarray) -> CloudShape:
    """Clip to [0, 1], zero the border voxels, scale the maximum to 1."""
    density = np.clip(density, 0.0, 1.0)
    density[[0, -1], :, :] = 0.0
    density[:, [0, -1], :] = 0.0
    density[:, :, [0, -1]] = 0.0
    peak = float(density.max())
    if peak <= 0.0:
        raise ValueError("the generated field is empty")
    return CloudShape((density / peak).astype(np.float32), lower, lower + size)


def _unit_points(X, Y, Z, size) -> np.ndarray:
    return np.stack([X / size[0], Y / size[1], Z / size[2]], axis=-1)


def soft_spheres(X, Y, Z, blobs) -> np.ndarray:
    """Union (max) of cones 1 - distance / r of the spheres ``blobs`` (cx, cy, cz, r) at the points X, Y, Z."""
    shape = np.zeros_like(X)
    for cx, cy, cz, r in blobs:
        d = np.sqrt((X - cx) ** 2 + (Y - cy) ** 2 + (Z - cz) ** 2) / r
        shape = np.maximum(shape, np.clip(1.0 - d, 0.0, None))
    return shape


def with_turrets(rng, blobs: list, count: int) -> list:
    """``blobs`` (cx, cy, cz, r) and ``count`` smaller turrets whose centres sit on the surfaces of the first three,
    biased upwards: a cauliflower top."""
    blobs = list(blobs)
    for _ in range(count):
        cx, cy, cz, r = blobs[rng.integers(0, 3)]
        direction = rng.normal(size=3)
        direction[1] = abs(direction[1]) * 1.5
        direction /= np.linalg.norm(direction)
        radius = rng.uniform(0.25, 0.45) * r
        centre = np.array([cx, cy, cz]) + direction * r * 0.85
        blobs.append((centre[0], max(centre[1], radius * 0.6), centre[2], radius))
    return blobs


def cumulus(rng, footprint: float, base: float, resolution: int) -> CloudShape:
    """Soft spheres (a central tower, two shoulders, turrets on their surfaces) on a flat base, eroded by noise."""
    size = np.array([footprint, 0.66 * footprint, footprint])
    (_, (X, Y, Z)) = _grid(size, resolution)
    f, c = footprint, footprint / 2
    blobs = [(c, 0.26 * f, c, 0.3 * f), (c - 0.22 * f, 0.16 * f, c + 0.07 * f, 0.21 * f),
             (c + 0.21 * f, 0.15 * f, c - 0.05 * f, 0.2 * f)]
    shape = soft_spheres(X, Y, Z, with_turrets(rng, blobs, 24))
    flat_base = np.clip(Y / (0.04 * f), 0.0, 1.0)
    noise = fbm(_unit_points(X, Y, Z, size), rng, 5)
    lower = np.array([-c, base, -c])
    return _finish((shape * 3.0 - 0.8 * noise) * flat_base, lower, size)


def _edge_fade(X, Z, size, width: float = 0.1) -> np.ndarray:
    """1 inside, falling to 0 over ``width`` (a fraction of the footprint) towards the box's sides."""
    u = np.minimum(X / size[0], 1.0 - X / size[0])
    w = np.minimum(Z / size[2], 1.0 - Z / size[2])
    return np.clip(np.minimum(u, w) / width, 0.0, 1.0)


def stratocumulus(rng, footprint: float, base: float, resolution: int) -> CloudShape:
    """A sheet with a bumpy top and a flat bottom, broken by holes."""
    thickness = rng.uniform(250.0, 450.0)
    size = np.array([footprint, thickness, footprint])
    (_, (X, Y, Z)) = _grid(size, resolution)
    points = _unit_points(X, Y, Z, size)
    flat = points.copy()
    flat[..., 1] = 0.0  # columns: one value per (x, z)
    top = thickness * (0.55 + 0.4 * fbm(flat, rng, 6, octaves=3))
    holes = value_noise(flat, rng, 5)
    threshold = rng.uniform(0.35, 0.45)
    coverage = np.clip((holes - threshold) / 0.08, 0.0, 1.0)
    body = np.clip((top - Y) / (0.15 * thickness), 0.0, 1.0) * np.clip(Y / (0.1 * thickness), 0.0, 1.0)
    density = body * coverage * _edge_fade(X, Z, size) * (0.55 + 0.45 * fbm(points, rng, 8, octaves=3))
    lower = np.array([-footprint / 2, base, -footprint / 2])
    return _finish(density * 1.6, lower, size)


def towering(rng, footprint: float, base: float, resolution: int) -> CloudShape:
    """A column of stacked bulges rising into a wide, flat anvil whose centre is pushed downwind (+x)."""
    height = rng.uniform(1.0, 1.25) * footprint
    size = np.array([footprint, height, footprint])
    (_, (X, Y, Z)) = _grid(size, resolution)
    c = footprint / 2
    column_radius = rng.uniform(0.15, 0.2) * footprint
    blobs = []
    for level in np.linspace(0.1, 0.75, 7):
        wobble = rng.normal(scale=0.15 * column_radius, size=2)
        blobs.append((c + wobble[0], level * height, c + wobble[1], column_radius * rng.uniform(1.0, 1.3)))
    column = soft_spheres(X, Y, Z, blobs)
    anvil_thickness = rng.uniform(0.1, 0.15) * height
    anvil_centre = np.array([c + 0.08 * footprint, height - 1.2 * anvil_thickness, c])
    radial = np.hypot(X - anvil_centre[0], Z - anvil_centre[2]) / (0.4 * footprint)
    vertical = np.abs(Y - anvil_centre[1]) / anvil_thickness
    anvil = np.clip(1.0 - np.maximum(radial**4, vertical**2), 0.0, None)
    noise = fbm(_unit_points(X, Y, Z, size), rng, 5)
    flat_base = np.clip(Y / (0.04 * footprint), 0.0, 1.0)
    lower = np.array([-c, base, -c])
    return _finish((np.maximum(column * 3.0, anvil * 2.0) - 0.8 * noise) * flat_base, lower, size)


def cirrus(rng, footprint: float, base: float, resolution: int) -> CloudShape:
    """Thin streaks: noise stretched along a random horizontal direction inside a thin sheet."""
    thickness = rng.uniform(250.0, 400.0)
    size = np.array([footprint, thickness, footprint])
    (_, (X, Y, Z)) = _grid(size, resolution)
    angle = rng.uniform(0.0, np.pi)
    along = (np.cos(angle) * X + np.sin(angle) * Z) / footprint
    across = (-np.sin(angle) * X + np.cos(angle) * Z) / footprint
    streaks = np.stack([0.15 * along, 0.5 * Y / thickness, 1.5 * across], axis=-1)
    fibres = fbm(streaks, rng, 6, octaves=3)
    centre = 0.5 + 0.25 * (value_noise(_unit_points(X, Y, Z, size), rng, 3) - 0.5)
    profile = np.clip(1.0 - ((Y / thickness - centre) / 0.3) ** 2, 0.0, None)
    density = np.clip(fibres - 0.45, 0.0, None) * profile * _edge_fade(X, Z, size, 0.15)
    lower = np.array([-footprint / 2, base, -footprint / 2])
    return _finish(density, lower, size)


def inside(rng, footprint: float, base: float, resolution: int) -> CloudShape:
    """A broad blob, dense and filled at its centre (where the camera goes), ragged at its edges."""
    size = np.array([footprint, 0.8 * footprint, footprint])
    (_, (X, Y, Z)) = _grid(size, resolution)
    c = size / 2
    blobs = [(c[0], c[1], c[2], 0.45 * footprint)]
    for _ in range(10):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        radius = rng.uniform(0.15, 0.25) * footprint
        centre = c + direction * np.array([0.3, 0.15, 0.3]) * footprint
        blobs.append((*centre, radius))
    shape = soft_spheres(X, Y, Z, blobs)
    noise = fbm(_unit_points(X, Y, Z, size), rng, 5)
    lower = np.array([-c[0], base, -c[2]])
    return _finish(shape * 3.0 - 0.8 * noise, lower, size)


SHAPES = {"cumulus": cumulus, "stratocumulus": stratocumulus, "towering": towering, "cirrus": cirrus,
          "inside": inside, "storm": towering}
#: Height fractions of a storm cell over which the droplets give way to the anvil's ice.
ICE_FROM, ICE_TO = 0.62, 0.78
#: The rain shaft's width (a fraction of the cell's footprint) and how far it reaches up into the cell.
RAIN_WIDTH, RAIN_INTO_CELL = 0.45, 0.25


def storm_species(rng, shape: CloudShape, resolution: int) -> tuple[np.ndarray, np.ndarray, CloudShape]:
    """(cloud droplets, anvil ice) splitting a towering cell's field by height (smoothstep from ``ICE_FROM`` to
    ``ICE_TO`` of its height), and a rain shaft from the ground to ``RAIN_INTO_CELL`` of the way up the cell: a
    column ``RAIN_WIDTH`` of the footprint wide, densest at its axis, streaked by noise stretched vertically."""
    height = float(shape.upper[1] - shape.lower[1])
    y = (np.arange(shape.density.shape[1]) + 0.5) / shape.density.shape[1]
    t = np.clip((y - ICE_FROM) / (ICE_TO - ICE_FROM), 0.0, 1.0)
    ice_weight = (t * t * (3.0 - 2.0 * t))[None, :, None]
    cloud, ice = shape.density * (1.0 - ice_weight), shape.density * ice_weight
    width = RAIN_WIDTH * float(shape.upper[0] - shape.lower[0])
    top = float(shape.lower[1]) + RAIN_INTO_CELL * height
    size = np.array([width, top, width])
    (_, (X, Y, Z)) = _grid(size, max(resolution // 2, MIN_CELLS))
    radial = np.hypot(X / width - 0.5, Z / width - 0.5) / 0.5
    streaks = fbm(np.stack([X / width, 0.1 * Y / top, Z / width], axis=-1), rng, 4, octaves=3)
    fade = np.clip((top - Y) / (0.3 * (top - float(shape.lower[1]))), 0.0, 1.0)
    rain = np.clip(1.0 - radial, 0.0, None) * fade * (0.4 + 0.6 * streaks)
    centre = 0.5 * (shape.lower + shape.upper)
    lower = np.array([centre[0] - width / 2, 0.0, centre[2] - width / 2])
    return cloud.astype(np.float32), ice.astype(np.float32), _finish(rain, lower, size)


def peak_column(density: np.ndarray, voxel_size: np.ndarray) -> tuple[float, int]:
    """(largest line integral of ``density`` [field units x m] along the grid's x, y or z lines, that axis)."""
    sums = [float(density.sum(axis=a, dtype=np.float64).max()) * float(voxel_size[a]) for a in range(3)]
    axis = int(np.argmax(sums))
    return sums[axis], axis
