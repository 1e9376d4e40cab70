"""Oriented ice in the renderers: each frame's phase of an ice field's crystals towards the sun, by look direction.

Randomly oriented crystals scatter by the scattering angle alone, so the techniques look their phase up in the
species' table. Oriented crystals (:mod:`warpsky.optics.oriented_ice`) scatter sunlight by where the observer looks
relative to the sun's elevation and azimuth. For one frame the sun is fixed, so the sunlight scattered at a point
of an oriented ice field is a function of the look direction alone (the direction the ray travelled to reach the
point): one slice of the oriented table at the frame's sun elevation, over the sky bins around the sun.

An ice field with oriented crystals (``warpsky:ice:orientation`` other than ``random``) holds a mixture: a number
fraction f of crystals of the oriented law and 1 - f randomly oriented columns of the ``ice`` species. Each part
scatters in proportion to its number times its crystals' orientation-averaged projected area (a fourth of the
surface, Cauchy), so the slice here is

    p(look) = w p_oriented(e, look) + (1 - w) p_ice(theta),   w = f S_o / (f S_o + (1 - f) S_ice),

with S the crystals' surface areas and theta the scattering angle of the look direction. The field's extinction
stays what the stage gives, the same from every direction (oriented crystals present more area to some directions
than others; that dependence is left out).

Which light uses the slice: the sunlight scattered once towards the eye (single_scatter, hybrid's march, slicing's
first order) and the sunlight reaching every path vertex of the path tracer (next-event estimation). Paths that go
on scattering through oriented ice use the table for any incoming direction (:mod:`warpsky.optics.oriented_sampling`).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

from warpsky.numerics import bilinear_cell, bilinear_mix
from warpsky.optics.oriented_ice_kernels import SkyGrid

#: Sun elevations are rounded to this step [deg] before a table is built, so that frames a hair apart share it.
SUN_ELEVATION_STEP_DEG = 0.1
#: Photons per channel for a frame's table: the parhelion's peak bin then carries about 1 % noise.
FRAME_PHOTONS = 4_000_000


@wp.struct
class OrientedPhases:
    """The frame's oriented-ice slices as kernels see them.

    Attributes:
        values: Flat (slices, elevation bins, azimuth bins, 3) phase [1/sr] over look directions.
        slice_of: Per medium, its slice, or -1 for a medium scattering by its phase table alone.
        sun_from_world: Rows are the sun frame's axes in world coordinates (X horizontal towards the sun, Y up).
        grid: The sky bins of every slice.
        count: Number of slices (0: no medium is oriented; nothing else is read).
    """

    values: wp.array(dtype=float)
    slice_of: wp.array(dtype=int)
    sun_from_world: wp.mat33
    grid: SkyGrid
    count: int


@wp.func
def slice_texel(phases: OrientedPhases, slice_index: int, row: int, column: int) -> wp.vec3:
    base = ((slice_index * phases.grid.elevation_bins + row) * phases.grid.azimuth_bins + column) * 3
    return wp.vec3(phases.values[base], phases.values[base + 1], phases.values[base + 2])


@wp.func
def oriented_value(phases: OrientedPhases, slice_index: int, look: wp.vec3) -> wp.vec3:
    """Phase [1/sr] of slice ``slice_index`` seen along the world look direction ``look`` (unit), bilinear
    between the bin centres in (elevation, azimuth from the sun) so that the arcs' edges do not show the bins."""
    local = phases.sun_from_world * look
    horizontal = wp.sqrt(local[0] * local[0] + local[2] * local[2])
    y = (wp.atan2(local[1], horizontal) + 0.5 * wp.pi) / phases.grid.elevation_step
    x = wp.atan2(wp.abs(local[2]), local[0]) / phases.grid.azimuth_step
    cell = bilinear_cell(wp.vec2(x, y), wp.vec2i(phases.grid.azimuth_bins, phases.grid.elevation_bins))
    lo = cell.lo  # (column, row)
    hi = cell.hi
    return bilinear_mix(slice_texel(phases, slice_index, lo[1], lo[0]), slice_texel(phases, slice_index, lo[1], hi[0]),
                        slice_texel(phases, slice_index, hi[1], lo[0]), slice_texel(phases, slice_index, hi[1], hi[0]),
                        cell.frac)


def sun_elevation_deg(scene) -> float:
    """The frame's sun elevation [deg], clamped to [0, 90] and rounded to :data:`SUN_ELEVATION_STEP_DEG` (a set
    sun lights nothing, and its slice is never read)."""
    if scene.sun is None:
        return 0.0
    sine = float(np.clip(np.asarray(scene.sun.direction, dtype=np.float64)[1], 0.0, 1.0))
    degrees = math.degrees(math.asin(sine))
    return round(degrees / SUN_ELEVATION_STEP_DEG) * SUN_ELEVATION_STEP_DEG


def oriented_media(media) -> list[int]:
    """Indices of the media whose ice crystals are oriented."""
    return [i for i, m in enumerate(media) if m.ice is not None and m.ice.orientation != "random"]


