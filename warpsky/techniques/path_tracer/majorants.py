"""Local majorants of the path tracer: coarse grids of upper bounds on each medium's extinction.

Every medium carries a coarse grid of upper bounds on its extinction (one value per block of voxels,
:class:`MajorantGrid`), and a ray advances from block boundary to block boundary with the sum of the bounds of the
blocks it is in, so thin regions are crossed in a few steps and a thick core does not slow the rest of the cloud
down. The air's majorant over a stretch of ray is its density at the stretch's lowest point: on a flat earth the
stretch's lower end, on a round one its end or the ray's point nearest the planet's centre (its perigee) when that
lies inside it.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.media.air.medium import Air, air_bound, altitude, coefficient_at, top_entry, vertical
from warpsky.media.air.round_earth_kernels import Line, altitude_at, make_line
from warpsky.media.voxels.bricks import CoarseCells, cell_maxima, cell_step, effective_block
from warpsky.media.voxels.detail import detail_factor_bound
from warpsky.media.voxels.voxel import VoxelMedia, grid_interval, reduced_coefficients
from warpsky.model.scene import VoxelMedium
from warpsky.techniques.path_tracer.fog_media import FogTracking

#: Majorants are inflated by this factor so float32 interpolation never exceeds them.
MAJORANT_MARGIN = wp.constant(1.0001)
#: On a round earth a stretch of ray is doubled (at most :data:`STRETCH_DOUBLINGS` times) while its majorant crosses
#: at most this optical depth over it: in the thin high air few stretches, each with few null collisions on average.
STRETCH_DEPTH = wp.constant(0.25)
STRETCH_DOUBLINGS = wp.constant(16)
#: A round earth's majorant is taken this much lower [m] than a stretch's lowest point: the float32 rounding of a
#: point's altitude far from the camera (centimetres at 1000 km).
ALTITUDE_SLACK = wp.constant(0.5)
#: A ray above a round earth's air crosses in one step to where it enters the top when that is farther than this [m]
#: (nearer, float32 rounding has put a point just inside above it).
ENTRY_STEP = wp.constant(1.0)


#: One medium's majorant cells: cell (i, j, k) covers voxels [i*block, (i+1)*block) (the cells the shadow marches
#: skip empty ones of, :mod:`warpsky.media.voxels.bricks`).
MajorantGrid = CoarseCells


@wp.struct
class Majorants:
    """Every medium's majorant grid: one :class:`MajorantGrid` per medium over one flat buffer of bounds [1/m], and
    the same bounds for the media after high-order similarity (``reduced``; the same buffer when paths never
    switch to it); and the scene's analytic fogs, whose bounds come from their terms
    (:mod:`~warpsky.techniques.path_tracer.fog_media`)."""

    grids: wp.array(dtype=MajorantGrid)
    values: wp.array(dtype=float)
    reduced: wp.array(dtype=float)
    fog: FogTracking  # the analytic fogs, read only by the kernels specialised on fog


@wp.struct
class Segment:
    """The majorant [1/m] that holds from the current point to ``end`` [m along the ray]."""

    majorant: float
    end: float


@wp.struct
class Stretch:
    """A stretch of ray from a point, its length [m] and its air's majorant [1/m]."""

    length: float
    majorant: float


@wp.func
def round_stretch(air: Air, line: Line, length: float, t_left: float) -> Stretch:
    """The stretch of ``length`` [m] along ``line`` from its start (its bound taken over at most ``t_left``): the
    air's majorant at its lowest point, the start, the end or the perigee between them."""
    span = wp.min(length, t_left)
    h_end = altitude_at(line, span)
    lowest = wp.min(line.h0, h_end)
    if line.tp > 0.0 and line.tp < span:
        lowest = line.hp
    out = Stretch()
    out.length = length
    out.majorant = air_bound(air, lowest - ALTITUDE_SLACK, wp.max(line.h0, h_end)) * MAJORANT_MARGIN
    return out


