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

with S the crystals' surface areas and theta the scattering angle of the look direction. The kernels evaluate the
two parts apart (:func:`oriented_value`): the oriented table, built for the frame on 0.25° x 0.25° sky bins
(:data:`FRAME_BIN_DEG`), bilinearly between their centres; the random crystals' phase from the ``ice`` species'
table by theta (the shared angle grid, 0.1° steps at the halos). Mixed on the sky bins instead, the 22° halo's
inner edge took the bins' steps: up to 3 pixels from one position angle to the next in the 768-wide sundogs frame,
0.6 since (``evaluation/benchmarks/bench_halo_edge.py``). The field's extinction stays what the stage gives, the same
from every direction (oriented crystals present more area to some directions than others; that dependence is left
out).

Which light uses the slice: the sunlight scattered once towards the eye (single_scatter, hybrid's march, slicing's
first order) and the sunlight reaching every path vertex of the path tracer (next-event estimation). Paths that go
on scattering through oriented ice use the table for any incoming direction (:mod:`warpsky.optics.oriented_sampling`).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

from warpsky.core.numerics import bilinear_cell, bilinear_mix
from warpsky.optics.kernels import scattering_angle, table_phase
from warpsky.optics.oriented_ice_kernels import SkyGrid

#: Sun elevations are rounded to this step [deg] before a table is built, so that frames a hair apart share it.
SUN_ELEVATION_STEP_DEG = 0.1
#: Sky bins of a frame's table, (elevation, azimuth) [deg]: at 0.25° a bin is 1.4 pixels of a 768-wide frame
#: with a 104° field of view, fine enough that the tangent arcs' and parhelia's edges show no steps.
FRAME_BIN_DEG = (0.25, 0.25)
#: Photons per channel for a frame's table: 8 times the 4 M that gave 1 % noise in a parhelion's peak bin of
#: 1° x 0.5°, for bins 8 times smaller.
FRAME_PHOTONS = 32_000_000


@wp.struct
class OrientedPhases:
    """The frame's oriented-ice slices as kernels see them.

    Attributes:
        values: Flat (slices, elevation bins, azimuth bins, 3) phase [1/sr] of the oriented crystals alone over
            look directions (bin averages, each slice normalised on the bins).
        random_share: Per slice, the share 1 - w of the scattering by the random crystals mixed in.
        random: Flat (3, angle grid nodes) phase [1/sr] of the ``ice`` species (random columns) by scattering angle.
        slice_of: Per medium, its slice, or -1 for a medium scattering by its phase table alone.
        sun_from_world: Rows are the sun frame's axes in world coordinates (X horizontal towards the sun, Y up).
        sun: Unit vector towards the sun (world).
        grid: The sky bins of every slice.
        count: Number of slices (0: no medium is oriented; nothing else is read).
    """

    values: wp.array(dtype=float)
    random_share: wp.array(dtype=float)
    random: wp.array(dtype=float)
    slice_of: wp.array(dtype=int)
    sun_from_world: wp.mat33
    sun: wp.vec3
    grid: SkyGrid
    count: int


@wp.func
def slice_texel(phases: OrientedPhases, slice_index: int, row: int, column: int) -> wp.vec3:
    base = ((slice_index * phases.grid.elevation_bins + row) * phases.grid.azimuth_bins + column) * 3
    return wp.vec3(phases.values[base], phases.values[base + 1], phases.values[base + 2])


@wp.func
def oriented_value(phases: OrientedPhases, slice_index: int, look: wp.vec3) -> wp.vec3:
    """Mixed phase [1/sr] of slice ``slice_index`` seen along the world look direction ``look`` (unit): the
    oriented crystals' table (:func:`oriented_table_value`) and the random crystals' phase at the look direction's
    scattering angle, weighted by their shares (module docstring)."""
    oriented = oriented_table_value(phases, slice_index, look)
    share = phases.random_share[slice_index]
    if share <= 0.0:
        return oriented
    random = table_phase(phases.random, 0, scattering_angle(look, phases.sun))
    return oriented * (1.0 - share) + random * share


@wp.func
def oriented_table_value(phases: OrientedPhases, slice_index: int, look: wp.vec3) -> wp.vec3:
    """Phase [1/sr] of the oriented crystals of slice ``slice_index`` seen along the world look direction ``look``
    (unit), bilinear between the bin centres in (elevation, azimuth from the sun), clamped at the end bins."""
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