def frame_slices(scene, *, photons: int = FRAME_PHOTONS) -> tuple[np.ndarray, list[int], object]:
    """((slices, E, A, 3) float32 phase, slice index per medium (-1: none), the sky bins) for the frame's sun.

    One slice per oriented medium, its oriented table built at the frame's sun elevation (cached on disk by
    :func:`~warpsky.optics.oriented_ice.oriented_ice_table`, with a progress line while it builds) and mixed with
    the ``ice`` species' random phase as the module docstring says."""
    from warpsky.optics.oriented_ice import SkyBins

    grid = SkyBins()
    indices = oriented_media(scene.media)
    slice_of = [-1] * len(scene.media)
    if not indices:
        return np.zeros((0, grid.elevation_bins, grid.azimuth_bins, 3), np.float32), slice_of, grid
    elevation = sun_elevation_deg(scene)
    slices = []
    for index in indices:
        slices.append(_frame_slice(scene.media[index].ice, elevation, photons))
        slice_of[index] = len(slices) - 1
    return np.stack(slices), slice_of, grid


@functools.lru_cache(maxsize=8)
def _frame_slice(spec, elevation_deg: float, photons: int) -> np.ndarray:
    """The mixed slice of an ice field's crystals (:class:`~warpsky.scene.model.IceCrystals`) for a sun at
    ``elevation_deg``, kept per process: the frames of a batch, and hybrid's march and paths within a frame, share
    it instead of loading and mixing the table again (callers must not write into it)."""
    from warpsky.optics.oriented_ice import IceOrientation, SkyBins, oriented_ice_table

    grid = SkyBins()
    orientation = IceOrientation(spec.orientation, spec.tilt_deg, spec.habit)
    table = oriented_ice_table(orientation, sun_elevations_deg=(elevation_deg,), grid=grid, photons=photons)
    return mixed_slice(table.phase[0], spec.fraction, orientation, grid, elevation_deg)


def mixed_slice(oriented: np.ndarray, fraction: float, orientation, grid, elevation_deg: float) -> np.ndarray:
    """(E, A, 3) float32: an oriented slice for a sun at ``elevation_deg`` mixed with the ``ice`` species' random
    phase on the same bins, weighted as the module docstring says."""
    from warpsky.optics.tables import phase_table

    weight = _oriented_weight(fraction, orientation)
    if weight >= 1.0:
        return oriented.astype(np.float32)
    random_phase = _random_phase_on_bins(phase_table("ice"), grid, elevation_deg)
    return (weight * oriented + (1.0 - weight) * random_phase).astype(np.float32)


def _oriented_weight(fraction: float, orientation) -> float:
    """Share of the scattering by the oriented crystals: number fraction times surface (mean projected area)."""
    from warpsky.optics.ice import HABITS
    from warpsky.optics.species import get_species

    oriented = fraction * orientation.crystal.surface_area
    random = (1.0 - fraction) * HABITS[get_species("ice").params["habit"]].surface_area
    return oriented / (oriented + random) if oriented + random > 0.0 else 0.0


def _random_phase_on_bins(phase_table: np.ndarray, grid, elevation_deg: float) -> np.ndarray:
    """(E, A, 3) random-orientation phase [1/sr] as bin averages around a sun at ``elevation_deg`` (the species
    table (3, M) on the shared angle grid), normalised on the bins per channel."""
    from warpsky.optics.oriented_ice import profile_bins

    return np.stack([profile_bins(phase_table[c], elevation_deg, grid) for c in range(3)], axis=-1)


def oriented_phases(scene, device, *, cache: str | None = None) -> OrientedPhases:
    """The kernels' :class:`OrientedPhases` for ``scene`` on ``device``. Without oriented media it is an empty
    struct (count 0) that kernels skip. With ``cache`` (a name such as ``"slicing"``) the arrays are kept on the
    device under ``<cache>:oriented*`` and uploaded only when their contents change
    (:func:`warpsky.device_buffers.upload`), so a batch's frames pass the same addresses."""
    from warpsky import device_buffers
    from warpsky.optics.oriented_ice import sun_frame

    values, slice_of, grid = frame_slices(scene)
    out = OrientedPhases()
    out.count = int(values.shape[0])
    flat = np.ascontiguousarray(values.reshape(-1) if out.count else np.zeros(1), dtype=np.float32)
    index = np.asarray(slice_of or [-1], dtype=np.int32)
    if cache is None:
        out.values = wp.array(flat, dtype=float, device=device)
        out.slice_of = wp.array(index, dtype=int, device=device)
    else:
        out.values = device_buffers.upload(f"{cache}:oriented", flat, float, device)
        out.slice_of = device_buffers.upload(f"{cache}:oriented_slice_of", index, int, device)
    direction = scene.sun.direction if scene.sun is not None else np.array([0.0, 1.0, 0.0])
    out.sun_from_world = wp.mat33(*sun_frame(direction).reshape(-1).tolist())
    out.grid = grid.struct()
    return out