@wp.func
def round_air_segment(air: Air, origin: wp.vec3, direction: wp.vec3, t: float, t_max: float) -> Segment:
    """:func:`air_segment` on a round earth: vacuum above the top of the air (a ray that rises there ends, one
    that will enter the air crosses to its entry in one step), else a stretch over which the altitude changes by
    about ``band`` (``band`` / |mu| long, at most the sqrt(2 r band) in which a ray leaving its perigee rises by
    ``band``) with the density at its lowest point, doubled while its majorant crosses at most
    :data:`STRETCH_DEPTH` optical depths (the thin high air: few stretches, few null collisions each)."""
    out = Segment()
    out.majorant = 0.0
    out.end = t_max
    ra = air.planet
    p = origin + t * direction
    h = altitude(air, p)
    mu = wp.dot(direction, vertical(air, p))
    entry = top_entry(ra, h, mu)
    if entry < 0.0:
        return out
    if entry > ENTRY_STEP:
        out.end = wp.min(out.end, t + entry)
        return out
    line = make_line(ra, h, mu)
    band = wp.min(air.band / wp.max(wp.abs(mu), 1.0e-30), wp.sqrt(2.0 * (ra.radius + h) * air.band))
    stretch = round_stretch(air, line, band, t_max - t)
    for _k in range(STRETCH_DOUBLINGS):
        if 2.0 * stretch.majorant * stretch.length > STRETCH_DEPTH or stretch.length >= t_max - t:
            break
        longer = round_stretch(air, line, 2.0 * stretch.length, t_max - t)
        if longer.majorant * longer.length > STRETCH_DEPTH:
            break
        stretch = longer
    out.majorant = stretch.majorant
    out.end = wp.min(out.end, t + stretch.length)
    return out


@wp.func
def air_segment(air: Air, origin: wp.vec3, direction: wp.vec3, t: float, t_max: float) -> Segment:
    """The air's majorant at ``origin + t * direction`` and where it changes (``t_max`` and 0 without air)."""
    out = Segment()
    out.majorant = 0.0
    out.end = t_max
    if air.enabled != 0:
        if air.round != 0:
            return round_air_segment(air, origin, direction, t, t_max)
        y = origin[1] + t * direction[1]
        dy = direction[1]
        h = air.camera_altitude + y
        if dy == 0.0:
            out.majorant = air_bound(air, h, h) * MAJORANT_MARGIN
        else:
            remaining = wp.max(coefficient_at(air, h)) / (air.gamma * wp.max(dy, 1.0e-30))
            if dy < 0.0 or remaining > 1.0e-6:
                stretch = air.band / wp.abs(dy)
                lowest = y
                highest = y + dy * wp.min(stretch, t_max - t)
                if dy < 0.0:
                    lowest = highest
                    highest = y
                out.majorant = air_bound(air, air.camera_altitude + lowest, air.camera_altitude + highest) * (
                    MAJORANT_MARGIN)
                out.end = wp.min(out.end, t + stretch)
    return out


@wp.func
def majorant_segment(media: VoxelMedia, majorants: Majorants, air: Air, origin: wp.vec3, direction: wp.vec3,
                     t: float, t_max: float, reduced: int) -> Segment:
    """Sum of the majorants of the air and all media at ``origin + t * direction`` and where the first of them
    changes; with ``reduced`` the media's bounds after high-order similarity."""
    out = air_segment(air, origin, direction, t, t_max)
    for m in range(media.count):
        grid = media.grids[m]
        mg = majorants.grids[m]
        p0 = grid.eye_index + grid.index_from_world * origin
        dir_index = grid.index_from_world * direction
        span = grid_interval(grid, p0, dir_index, t, t_max)
        if span[1] <= span[0]:
            continue
        if span[0] > t:
            out.end = wp.min(out.end, span[0])  # the medium starts ahead: the majorant changes there
            continue
        step = cell_step(mg, p0, dir_index, t, span[1])
        if reduced != 0:
            out.majorant += majorants.reduced[step.index]
        else:
            out.majorant += majorants.values[step.index]
        out.end = wp.min(out.end, step.end)
    return out


