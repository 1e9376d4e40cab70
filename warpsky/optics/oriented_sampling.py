"""Oriented ice for light that has scattered before: the phase for any incoming direction, and sampling it.

The sun's own light meets oriented crystals from one direction per frame (:mod:`warpsky.optics.oriented_phase`).
Light that has scattered already arrives from anywhere, so a path tracer continuing a path through oriented ice
needs the phase for every incoming elevation. This module keeps, per oriented medium, the oriented table at
:data:`SAMPLING_ELEVATIONS` (each slice mixed with the random crystals as the frame's slice is), and

* evaluates T(s, l), the phase of light from direction s (towards its source) seen along look direction l:
  piecewise constant over the sky bins (1° x 0.5°), linear in the elevation of s between the two nearest
  slices; an s below the horizon mirrors s and l top to bottom (the orientation laws are symmetric under it);
* samples it. A path tracer arrives at a scattering point along d (the look direction there) and needs the
  direction s the light came from, with density proportional to T(s, d). By Helmholtz reciprocity
  T(s, d) = T(-d, -s), which is a slice of the table with -d as its source: pick the slice (k or k + 1, by the
  interpolation weight), a bin by the green channel's marginal and conditional CDFs, a uniform point in the bin
  (uniform in the sine of the elevation and in azimuth), a random azimuth sign; s is minus that look direction.
  Its density is exactly T(-d, -s) in the green channel, which the path tracer divides by.

Both the value and the density are taken in the reciprocal form T(-d, -s), so a sample's weight in the green
channel is 1 and the other channels carry their ratio to green (the dispersion of the halos).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

from warpsky.core.numerics import cdf_search
from warpsky.optics.oriented_ice_kernels import SkyGrid

#: Incoming elevations [deg] at which the continuation table is built (the sun's own light uses the frame's exact
#: elevation instead).
SAMPLING_ELEVATIONS = tuple(float(e) for e in range(0, 91, 5))
#: Photons per channel and elevation for the continuation table (its peak bins carry about 2 % noise).
SAMPLING_PHOTONS = 1_000_000
#: The channel whose distribution is sampled (green, as for the angle tables).
SAMPLED = 1


@wp.struct
class OrientedTables:
    """Per oriented medium, its mixed table at :data:`SAMPLING_ELEVATIONS` and the green channel's CDFs.

    Attributes:
        values: Flat (tables, K, E, A, 3) phase [1/sr]; every (table, slice, channel) integrates to 1 on the bins.
        marginal: Flat (tables, K, E + 1) CDF over elevation bins (green).
        conditional: Flat (tables, K, E, A + 1) CDFs over azimuth bins per elevation bin (green).
        table_of: Per medium, its table, or -1.
        elevation_step: Spacing of the slices' incoming elevations [rad], the first at 0.
        slices: K.
        grid: The sky bins.
        count: Number of tables (0: nothing is read).
    """

    values: wp.array(dtype=float)
    marginal: wp.array(dtype=float)
    conditional: wp.array(dtype=float)
    table_of: wp.array(dtype=int)
    elevation_step: float
    slices: int
    grid: SkyGrid
    count: int


@wp.func
def source_frame(s: wp.vec3) -> wp.mat33:
    """Rows: the frame of a source direction s (X horizontal towards it, Y up, Z = X x Y); world X when vertical."""
    horizontal = wp.vec3(s[0], 0.0, s[2])
    x = wp.vec3(1.0, 0.0, 0.0)
    if wp.length(horizontal) > 1.0e-9:
        x = wp.normalize(horizontal)
    y = wp.vec3(0.0, 1.0, 0.0)
    z = wp.cross(x, y)
    return wp.mat33(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2])


@wp.func
def slice_position(tables: OrientedTables, s: wp.vec3) -> wp.vec2:
    """(lower slice, weight of the upper one) for a source direction s (mirrored to the upper hemisphere)."""
    elevation = wp.asin(wp.clamp(wp.abs(s[1]), 0.0, 1.0))
    x = wp.clamp(elevation / tables.elevation_step, 0.0, float(tables.slices - 1))
    lower = wp.min(int(x), wp.max(tables.slices - 2, 0))
    return wp.vec2(float(lower), wp.clamp(x - float(lower), 0.0, 1.0))


@wp.func
def bin_offset(tables: OrientedTables, table: int, k: int, row: int, column: int) -> int:
    g = tables.grid
    return (((table * tables.slices + k) * g.elevation_bins + row) * g.azimuth_bins + column) * 3


@wp.func
def look_bin(tables: OrientedTables, s: wp.vec3, look: wp.vec3) -> wp.vec2:
    """(row, column) of the sky bin of ``look`` in the frame of source ``s`` (both mirrored when s is below)."""
    local = source_frame(s) * look
    if s[1] < 0.0:
        local = wp.vec3(local[0], -local[1], local[2])
    g = tables.grid
    horizontal = wp.sqrt(local[0] * local[0] + local[2] * local[2])
    row = int(wp.floor((wp.atan2(local[1], horizontal) + 0.5 * wp.pi) / g.elevation_step + 0.5))
    column = int(wp.floor(wp.atan2(wp.abs(local[2]), local[0]) / g.azimuth_step + 0.5))
    return wp.vec2(float(wp.clamp(row, 0, g.elevation_bins - 1)), float(wp.clamp(column, 0, g.azimuth_bins - 1)))


@wp.func
def directional_value(tables: OrientedTables, table: int, s: wp.vec3, look: wp.vec3) -> wp.vec3:
    """T(s, look) [1/sr], RGB: light from source direction ``s`` seen along ``look`` (world, unit)."""
    at = slice_position(tables, s)
    cell = look_bin(tables, s, look)
    k = int(at[0])
    upper = wp.min(k + 1, tables.slices - 1)
    a = bin_offset(tables, table, k, int(cell[0]), int(cell[1]))
    b = bin_offset(tables, table, upper, int(cell[0]), int(cell[1]))
    t = at[1]
    out = wp.vec3(0.0)
    for c in range(3):
        out[c] = tables.values[a + c] * (1.0 - t) + tables.values[b + c] * t
    return out


@wp.func
def directional_sample(tables: OrientedTables, table: int, d: wp.vec3, state: wp.uint32):
    """(the direction s the light came from, state) for a path arriving along ``d``, with density
    T(-d, -s) in the green channel (see the module docstring). Six random draws."""
    source = -d
    at = slice_position(tables, source)
    k = int(at[0])
    if wp.randf(state) < at[1]:
        k = wp.min(k + 1, tables.slices - 1)
    g = tables.grid
    marginal_base = (table * tables.slices + k) * (g.elevation_bins + 1)
    row = cdf_search(tables.marginal, marginal_base, g.elevation_bins, wp.randf(state))
    conditional_base = ((table * tables.slices + k) * g.elevation_bins + row) * (g.azimuth_bins + 1)
    column = cdf_search(tables.conditional, conditional_base, g.azimuth_bins, wp.randf(state))
    # a uniform point of the bin in solid angle: uniform in sin(elevation) and in azimuth (both clipped at the ends)
    e0 = wp.max(float(row) * g.elevation_step - 0.5 * g.elevation_step - 0.5 * wp.pi, -0.5 * wp.pi)
    e1 = wp.min(float(row) * g.elevation_step + 0.5 * g.elevation_step - 0.5 * wp.pi, 0.5 * wp.pi)
    a0 = wp.max(float(column) * g.azimuth_step - 0.5 * g.azimuth_step, 0.0)
    a1 = wp.min(float(column) * g.azimuth_step + 0.5 * g.azimuth_step, wp.pi)
    sine = wp.sin(e0) + (wp.sin(e1) - wp.sin(e0)) * wp.randf(state)
    azimuth = a0 + (a1 - a0) * wp.randf(state)
    if wp.randf(state) < 0.5:
        azimuth = -azimuth
    cosine = wp.sqrt(wp.max(1.0 - sine * sine, 0.0))
    local = wp.vec3(cosine * wp.cos(azimuth), sine, cosine * wp.sin(azimuth))
    if source[1] < 0.0:
        local = wp.vec3(local[0], -local[1], local[2])
    look = wp.transpose(source_frame(source)) * local
    return -wp.normalize(look), state


@functools.lru_cache(maxsize=4)
def _medium_tables(spec, elevations: tuple, photons: int) -> tuple[list, list, list]:
    """(mixed slices, green marginal CDFs, green conditional CDFs) of an ice field's crystals
    (:class:`~warpsky.model.scene.IceCrystals`) at ``elevations``, kept per process so that the frames of a batch
    do not load, mix and integrate the table again (callers must not write into them)."""
    from warpsky.optics.oriented_ice import IceOrientation, SkyBins, oriented_ice_table, slice_cdf
    from warpsky.optics.oriented_phase import mixed_slice

    grid = SkyBins()
    solid = grid.solid_angles()[:, :, None]
    orientation = IceOrientation(spec.orientation, spec.tilt_deg, spec.habit)
    table = oriented_ice_table(orientation, sun_elevations_deg=elevations, grid=grid, photons=photons)
    values, marginals, conditionals = [], [], []
    for k, elevation in enumerate(elevations):
        mixed = mixed_slice(table.phase[k], spec.fraction, orientation, grid, elevation)
        mixed = mixed / np.maximum((mixed * solid).sum(axis=(0, 1)), 1e-300)
        marginal, conditional = slice_cdf(mixed, grid)
        values.append(mixed.astype(np.float32))
        marginals.append(marginal[:, SAMPLED].astype(np.float32))
        conditionals.append(conditional[:, :, SAMPLED].astype(np.float32))
    return values, marginals, conditionals


def continuation_tables(scene, device, *, elevations=None, photons: int | None = None,
                        cache: str | None = None) -> OrientedTables:
    """The kernels' :class:`OrientedTables` of ``scene``'s oriented media (an empty struct without any): each
    oriented table built at ``elevations`` (default :data:`SAMPLING_ELEVATIONS`, evenly spaced from 0) with
    ``photons`` per channel (default :data:`SAMPLING_PHOTONS`), cached on disk, mixed with the random crystals,
    renormalised per channel, with the green channel's CDFs. With ``cache`` (a name) the arrays are kept on the
    device under ``<cache>:continuation*`` and uploaded only when their contents change."""
    from warpsky.core import device_buffers
    from warpsky.optics.oriented_ice import SkyBins
    from warpsky.optics.oriented_phase import oriented_media

    elevations = np.asarray(SAMPLING_ELEVATIONS if elevations is None else elevations, dtype=np.float64)
    steps = np.diff(elevations)
    if elevations[0] != 0.0 or (len(steps) and not np.allclose(steps, steps[0])) or elevations[-1] != 90.0:
        raise ValueError(f"continuation table elevations must run evenly from 0 to 90 degrees, got {elevations}")
    photons = SAMPLING_PHOTONS if photons is None else int(photons)
    grid = SkyBins()
    indices = oriented_media(scene.media)
    table_of = [-1] * max(len(scene.media), 1)
    values, marginals, conditionals = [], [], []
    for index in indices:
        table_values, table_marginals, table_conditionals = _medium_tables(
            scene.media[index].ice, tuple(float(e) for e in elevations), photons)
        values += table_values
        marginals += table_marginals
        conditionals += table_conditionals
        table_of[index] = len(values) // len(elevations) - 1
    out = OrientedTables()
    out.count = len(indices)
    out.slices = len(elevations)
    out.elevation_step = math.radians(float(elevations[1] - elevations[0])) if len(elevations) > 1 else 1.0
    out.grid = grid.struct()

    def flat(parts):
        return np.ascontiguousarray(np.concatenate([p.reshape(-1) for p in parts]) if parts else np.zeros(1),
                                    dtype=np.float32)

    arrays = {"values": (flat(values), float), "marginal": (flat(marginals), float),
              "conditional": (flat(conditionals), float), "table_of": (np.asarray(table_of, dtype=np.int32), int)}
    for name, (array, dtype) in arrays.items():
        if cache is None:
            setattr(out, name, wp.array(array, dtype=dtype, device=device))
        else:
            setattr(out, name, device_buffers.upload(f"{cache}:continuation_{name}", array, dtype, device))
    return out


def oriented_table_bytes(media) -> tuple[int, int]:
    """(frame slices, continuation tables) [bytes, float32] of ``media``'s oriented ice: per oriented medium its
    frame slice (:func:`~warpsky.optics.oriented_phase.frame_slices`, E x A x 3 on the frame's bins) and its
    continuation table (:data:`SAMPLING_ELEVATIONS` slices of E x A x 3 values, E x (A + 1) conditional and E + 1
    marginal CDFs on the default bins): what the memory estimates count, without building anything."""
    from warpsky.optics.oriented_ice import SkyBins
    from warpsky.optics.oriented_phase import frame_bins, oriented_media

    count = len(oriented_media(media))
    frame, grid = frame_bins(), SkyBins()
    e, a = grid.elevation_bins, grid.azimuth_bins
    per_slice = e * a * 3 + e * (a + 1) + e + 1
    return (4 * count * frame.elevation_bins * frame.azimuth_bins * 3,
            4 * count * len(SAMPLING_ELEVATIONS) * per_slice)
