"""Voxel media on the device: one flat value buffer for all grids, a small struct per grid, and lookups.

Kernels never see world coordinates. The host expresses each grid relative to the camera in float64 and hands
the kernel the camera's position in that grid's index space plus the linear map from world directions to index
directions, so a scene 100 km from the origin renders with the same float32 precision as one at the origin.
A ray ``x(t) = camera + t * d`` (t in metres) is ``p(t) = eye_index + t * (index_from_world @ d)`` in index space.

Dense arrays are used on every device: on the CPU a trilinear lookup from a dense array is about six times faster
than through a NanoVDB ``wp.Volume`` (FACTS.md), and on the GPU dense grids of the sizes warpsky renders fit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.media.advection_kernels import DetailState, advected_detail
from warpsky.scene.model import VoxelMedium

#: Detail multiplies density by ``max(0, 1 + amplitude * clamp(z, -DETAIL_Z_MAX, DETAIL_Z_MAX))``, so by at most
#: ``1 + DETAIL_Z_MAX * amplitude`` (what a majorant must allow for).
DETAIL_Z_MAX = wp.constant(3.0)


@wp.struct
class VoxelGrid:
    """One medium's grid and optics as the kernels see them."""

    offset: int  # first value of this grid in the flat buffer
    shape: wp.vec3i  # voxel counts along index x, y, z
    eye_index: wp.vec3  # camera position in index coordinates
    index_from_world: wp.mat33  # index-space displacement per world metre
    extinction: wp.vec3  # extinction per unit field value [1/m], RGB
    scattering: wp.vec3  # extinction * albedo [1/m per unit field value], RGB
    phase_kind: int  # PhaseKind code, or TABLE_KIND + table index for a species
    phase_g: float  # HG asymmetry


@wp.func
def grid_value(values: wp.array(dtype=float), grid: VoxelGrid, p: wp.vec3) -> float:
    """Trilinear field value at index position ``p``; zero outside the box [-0.5, n - 0.5], clamped inside it."""
    n = grid.shape
    if p[0] < -0.5 or p[1] < -0.5 or p[2] < -0.5:
        return 0.0
    if p[0] > float(n[0]) - 0.5 or p[1] > float(n[1]) - 0.5 or p[2] > float(n[2]) - 0.5:
        return 0.0
    x = wp.clamp(p[0], 0.0, float(n[0] - 1))
    y = wp.clamp(p[1], 0.0, float(n[1] - 1))
    z = wp.clamp(p[2], 0.0, float(n[2] - 1))
    i0 = wp.min(int(x), n[0] - 1)
    j0 = wp.min(int(y), n[1] - 1)
    k0 = wp.min(int(z), n[2] - 1)
    i1 = wp.min(i0 + 1, n[0] - 1)
    j1 = wp.min(j0 + 1, n[1] - 1)
    k1 = wp.min(k0 + 1, n[2] - 1)
    fx = x - float(i0)
    fy = y - float(j0)
    fz = z - float(k0)
    sy = n[2]
    sx = n[1] * n[2]
    b = grid.offset
    c000 = values[b + i0 * sx + j0 * sy + k0]
    c001 = values[b + i0 * sx + j0 * sy + k1]
    c010 = values[b + i0 * sx + j1 * sy + k0]
    c011 = values[b + i0 * sx + j1 * sy + k1]
    c100 = values[b + i1 * sx + j0 * sy + k0]
    c101 = values[b + i1 * sx + j0 * sy + k1]
    c110 = values[b + i1 * sx + j1 * sy + k0]
    c111 = values[b + i1 * sx + j1 * sy + k1]
    c00 = c000 + (c001 - c000) * fz
    c01 = c010 + (c011 - c010) * fz
    c10 = c100 + (c101 - c100) * fz
    c11 = c110 + (c111 - c110) * fz
    c0 = c00 + (c01 - c00) * fy
    c1 = c10 + (c11 - c10) * fy
    return c0 + (c1 - c0) * fx


@wp.struct
class MediumDetail:
    """A medium's animated detail at one time (``amplitude`` 0: none; ``state`` is then never read)."""

    state: DetailState  # the advected noise, positions relative to the camera [m]
    amplitude: float


@wp.func
def detail_factor(detail: MediumDetail, p: wp.vec3) -> float:
    """Factor on the coarse density at ``p`` (camera-relative metres): ``max(0, 1 + a clamp(z, -3, 3))`` with ``z``
    the advected noise in standard deviations; in [0, 1 + 3 a]."""
    z = (advected_detail(detail.state, p) - detail.state.mean) / detail.state.std
    return wp.max(0.0, 1.0 + detail.amplitude * wp.clamp(z, -DETAIL_Z_MAX, DETAIL_Z_MAX))