#: Automatic majorant cells: the largest power-of-two edge (within AUTO_BLOCKS) whose cell holds at most this
#: optical depth across an edge at the medium's densest point (its detail bound included). Null collisions fall
#: with finer cells, crossings rise: on the storm (15 optical depths per 250 m voxel) 2-voxel cells trace 1.5x the
#: paths per second of 8-voxel ones (48x32, 16 spp), on the demo cumulus (0.75 per voxel) 8-voxel cells 1.4x those
#: of 2-voxel ones (96x64); the choice changes no expectation, only the speed.
AUTO_BLOCK_DEPTH = 6.0
AUTO_BLOCKS = (2, 8)


def medium_block(medium: VoxelMedium, block: int | None) -> int:
    """Majorant cell edge [voxels] for ``medium``: ``block`` when given, else the automatic one (see
    :data:`AUTO_BLOCK_DEPTH`)."""
    if block is not None:
        return int(block)
    peak = float(np.max(medium.density)) if medium.density.size else 0.0
    depth = peak * float(np.max(medium.extinction_scale)) * detail_factor_bound(medium) * float(
        np.min(medium.voxel_size))
    edge = AUTO_BLOCKS[1]
    while edge > AUTO_BLOCKS[0] and edge * depth > AUTO_BLOCK_DEPTH:
        edge //= 2
    return edge


#: Upper bounds of a trilinearly interpolated grid over coarse cells of ``block`` voxels.
majorant_grid = cell_maxima


def cell_bounds(cells: np.ndarray, coefficient: float, medium: VoxelMedium) -> np.ndarray:
    """Majorants [1/m] of cells whose densest field values are ``cells`` (:func:`majorant_grid`), for extinction
    ``coefficient`` per unit field value: with :data:`MAJORANT_MARGIN` and the detail bound."""
    bound = cells * coefficient
    bound *= float(MAJORANT_MARGIN)
    bound *= detail_factor_bound(medium)
    return bound


def upload_majorants(media: tuple[VoxelMedium, ...], block: int | None, device, *, cache_name: str | None = None,
                     reduced: bool = False) -> tuple[Majorants, int]:
    """Majorant grids of ``media`` (cells of ``block`` voxels, None: each medium's :func:`medium_block`; bounds on
    extinction times the detail bound, with :data:`MAJORANT_MARGIN`) uploaded to ``device``, and the number of
    cells; with ``reduced`` also the bounds on the extinction after high-order similarity (sigma_t - g sigma_s).
    With ``cache_name`` the bounds go through :func:`warpsky.core.device_buffers.upload` (no copy when the previous
    frame's bounds were the same)."""
    mgrids, chunks, reduced_chunks, offset = [], [], [], 0
    for medium in media:
        edge = medium_block(medium, block)
        cells = majorant_grid(medium.density, edge)
        bound = cell_bounds(cells, float(np.max(medium.extinction_scale)), medium)
        if reduced:
            coefficient = float(np.max(reduced_coefficients(medium)[0]))
            reduced_chunks.append(cell_bounds(cells, max(coefficient, 0.0), medium).reshape(-1))
        mg = MajorantGrid()
        mg.offset = offset
        mg.shape = wp.vec3i(*bound.shape)
        mg.block = float(effective_block(medium.density.shape, edge))
        mgrids.append(mg)
        chunks.append(bound.reshape(-1))
        offset += bound.size
    out = Majorants()
    values = np.concatenate(chunks) if chunks else np.zeros(1, np.float32)
    if cache_name is None:
        out.values = wp.array(values, dtype=float, device=device)
    else:
        out.values = device_buffers.upload(cache_name, values, float, device)
    out.reduced = out.values
    if reduced and reduced_chunks:
        bounds = np.concatenate(reduced_chunks).astype(np.float32)
        out.reduced = (wp.array(bounds, dtype=float, device=device) if cache_name is None
                       else device_buffers.upload(f"{cache_name}:reduced", bounds, float, device))
    out.grids = wp.array(mgrids if mgrids else [MajorantGrid()], dtype=MajorantGrid, device=device)
    return out, offset