def frame_bins():
    """The :class:`~warpsky.optics.oriented_ice.SkyBins` of a frame's table (:data:`FRAME_BIN_DEG`)."""
    from warpsky.optics.oriented_ice import SkyBins

    return SkyBins(*FRAME_BIN_DEG)


def oriented_media(media) -> list[int]:
    """Indices of the media whose ice crystals are oriented."""
    return [i for i, m in enumerate(media) if m.ice is not None and m.ice.orientation != "random"]


def frame_slices(scene, *, photons: int | None = None) -> tuple[np.ndarray, np.ndarray, list[int], object]:
    """((slices, E, A, 3) float32 phase of the oriented crystals, (slices,) the random crystals' share of the
    scattering, slice index per medium (-1: none), the sky bins) for the frame's sun.

    One slice per oriented medium, its oriented table built at the frame's sun elevation with ``photons`` per
    channel (default :data:`FRAME_PHOTONS`; cached on disk by
    :func:`~warpsky.optics.oriented_ice.oriented_ice_table`, with a progress line while it builds); the kernels mix
    it with the ``ice`` species' random phase by that share (module docstring; :func:`mixed_slice` does it on the
    bins)."""
    grid = frame_bins()
    indices = oriented_media(scene.media)
    slice_of = [-1] * len(scene.media)
    if not indices:
        return np.zeros((0, grid.elevation_bins, grid.azimuth_bins, 3), np.float32), np.zeros(0), slice_of, grid
    elevation = sun_elevation_deg(scene)
    photons = FRAME_PHOTONS if photons is None else int(photons)
    slices, shares = [], []
    for index in indices:
        values, share = _frame_slice(scene.media[index].ice, elevation, photons)
        slices.append(values)
        shares.append(share)
        slice_of[index] = len(slices) - 1
    return np.stack(slices), np.array(shares), slice_of, grid


@functools.lru_cache(maxsize=8)
def _frame_slice(spec, elevation_deg: float, photons: int) -> tuple[np.ndarray, float]:
    """(the oriented table's slice, the random crystals' share 1 - w) of an ice field's crystals
    (:class:`~warpsky.model.scene.IceCrystals`) for a sun at ``elevation_deg``, kept per process: the frames of a
    batch, and hybrid's march and paths within a frame, share it instead of loading the table again (callers must
    not write into it)."""
    from warpsky.optics.oriented_ice import IceOrientation, oriented_ice_table

    orientation = IceOrientation(spec.orientation, spec.tilt_deg, spec.habit)
    table = oriented_ice_table(orientation, sun_elevations_deg=(elevation_deg,), grid=frame_bins(), photons=photons)
    return table.phase[0].astype(np.float32), 1.0 - _oriented_weight(spec.fraction, orientation)


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
    (:func:`warpsky.core.device_buffers.upload`), so a batch's frames pass the same addresses."""
    from warpsky.core import device_buffers
    from warpsky.optics.oriented_ice import sun_frame
    from warpsky.optics.tables import phase_table

    values, shares, slice_of, grid = frame_slices(scene)
    out = OrientedPhases()
    out.count = int(values.shape[0])
    arrays = {
        "values": (values.reshape(-1) if out.count else np.zeros(1), float),
        "random_share": (shares if out.count else np.zeros(1), float),
        "random": (phase_table("ice").reshape(-1) if out.count else np.zeros(1), float),
        "slice_of": (np.asarray(slice_of or [-1], dtype=np.int32), int),
    }
    for name, (array, dtype) in arrays.items():
        array = np.ascontiguousarray(array, dtype=np.int32 if dtype is int else np.float32)
        if cache is None:
            setattr(out, name, wp.array(array, dtype=dtype, device=device))
        else:
            key = "oriented" if name == "values" else f"oriented_{name}"
            setattr(out, name, device_buffers.upload(f"{cache}:{key}", array, dtype, device))
    direction = scene.sun.direction if scene.sun is not None else np.array([0.0, 1.0, 0.0])
    out.sun_from_world = wp.mat33(*sun_frame(direction).reshape(-1).tolist())
    out.sun = wp.vec3(*np.asarray(direction, dtype=np.float32).tolist())
    out.grid = grid.struct()
    return out
