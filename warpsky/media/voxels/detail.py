"""Animated density detail of voxel media: from a :class:`~warpsky.model.scene.DetailSpec` to the
per-medium ``MediumDetail`` structs the samplers read at each sample.

The detail of a spec is one :class:`~warpsky.media.advection.advection.AdvectedDetail`: a periodic 64^3 noise texture
(Gaussian-filtered, features about ``scale`` across, texel ``scale / 2``) that tiles world space with a period of
``32 scale``, advected by the spec's wind plus curl noise (largest eddies ``8 scale``, two octaves, on a 32^3 flow
grid) in 3 staggered layers of life ``period``. A cold frame costs at most 32 semi-Lagrangian steps per layer
(``step_s = period / 32``), so frame 900 never needs frames 1..899; consecutive frames reuse the previous steps and
give the same pixels bit for bit.

Objects are cached per (spec without its amplitude, device), at most :data:`CACHE_SIZE` of them, so a sequence
rendered in one process steps forward instead of starting over. The cache is not thread-safe: render frames of
one process one after another (the batch executors do).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import warp as wp

from warpsky.media.advection.advection import AdvectedDetail, Flow3D, periodic_noise
from warpsky.media.advection.advection_kernels import DetailState
from warpsky.media.advection.advection_kernels import advected_detail as advected_noise
from warpsky.model.scene import DetailSpec, VoxelMedium

#: Texels of the detail texture per axis, and texels per ``scale`` (the tile is 32 scale wide).
TEXTURE_RESOLUTION = 64
TEXELS_PER_SCALE = 2
#: Flow grid nodes per axis over the tile; the largest eddies span 8 scale, the smallest 4 scale (4 nodes).
FLOW_RESOLUTION = 32
EDDY_SCALES = 8.0
LAYERS = 3
CACHE_SIZE = 8

_cache: OrderedDict = OrderedDict()

#: Detail multiplies density by ``max(0, 1 + amplitude * clamp(z, -DETAIL_Z_MAX, DETAIL_Z_MAX))``, so by at most
#: ``1 + DETAIL_Z_MAX * amplitude`` (what a majorant must allow for).
DETAIL_Z_MAX = wp.constant(3.0)


@wp.struct
class MediumDetail:
    """A medium's animated detail at one time (``amplitude`` 0: none; ``state`` is then never read)."""

    state: DetailState  # the advected noise, positions relative to the camera [m]
    amplitude: float
    edge: float  # the spec's edge in field units (extinction [1/m] over the field's extinction per unit)
    source: int  # the first medium whose noise this one's is (fields of one Volume share it): evaluated once


@wp.func
def detail_z(detail: MediumDetail, p: wp.vec3) -> float:
    """The advected noise at ``p`` (camera-relative metres) in standard deviations."""
    return (advected_noise(detail.state, p) - detail.state.mean) / detail.state.std


@wp.func
def factor_of_z(amplitude: float, z: float) -> float:
    """``max(0, 1 + a clamp(z, -Z, Z))`` with Z = DETAIL_Z_MAX: in [0, 1 + Z a]."""
    return wp.max(0.0, 1.0 + amplitude * wp.clamp(z, -DETAIL_Z_MAX, DETAIL_Z_MAX))


@wp.func
def value_of_z(detail: MediumDetail, value: float, z: float) -> float:
    """The detailed field: the coarse ``value`` times :func:`factor_of_z`, less the edge, floored at zero
    (never above ``value (1 + Z a)``)."""
    return wp.max(0.0, value * factor_of_z(detail.amplitude, z) - detail.edge)


@wp.func
def detail_value(detail: MediumDetail, value: float, p: wp.vec3) -> float:
    """The detailed field at ``p`` (camera-relative metres) from its coarse ``value`` there."""
    return value_of_z(detail, value, detail_z(detail, p))


@wp.func
def detailed_value(value: float, details: wp.array(dtype=MediumDetail), m: int, p: wp.vec3) -> float:
    """Medium ``m``'s coarse ``value`` at ``p`` (camera-relative metres) with its detail, if it has one."""
    if value > 0.0:
        amplitude = details[m].amplitude
        if amplitude > 0.0:
            return detail_value(details[m], value, p)
    return value