@wp.func
def detailed_value(value: float, details: wp.array(dtype=MediumDetail), m: int, p: wp.vec3) -> float:
    """Medium ``m``'s coarse ``value`` at ``p`` (camera-relative metres) times its detail factor, if it has one."""
    if value > 0.0:
        amplitude = details[m].amplitude
        if amplitude > 0.0:
            return value * detail_factor(details[m], p)
    return value


@wp.func
def slab_interval(origin: float, direction: float, lo: float, hi: float, t0: float, t1: float) -> wp.vec2:
    """Clip the parameter interval [t0, t1] of ``origin + t * direction`` to the slab lo <= x <= hi."""
    if direction == 0.0:
        if origin < lo or origin > hi:
            return wp.vec2(1.0, 0.0)
        return wp.vec2(t0, t1)
    inv = 1.0 / direction
    ta = (lo - origin) * inv
    tb = (hi - origin) * inv
    return wp.vec2(wp.max(t0, wp.min(ta, tb)), wp.min(t1, wp.max(ta, tb)))


@wp.func
def grid_interval(grid: VoxelGrid, origin: wp.vec3, direction: wp.vec3, t0: float, t1: float) -> wp.vec2:
    """Parameter interval where ``origin + t * direction`` (index space) lies inside the grid's box.

    Returns (t_enter, t_exit); the interval is empty when t_enter >= t_exit.
    """
    r = wp.vec2(t0, t1)
    for axis in range(3):
        r = slab_interval(origin[axis], direction[axis], -0.5, float(grid.shape[axis]) - 0.5, r[0], r[1])
    return r


@wp.struct
class MediaSample:
    """All media at one point, for one scattering angle."""

    extinction: wp.vec3  # summed extinction coefficient [1/m] (Riley Eqs. 2-3)
    scattering: wp.vec3  # summed scattering coefficient [1/m]
    phase_scattering: wp.vec3  # sum of scattering_i * P_i(theta) [1/(m sr)]
    lookups: int  # grid lookups it took


@wp.func
def combined_phase(sample: MediaSample) -> wp.vec3:
    """Phase function of the mixture at the point (Riley Eq. 6): scattering-weighted mean of the species' phases."""
    out = wp.vec3(0.0)
    for c in range(3):
        if sample.scattering[c] > 0.0:
            out[c] = sample.phase_scattering[c] / sample.scattering[c]
    return out


@functools.cache
def media_sampler(has_tables: bool, has_detail: bool = False):
    """``sample_media(values, grids, grid_count, phase_tables, details, t, view, theta) -> MediaSample`` at the
    point ``t`` metres along the view ray, specialised on whether any medium uses a phase table and whether any
    has animated detail (``details`` is read only then)."""
    from warpsky.optics.kernels import medium_phase
    from warpsky.optics.phase import phase_eval

    @wp.func
    def sample_media(
        values: wp.array(dtype=float),
        grids: wp.array(dtype=VoxelGrid),
        grid_count: int,
        phase_tables: wp.array(dtype=float),
        details: wp.array(dtype=MediumDetail),
        t: float,
        view: wp.vec3,
        theta: float,
    ) -> MediaSample:
        out = MediaSample()
        out.extinction = wp.vec3(0.0)
        out.scattering = wp.vec3(0.0)
        out.phase_scattering = wp.vec3(0.0)
        out.lookups = grid_count
        for m in range(grid_count):
            grid = grids[m]
            value = grid_value(values, grid, grid.eye_index + t * (grid.index_from_world * view))
            if wp.static(has_detail):
                value = detailed_value(value, details, m, t * view)
            if value > 0.0:
                phase = wp.vec3(0.0)
                if wp.static(has_tables):
                    phase = medium_phase(phase_tables, grid.phase_kind, grid.phase_g, theta)
                else:
                    phase = wp.vec3(phase_eval(grid.phase_kind, grid.phase_g, wp.cos(theta)))
                scattering = grid.scattering * value
                out.extinction += grid.extinction * value
                out.scattering += scattering
                out.phase_scattering += wp.cw_mul(scattering, phase)
        return out

    return sample_media


#: Voxel fields one frame combines. Every sample keeps each field's density in registers (one grid read per field
#: per sample, however many phase functions or scattering orders are evaluated from it afterwards).
MAX_MEDIA = 16
FieldDensities = wp.types.vector(length=MAX_MEDIA, dtype=float)


