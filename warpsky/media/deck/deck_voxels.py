"""A height-field cloud deck (Max 1986) and its haze as voxel media, so that the path tracer can trace them as a
reference for the deck pass.

The deck fills H + h(f) < y < H + g(f) where the pattern f(x, z, t) > 0
(:mod:`warpsky.model.deck`). The grid covers a horizontal square around a centre (the camera) and,
vertically, the deck's band [H + h(f_max), H + g(f_max)] in rows of height Δy from the band's floor. Each voxel
column is split into s x s sub-columns at the centres of an s x s partition of its footprint; in each sub-column the
cloud is the interval [h, g] (empty where f <= 0), and a voxel's density is the part of its height that interval
covers, averaged over the sub-columns (partial volume):

    density_k = mean over sub-columns of clamp(min(g, (k + 1) Δy) - max(h, k Δy), 0, Δy) / Δy.

A :class:`~warpsky.model.scene.VoxelMedium` interpolates trilinearly between voxel centres and clamps to the edge
values out to its box, so along a vertical line through a column centre its integral is exactly Σ_k density_k Δy:
every column's vertical optical depth is ρ times the mean of (g - h) over its s x s sub-columns (s = 1: ρ (g - h) at
the column centre, to float32 precision), whatever Δy. The sub-columns follow the deck's edges and holes within the
footprint (no staircase of whole voxels); what Δy changes is where the tops and bases lie within their voxels
(smeared over about one Δy).

The haze (Max §5) is a second medium: one voxel of density 1 whose box is the slab [floor, top] over the same
square, so it is exactly homogeneous there (extinction, albedo and Henyey-Greenstein g of the haze).
"""

from __future__ import annotations

import math

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.media.stratiform.stratiform_voxels import VOXEL_BUDGET, ColumnGrid
from warpsky.model.deck import CloudDeck
from warpsky.model.scene import PhaseKind, PhaseModel, VoxelMedium


def deck_grid(clouds: CloudDeck, centre_xz, half_size: float, width: float, height: float, *,
              max_voxels: int = VOXEL_BUDGET, setting: str = "voxel") -> ColumnGrid:
    """The grid :func:`voxelize_deck` fills, checked against ``max_voxels`` (nothing is allocated).

    The square of half-size ``half_size`` [m] around world ``centre_xz`` is split into whole voxels no wider than
    ``width`` [m] (square columns); rows of ``height`` [m] are stacked from the deck's lowest base until they reach
    its highest top.
    ``setting`` names what set the sizes in the error messages."""
    where = f"height-field clouds {clouds.name}"
    for name, value in ((f"{setting} (extent)", half_size), (f"{setting} (width)", width),
                        (f"{setting} (height)", height)):
        if not (math.isfinite(value) and value > 0.0):
            raise UsageError(f"{where}: {name} must be a positive length [m], got {value}")
    low, high = clouds.band
    count = max(1, math.ceil(2.0 * half_size / width - 1e-9))
    shape = (count, max(1, math.ceil((high - low) / height - 1e-9)), count)
    if math.prod(shape) > max_voxels:
        raise UsageError(f"{where}: {setting} {width:g} m x {height:g} m (width x height) over a square of half-size "
                         f"{half_size:g} m gives {shape[0]}x{shape[1]}x{shape[2]} = {math.prod(shape):,} voxels, over "
                         f"the budget of {max_voxels:,}; use larger voxels or a smaller extent")
    cx, cz = (float(v) for v in centre_xz)
    edge = 2.0 * half_size / count
    return ColumnGrid((cx - half_size, cz - half_size), (edge, edge), float(height), shape, float(low))


def sub_column_offsets(width: float, supersample: int) -> np.ndarray:
    """Offsets [m] of the s sub-column centres from a column centre along one axis: ((j + 1/2) / s - 1/2) width."""
    return ((np.arange(supersample) + 0.5) / supersample - 0.5) * width