def detail_factor_bound(medium: VoxelMedium) -> float:
    """Largest factor animated detail can multiply ``medium``'s density by: ``1 + DETAIL_Z_MAX amplitude`` (1
    without active detail), what a majorant must allow for."""
    if not medium.has_detail:
        return 1.0
    return 1.0 + float(DETAIL_Z_MAX) * float(medium.detail.amplitude)


def edge_in_field_units(medium: VoxelMedium) -> float:
    """The medium's ``warpsky:detail:edge`` [1/m] in its field's units: over its largest extinction per unit
    (the edge clears the same fringe in every channel's field)."""
    if not medium.has_detail or medium.detail.edge <= 0.0:
        return 0.0
    per_unit = float(np.max(medium.extinction_scale))
    return float(medium.detail.edge) / per_unit if per_unit > 0.0 else 0.0


def tile_size(spec: DetailSpec) -> float:
    """Period of the detail in world space along every axis [m]."""
    return spec.scale * TEXTURE_RESOLUTION / TEXELS_PER_SCALE


def advected_detail(spec: DetailSpec, device):
    """The (cached) :class:`~warpsky.media.advection.advection.AdvectedDetail` of ``spec`` on ``device``, anchored at
    the world origin (its texture tiles all space)."""
    device = str(wp.get_device(device))
    key = (spec.scale, spec.wind, spec.curl_speed, spec.period, spec.seed, device)
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    tile = tile_size(spec)
    extent = (tile, tile, tile)
    texture = periodic_noise((TEXTURE_RESOLUTION,) * 3, smoothing_texels=1.0, seed=spec.seed)
    if spec.curl_speed > 0.0:
        flow = Flow3D.procedural(extent, wind_m_s=spec.wind, speed_m_s=spec.curl_speed,
                                 scale_m=EDDY_SCALES * spec.scale, octaves=2, resolution=(FLOW_RESOLUTION,) * 3,
                                 seed=spec.seed + 1)
    else:
        flow = Flow3D.still(extent, wind_m_s=spec.wind)
    detail = AdvectedDetail(texture, (0.0, 0.0, 0.0), flow, layers=LAYERS, period_s=spec.period, device=device)
    _cache[key] = detail
    while len(_cache) > CACHE_SIZE:
        _cache.popitem(last=False)
    return detail


def clear_cache() -> None:
    """Forget every cached detail (tests use it to render a frame cold)."""
    _cache.clear()


def medium_details(media: tuple[VoxelMedium, ...], time_s: float, camera_position, device) -> list | None:
    """One ``MediumDetail`` per medium at ``time_s`` [s], positions relative to ``camera_position`` (world m,
    float64); None when no medium has active detail. Arrays inside are the cached objects' buffers: launch the
    kernels that read them before asking for another time."""
    if not any(m.has_detail for m in media):
        return None
    camera = np.asarray(camera_position, dtype=np.float64)
    states: dict = {}
    sources: dict = {}
    out = []
    for index, medium in enumerate(media):
        entry = MediumDetail()
        entry.amplitude = 0.0
        entry.edge = 0.0
        entry.source = index
        spec = medium.detail
        if medium.has_detail:
            detail = advected_detail(spec, device)
            if id(detail) not in states:  # one advection per spec and frame, however many fields share it
                states[id(detail)] = detail.state(time_s)
            # anchor the tiling at a tile corner near the medium, so float32 offsets stay small far from the origin
            tile = tile_size(spec)
            anchor = np.floor(medium.world_corners().min(axis=0) / tile) * tile
            state = states[id(detail)]
            entry.state = _with_origin(state, anchor - camera)
            entry.amplitude = float(spec.amplitude)
            entry.edge = edge_in_field_units(medium)
            entry.source = sources.setdefault((id(detail), tuple(anchor.tolist())), index)
        out.append(entry)
    return out


def _with_origin(state, origin: np.ndarray):
    """A copy of the DetailState struct with another ``origin`` (same device arrays)."""
    copy = DetailState()
    for name in ("texture", "correlation", "displacement", "cells_per_texel", "weights", "layer_count", "shift",
                 "texels_per_m", "mean", "std"):
        setattr(copy, name, getattr(state, name))
    copy.origin = wp.vec3(*origin.tolist())
    return copy

