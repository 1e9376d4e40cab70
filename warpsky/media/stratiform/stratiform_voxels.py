"""A stratiform layer (Bouthors 2006) as a voxel medium, so that the path tracer can trace it as a reference for
the stratiform pass.

The layer is a height field: cloud fills base <= y <= base + thickness(x, z), with extinction κ = N0 π r_e²
(grey) and the ``stratus`` droplets' phase function. The voxel grid covers the layer's extent (or the part of it
inside ``bounds``) from the base up to the voxel row holding the highest column top. Each column of voxels stands
at one centre (x, z), where the thickness t is sampled as the stratiform pass samples it
(:func:`~warpsky.media.stratiform.thickness.sample_thickness` of the map at the frame's time, advection included); each
voxel's density is the fraction of its height inside [base, base + t] (partial volume):

    density_k = clamp((t - k Δy) / Δy, 0, 1),      k = 0 .. n_y - 1.

A :class:`~warpsky.model.scene.VoxelMedium` interpolates trilinearly between voxel centres and clamps to the edge
values out to its box; along a vertical line through a column centre that field is piecewise linear, and its
integral over the box is exactly Σ_k density_k Δy. So every column's vertical optical depth is κ t, exact for the
sampled thickness whatever Δy, and between column centres it is the bilinear interpolation of κ t. What the voxel
size does change is where the cloud's top lies within its last voxel (smeared over about one Δy) and how finely the
map's hole edges and slopes are followed horizontally.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.media.stratiform.thickness import at_time, sample_thickness, signed_thickness
from warpsky.model.scene import VoxelMedium
from warpsky.model.stratiform import StratiformLayer

#: Most voxels one layer's grid may hold (512 MiB of float32 density): a larger grid is refused before anything
#: is allocated.
VOXEL_BUDGET = 2**27

#: Species whose tabulated phase function the voxelised layer uses: the stratiform pass's droplets.
LAYER_SPECIES = "stratus"


@dataclasses.dataclass(frozen=True)
class ColumnGrid:
    """Where the voxels of a height-field medium (a stratiform layer, a height-field deck) lie, before any is
    allocated: columns over a horizontal rectangle, rows stacked from a floor.

    Attributes:
        origin: World (x, z) [m] of the grid's corner (the outer edge of voxel column (0, 0)).
        width: Horizontal voxel edges (Δx, Δz) [m].
        height: Vertical voxel edge Δy [m].
        shape: Voxel counts (n_x, n_y, n_z).
        floor: World y [m] of the grid's floor (a layer's base, a deck's lowest base).
    """

    origin: tuple[float, float]
    width: tuple[float, float]
    height: float
    shape: tuple[int, int, int]
    floor: float

    @property
    def voxels(self) -> int:
        return math.prod(self.shape)

    def column_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """World x (n_x,) and z (n_z,) of the voxel column centres [m]."""
        xs = self.origin[0] + (np.arange(self.shape[0]) + 0.5) * self.width[0]
        zs = self.origin[1] + (np.arange(self.shape[2]) + 0.5) * self.width[1]
        return xs, zs

    def world_from_index(self) -> np.ndarray:
        """4x4 affine map from index coordinates (voxel centres at integers) to world metres."""
        m = np.eye(4)
        m[0, 0], m[1, 1], m[2, 2] = self.width[0], self.height, self.width[1]
        m[:3, 3] = (self.origin[0] + 0.5 * self.width[0], self.floor + 0.5 * self.height,
                    self.origin[1] + 0.5 * self.width[1])
        return m


def layer_grid(layer: StratiformLayer, voxel: float, *, vertical: float | None = None, top: float | None = None,
               bounds=None, max_voxels: int = VOXEL_BUDGET, setting: str = "voxel") -> ColumnGrid:
    """The grid :func:`voxelize_layer` fills, checked against ``max_voxels`` (nothing is allocated).

    The layer's extent is split into whole voxels no wider than ``voxel`` [m] (so the columns tile it exactly);
    ``bounds`` ((x0, z0), (x1, z1)) [m] keeps the columns that overlap that world rectangle. Vertically the voxels
    are ``vertical`` [m] tall (default ``voxel``), stacked from the base until they reach ``top`` [m above the
    base; default the map's largest thickness], so bounded grids share the whole grid's voxels. ``setting`` names
    what set the sizes in the error messages.
    """
    where = f"stratiform layer {layer.name}"
    vertical = voxel if vertical is None else vertical
    for name, value in ((setting, voxel), (f"{setting} (vertical)", vertical)):
        if not (math.isfinite(value) and value > 0.0):
            raise UsageError(f"{where}: {name} must be a positive length [m], got {value}")
    top = float(layer.thickness.max()) if top is None else float(top)
    counts = [max(1, math.ceil(s / voxel - 1e-9)) for s in layer.size]
    width = (layer.size[0] / counts[0], layer.size[1] / counts[1])
    first, last = [0, 0], list(counts)
    if bounds is not None:
        (bx0, bz0), (bx1, bz1) = bounds
        for axis, (lo, hi) in enumerate(((bx0, bx1), (bz0, bz1))):
            start = math.floor((min(lo, hi) - layer.origin[axis]) / width[axis])
            stop = math.ceil((max(lo, hi) - layer.origin[axis]) / width[axis])
            first[axis], last[axis] = max(0, start), min(counts[axis], stop)
        if last[0] <= first[0] or last[1] <= first[1]:
            raise UsageError(f"{where}: bounds {tuple(bounds)} do not overlap the layer's extent")
    shape = (last[0] - first[0], max(1, math.ceil(top / vertical - 1e-9)), last[1] - first[1])
    if math.prod(shape) > max_voxels:
        raise UsageError(f"{where}: {setting} {voxel:g} m x {vertical:g} m (width x height) gives "
                         f"{shape[0]}x{shape[1]}x{shape[2]} = {math.prod(shape):,} voxels, over the budget of "
                         f"{max_voxels:,}; use larger voxels")
    origin = (layer.origin[0] + first[0] * width[0], layer.origin[1] + first[1] * width[1])
    return ColumnGrid(origin, width, float(vertical), shape, float(layer.base_altitude))


def column_thickness(layer: StratiformLayer, xs: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """(len(xs), len(zs)) thickness [m] of ``layer`` (a map with no advection left to apply) at the column centres
    ``xs`` x ``zs``, sampled as the stratiform pass samples it."""
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    return sample_thickness(signed_thickness(layer.thickness), layer.origin, layer.size, X, Z)


def partial_volume(thickness: np.ndarray, height: float, count: int) -> np.ndarray:
    """(n_x, count, n_z) float32 fraction of each voxel's height inside [0, thickness] for columns of ``count``
    voxels of ``height`` [m] each: clamp(t / Δy - k, 0, 1)."""
    k = np.arange(count, dtype=np.float64)[None, :, None]
    return np.clip(np.asarray(thickness, np.float64)[:, None, :] / height - k, 0.0, 1.0).astype(np.float32)


def voxelize_layer(layer: StratiformLayer, time_s: float, voxel: float, *, vertical: float | None = None,
                   bounds=None, max_voxels: int = VOXEL_BUDGET, setting: str = "voxel",
                   device: str = "cpu") -> VoxelMedium:
    """``layer``'s thickness map at ``time_s`` [s] as a partial-volume voxel medium.

    Args:
        layer: The layer (its ``time_s`` is replaced by the argument).
        time_s: Time [s] at which its (advected) map is taken.
        voxel: Largest horizontal voxel edge [m]; the extent is split into whole voxels.
        vertical: Vertical voxel edge [m] (default ``voxel``), stacked from the base; thin layers want it finer.
        bounds: Optional world rectangle ((x0, z0), (x1, z1)) [m]: only the columns overlapping it are made.
        max_voxels: A grid over this many voxels is refused (UsageError) before anything is allocated.
        setting: What set the sizes, for the error message.
        device: Warp device of the advection (an advected map is computed there).

    Returns:
        A :class:`VoxelMedium` of extinction κ [1/m] per unit density, albedo 1, species ``stratus``, whose columns
        have vertical optical depth κ t(x, z) at their centres.
    """
    layer = at_time(dataclasses.replace(layer, time_s=float(time_s)), device)
    options = {"vertical": vertical, "bounds": bounds, "max_voxels": max_voxels, "setting": setting}
    layer_grid(layer, voxel, **options)  # refuses a grid over the budget before anything is sampled
    columns = layer_grid(layer, voxel, top=0.0, **options)  # one voxel row: where the columns stand
    thickness = column_thickness(layer, *columns.column_centres())
    # voxel rows up to the highest sampled column (the map inside the bounds may be thinner than its maximum)
    grid = layer_grid(layer, voxel, top=float(thickness.max()), **options)
    density = partial_volume(thickness, grid.height, grid.shape[1])
    return VoxelMedium(
        name=layer.name,
        density=density,
        world_from_index=grid.world_from_index(),
        extinction_scale=np.full(3, layer.extinction),
        albedo=np.ones(3),
        source=f"stratiform layer {layer.name} voxelised at t = {time_s:g} s",
        species=LAYER_SPECIES,
    )