def cloud_fractions(clouds: CloudDeck, grid: ColumnGrid, time_s: float, supersample: int,
                    device: str = "cpu") -> np.ndarray:
    """(n_x, n_y, n_z) float32 partial-volume densities of the deck at ``time_s`` [s] (module docstring), computed
    by :mod:`~warpsky.media.deck.deck_voxel_kernels` on ``device`` (row bands over the CPU's threads)."""
    import warp as wp

    from warpsky.core.device import launch_rows
    from warpsky.media.deck.deck_voxel_kernels import deck_columns, deck_fractions_kernel

    nx, ny, nz = grid.shape
    with wp.ScopedDevice(device):
        out = wp.zeros((nx, ny, nz), dtype=float)
        launch_rows(deck_fractions_kernel, nx, nz, [deck_columns(clouds, grid, time_s, supersample, device), out],
                    device)
        return out.numpy()


def voxelize_deck(clouds: CloudDeck, time_s: float, centre_xz, half_size: float, width: float,
                  height: float, *, supersample: int = 4, max_voxels: int = VOXEL_BUDGET,
                  setting: str = "voxel", device: str = "cpu") -> tuple[VoxelMedium, ...]:
    """The deck at ``time_s`` [s] (waves moved to that time) over the square of half-size ``half_size`` [m] around
    world ``centre_xz`` as a partial-volume voxel medium, and its haze (if any) as a homogeneous box.

    Args:
        clouds: The deck.
        time_s: Time [s] of the wave motion.
        centre_xz: World (x, z) [m] the square is centred on.
        half_size: Half the square's edge [m].
        width: Largest horizontal voxel edge [m]; the square is split into whole voxels.
        height: Vertical voxel edge [m], stacked from the deck's lowest base.
        supersample: Sub-columns per column along x and z (s; s^2 per column).
        max_voxels: A grid over this many voxels is refused (UsageError) before anything is allocated.
        setting: What set the sizes, for the error message.
        device: Where the voxelisation's kernel runs (the grid is returned on the host).

    Returns:
        (cloud,) or (cloud, haze): the cloud of extinction rho * extinction_scale [1/m] per unit density, its albedo
        and HG phase; the haze of its density [1/m], albedo and HG phase, between its floor and top.
    """
    if isinstance(supersample, bool) or int(supersample) != supersample or supersample < 1:
        raise UsageError(f"height-field clouds {clouds.name}: supersample must be a whole number >= 1, "
                         f"got {supersample!r}")
    grid = deck_grid(clouds, centre_xz, half_size, width, height, max_voxels=max_voxels, setting=setting)
    cloud = VoxelMedium(
        name=clouds.name,
        density=cloud_fractions(clouds, grid, time_s, int(supersample), device),
        world_from_index=grid.world_from_index(),
        extinction_scale=clouds.extinction,
        albedo=clouds.albedo,
        phase=PhaseModel(PhaseKind.HG, clouds.g),
        source=f"height-field clouds {clouds.name} voxelised at t = {time_s:g} s",
    )
    if clouds.haze is None:
        return (cloud,)
    return cloud, haze_box(clouds, grid)


def haze_box(clouds: CloudDeck, grid: ColumnGrid) -> VoxelMedium:
    """The deck's haze as one voxel of density 1 filling [floor, top] over the grid's square."""
    haze = clouds.haze
    span = grid.width[0] * grid.shape[0]
    floor, top = haze.floor, clouds.haze_top
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = span, top - floor, span
    m[:3, 3] = (grid.origin[0] + 0.5 * span, 0.5 * (floor + top), grid.origin[1] + 0.5 * span)
    return VoxelMedium(f"{clouds.name} (haze)", np.ones((1, 1, 1), np.float32), m, haze.density, haze.albedo,
                       PhaseModel(PhaseKind.HG, haze.g), source=f"haze of {clouds.name}, {floor:g} .. {top:g} m")