@wp.struct
class VoxelMedia:
    """Every voxel medium of a frame on one device, relative to the camera (built by :class:`VoxelMediaBuffers`)."""

    values: wp.array(dtype=float)  # all grids' field values, one flat buffer
    grids: wp.array(dtype=VoxelGrid)  # one entry per medium
    details: wp.array(dtype=MediumDetail)  # one entry per medium (read only by kernels specialised on detail)
    count: int  # number of media


@wp.struct
class MediaPoint:
    """Every medium at one point: each field's density (its detail applied) and the summed coefficients [1/m]."""

    density: FieldDensities
    extinction: wp.vec3
    scattering: wp.vec3


@functools.cache
def media_functions(has_detail: bool):
    """``sample_media(media: VoxelMedia, p: vec3) -> MediaPoint`` at the camera-relative point ``p`` [m],
    specialised on animated detail: with it each field's coarse density is multiplied by its detail factor here,
    once per sample, so everything downstream (extinction, scattering, phases) sees the detailed density."""

    @wp.func
    def sample_media(media: VoxelMedia, p: wp.vec3) -> MediaPoint:
        out = MediaPoint()
        out.density = FieldDensities()
        out.extinction = wp.vec3(0.0)
        out.scattering = wp.vec3(0.0)
        for m in range(media.count):
            grid = media.grids[m]
            value = grid_value(media.values, grid, grid.eye_index + grid.index_from_world * p)
            if wp.static(has_detail):
                value = detailed_value(value, media.details, m, p)
            if value > 0.0:
                out.density[m] = value
                out.extinction += grid.extinction * value
                out.scattering += grid.scattering * value
        return out

    return sample_media


@dataclass
class VoxelMediaBuffers:
    """All voxel media of a scene uploaded to one device, expressed relative to one camera position."""

    values: wp.array
    grids: wp.array
    count: int
    min_voxel_size: float  # smallest voxel edge over all grids [m]
    details: wp.array | None = None  # MediumDetail per medium at the upload's time (a 1-entry dummy without detail)
    has_detail: bool = False  # whether any medium has animated detail: pick the samplers' has_detail specialisation

    @property
    def media(self) -> VoxelMedia:
        """The kernels' view of these buffers."""
        out = VoxelMedia()
        out.values = self.values
        out.grids = self.grids
        out.details = self.details
        out.count = self.count
        return out

    @classmethod
    def upload(
        cls, media: tuple[VoxelMedium, ...], camera_position: np.ndarray, device, species: tuple[str, ...] = (),
        *, time_s: float = 0.0,
    ) -> VoxelMediaBuffers:
        """Upload ``media``; a medium of species ``species[i]`` uses phase table i; animated detail at ``time_s``
        [s] (see :mod:`warpsky.media.detail`)."""
        from warpsky.media.detail import medium_details
        from warpsky.optics.kernels import TABLE_KIND

        infos = []
        chunks = []
        offset = 0
        for medium in media:
            index_from_world = np.linalg.inv(medium.world_from_index)
            grid = VoxelGrid()
            grid.offset = offset
            grid.shape = wp.vec3i(*medium.shape)
            eye = index_from_world @ np.append(np.asarray(camera_position, dtype=np.float64), 1.0)
            grid.eye_index = wp.vec3(*eye[:3].tolist())
            grid.index_from_world = wp.mat33(*index_from_world[:3, :3].reshape(-1).tolist())
            grid.extinction = wp.vec3(*medium.extinction_scale.tolist())
            grid.scattering = wp.vec3(*(medium.extinction_scale * medium.albedo).tolist())
            if medium.species is not None:
                grid.phase_kind = int(TABLE_KIND) + species.index(medium.species)
            else:
                grid.phase_kind = int(medium.phase.kind)
            grid.phase_g = float(medium.phase.g)
            infos.append(grid)
            chunks.append(medium.density.reshape(-1))
            offset += medium.density.size
        if offset >= 2**31:
            raise ValueError("voxel media exceed 2^31 values; split them or use coarser grids")
        flat = np.concatenate(chunks) if chunks else np.zeros(1, dtype=np.float32)
        values = wp.array(flat, dtype=float, device=device)
        grids = wp.array(infos if infos else [VoxelGrid()], dtype=VoxelGrid, device=device)
        sizes = [float(m.voxel_size.min()) for m in media]
        entries = medium_details(tuple(media), time_s, camera_position, device)
        details = wp.array(entries if entries else [MediumDetail()], dtype=MediumDetail, device=device)
        return cls(values, grids, len(infos), min(sizes) if sizes else 1.0, details, entries is not None)
