"""Voxel media on the device: one flat value buffer for all grids, a small struct per grid, and lookups.

Kernels never see world coordinates. The host expresses each grid relative to the camera in float64 and hands
the kernel the camera's position in that grid's index space plus the linear map from world directions to index
directions, so a scene 100 km from the origin renders with the same float32 precision as one at the origin.
A ray ``x(t) = camera + t * d`` (t in metres) is ``p(t) = eye_index + t * (index_from_world @ d)`` in index space.

Dense arrays are used on every device: on the CPU a trilinear lookup from a dense array is about six times faster
than through a NanoVDB ``wp.Volume``, and on the GPU dense grids of the sizes warpsky renders fit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.errors import ResourceError, UsageError
from warpsky.core.numerics import trilinear_cell
from warpsky.media.voxels.bricks import CoarseCells, cell_maxima, effective_block
from warpsky.media.voxels.detail import MediumDetail, detail_z, medium_details, value_of_z
from warpsky.model.scene import VoxelMedium
from warpsky.optics.kernels import TABLE_KIND
from warpsky.optics.tables import mean_cosine


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
    reduced_extinction: wp.vec3  # extinction - g scattering: after high-order similarity (isotropic phase), RGB
    reduced_scattering: wp.vec3  # scattering (1 - g), g the phase's mean cosine per channel, RGB
    cells: CoarseCells  # the grid's cells in the media's occupancy buffer (shape 0: none, walk it as one)
    up_metres: float  # metres per index step along world up where index y is vertical and columns are summed, else 0


@wp.func
def grid_value(values: wp.array(dtype=float), grid: VoxelGrid, p: wp.vec3) -> float:
    """Trilinear field value at index position ``p``; zero outside the box [-0.5, n - 0.5], clamped inside it."""
    n = grid.shape
    if p[0] < -0.5 or p[1] < -0.5 or p[2] < -0.5:
        return 0.0
    if p[0] > float(n[0]) - 0.5 or p[1] > float(n[1]) - 0.5 or p[2] > float(n[2]) - 0.5:
        return 0.0
    cell = trilinear_cell(p, n)
    lo = cell.lo
    hi = cell.hi
    i0 = lo[0]
    j0 = lo[1]
    k0 = lo[2]
    i1 = hi[0]
    j1 = hi[1]
    k1 = hi[2]
    fx = cell.frac[0]
    fy = cell.frac[1]
    fz = cell.frac[2]
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


#: Voxel fields one frame combines. Every sample keeps each field's density in registers (one grid read per field
#: per sample, however many phase functions or scattering orders are evaluated from it afterwards).
MAX_MEDIA = 16
FieldDensities = wp.types.vector(length=MAX_MEDIA, dtype=float)
#: One flag per field (which fields' detail noise a sample has evaluated).
FieldFlags = wp.types.vector(length=MAX_MEDIA, dtype=int)


def reduced_coefficients(medium: VoxelMedium) -> tuple[np.ndarray, np.ndarray]:
    """Extinction and scattering [1/m per unit field value], RGB, of ``medium`` after the order-1 similarity transform
    (high-order similarity): sigma_t - g sigma_s and sigma_s (1 - g) scattered isotropically, g its phase's mean
    cosine per channel."""
    g = mean_cosine(medium)
    scattering = medium.extinction_scale * medium.albedo
    return medium.extinction_scale - g * scattering, scattering * (1.0 - g)


def check_field_count(media: tuple[VoxelMedium, ...], technique: str, advice: str = "") -> None:
    """Raise a UsageError when ``technique``, whose samples keep every field's density in a
    :data:`FieldDensities` vector, is given more than :data:`MAX_MEDIA` fields."""
    if len(media) > MAX_MEDIA:
        raise UsageError(
            f"{technique} combines at most {MAX_MEDIA} voxel fields per frame, the scene has {len(media)}: "
            f"{', '.join(m.name for m in media)}; merge fields of one species into one grid{advice}")


@wp.struct
class VoxelMedia:
    """Every voxel medium of a frame on one device, relative to the camera (built by :class:`VoxelMediaBuffers`)."""

    values: wp.array(dtype=float)  # all grids' field values, one flat buffer
    grids: wp.array(dtype=VoxelGrid)  # one entry per medium
    details: wp.array(dtype=MediumDetail)  # one entry per medium (read only by kernels specialised on detail)
    count: int  # number of media
    occupancy: wp.array(dtype=float)  # every grid's largest value per cell of OCCUPANCY_BLOCK voxels, one buffer
    columns: wp.array(dtype=float)  # parallel to ``values``: each value's column integral above it (up_metres > 0)


@wp.struct
class MediaPoint:
    """Every medium at one point: each field's density (its detail applied) and the summed coefficients [1/m]."""

    density: FieldDensities
    extinction: wp.vec3
    scattering: wp.vec3


@wp.func
def media_span(media: VoxelMedia, origin: wp.vec3, view: wp.vec3, t_near: float, t_end: float) -> wp.vec2:
    """Union (t0, t1) of the media boxes along the view ray ``origin + t * view`` within [t_near, t_end] (empty:
    t1 <= t0)."""
    t0 = t_end
    t1 = t_near
    for m in range(media.count):
        grid = media.grids[m]
        start = grid.eye_index + grid.index_from_world * origin
        span = grid_interval(grid, start, grid.index_from_world * view, t_near, t_end)
        if span[1] > span[0]:
            t0 = wp.min(t0, span[0])
            t1 = wp.max(t1, span[1])
    return wp.vec2(t0, t1)


@functools.cache
def media_functions(has_detail: bool):
    """``sample_media(media: VoxelMedia, p: vec3) -> MediaPoint`` at the camera-relative point ``p`` [m],
    specialised on animated detail: with it each field's coarse density is multiplied by its detail factor here,
    once per sample, so everything downstream (extinction, scattering, phases) sees the detailed density. Fields
    that share one detail (a Volume's cloud, rain and snow) evaluate its noise once per sample."""

    @wp.func
    def sample_media(media: VoxelMedia, p: wp.vec3) -> MediaPoint:
        out = MediaPoint()
        out.density = FieldDensities()
        out.extinction = wp.vec3(0.0)
        out.scattering = wp.vec3(0.0)
        noise = FieldDensities()
        evaluated = FieldFlags()
        for m in range(media.count):
            grid = media.grids[m]
            value = grid_value(media.values, grid, grid.eye_index + grid.index_from_world * p)
            if wp.static(has_detail):
                if value > 0.0:
                    detail = media.details[m]
                    if detail.amplitude > 0.0:
                        source = detail.source
                        if evaluated[source] == 0:
                            noise[source] = detail_z(media.details[source], p)
                            evaluated[source] = 1
                        value = value_of_z(detail, value, noise[source])
            if value > 0.0:
                out.density[m] = value
                out.extinction += grid.extinction * value
                out.scattering += grid.scattering * value
        return out

    return sample_media


def upright_metres(index_from_world: np.ndarray) -> float:
    """Metres per index step along world up when the grid's index y axis is vertical (world up maps to +index y
    alone, to 1e-9 of its length), else 0: only then does a vertical ray follow one column of voxels."""
    up = np.asarray(index_from_world, dtype=np.float64)[:3, :3] @ np.array([0.0, 1.0, 0.0])
    if up[1] <= 0.0 or abs(up[0]) > 1e-9 * up[1] or abs(up[2]) > 1e-9 * up[1]:
        return 0.0
    return float(1.0 / up[1])


def column_sums(density: np.ndarray) -> np.ndarray:
    """S[i, j, k] = the integral of the trilinear field from voxel centre j up to the top of the box (index y =
    n - 0.5) along the column (i, k), in index units: linear between centres, constant in the last half voxel.
    Summed in float32 from the top down (relative rounding about 1e-7 per node summed)."""
    d = np.asarray(density, dtype=np.float32)
    out = np.empty_like(d)
    out[:, :-1, :] = d[:, :-1, :]
    out[:, :-1, :] += d[:, 1:, :]
    out[:, :-1, :] *= 0.5  # centre j to centre j + 1
    out[:, -1, :] = 0.5 * d[:, -1, :]
    np.cumsum(out[:, ::-1, :], axis=1, out=out[:, ::-1, :])
    return out


def grid_struct(medium: VoxelMedium, index_from_world: np.ndarray, camera_position, offset: int,
                species: tuple[str, ...], table_offset: int) -> VoxelGrid:
    """``medium``'s :class:`VoxelGrid` (its cells left to the caller): its values from ``offset`` in the flat
    buffer, the camera in its index space, its coefficients and phase."""
    grid = VoxelGrid()
    grid.offset = offset
    grid.shape = wp.vec3i(*medium.shape)
    eye = index_from_world @ np.append(np.asarray(camera_position, dtype=np.float64), 1.0)
    grid.eye_index = wp.vec3(*eye[:3].tolist())
    grid.index_from_world = wp.mat33(*index_from_world[:3, :3].reshape(-1).tolist())
    grid.extinction = wp.vec3(*medium.extinction_scale.tolist())
    grid.scattering = wp.vec3(*(medium.extinction_scale * medium.albedo).tolist())
    if medium.species is not None:
        grid.phase_kind = int(TABLE_KIND) + table_offset + species.index(medium.species)
    else:
        grid.phase_kind = int(medium.phase.kind)
    grid.phase_g = float(medium.phase.g)
    reduced_extinction, reduced_scattering = reduced_coefficients(medium)
    grid.reduced_extinction = wp.vec3(*reduced_extinction.tolist())
    grid.reduced_scattering = wp.vec3(*reduced_scattering.tolist())
    return grid


def cell_buffers(cell_chunks: list, column_chunks: list, occupancy, cache: str | None, device):
    """(occupancy, columns) on ``device``: the grids' cell maxima (``occupancy`` itself when given) and column sums
    concatenated, through :func:`warpsky.core.device_buffers.upload` as ``<cache>:occupancy`` and
    ``<cache>:columns``. None of either (grids uploaded without cells, or none upright) is a 1-entry dummy kept
    under a name of its own, so that an upload without cells of the same ``cache`` (the path tracer's, after the
    march's) does not replace the march's buffers."""
    def upload(name: str, chunks: list):
        if not chunks:
            data, key = np.zeros(1, np.float32), f"voxel_media:no_{name}"
        else:
            data, key = np.concatenate(chunks).astype(np.float32, copy=False), f"{cache}:{name}"
        if cache is None:
            return wp.array(data, dtype=float, device=device)
        return device_buffers.upload(key, data, float, device)

    if occupancy is None:
        occupancy = upload("occupancy", cell_chunks)
    return occupancy, upload("columns", column_chunks)


#: Voxels per cell edge of the occupancy the shadow marches skip empty space by (:mod:`~warpsky.media.voxels.
#: bricks`). On the demo cumulus (8.6 % of its voxels non-zero) 8-voxel cells leave 13 % of the box occupied before
#: the one-voxel dilation.
OCCUPANCY_BLOCK = 8


@dataclass
class VoxelMediaBuffers:
    """All voxel media of a scene uploaded to one device, expressed relative to one camera position."""

    values: wp.array
    grids: wp.array
    count: int
    min_voxel_size: float  # smallest voxel edge over all grids [m]
    details: wp.array | None = None  # MediumDetail per medium at the upload's time (a 1-entry dummy without detail)
    has_detail: bool = False  # whether any medium has animated detail: pick the samplers' has_detail specialisation
    occupancy: wp.array | None = None  # each grid's cell maxima (OCCUPANCY_BLOCK voxels), or a 1-entry dummy
    columns: wp.array | None = None  # each value's column integral above it (see :func:`column_sums`), or a dummy

    @property
    def media(self) -> VoxelMedia:
        """The kernels' view of these buffers."""
        out = VoxelMedia()
        out.values = self.values
        out.grids = self.grids
        out.details = self.details
        out.count = self.count
        out.occupancy = self.occupancy
        out.columns = self.columns
        return out

    @classmethod
    def upload(
        cls, media: tuple[VoxelMedium, ...], camera_position: np.ndarray, device, species: tuple[str, ...] = (),
        *, time_s: float = 0.0, cache: str | None = None, table_offset: int = 0, values: wp.array | None = None,
        cells: bool = True, occupancy: wp.array | None = None,
    ) -> VoxelMediaBuffers:
        """Upload ``media``; a medium of species ``species[i]`` uses phase table i; animated detail at ``time_s``
        [s] (see :mod:`warpsky.media.voxels.detail`). With ``cache`` (a name such as ``"slicing"``) the values, grid
        structs and details go through :func:`warpsky.core.device_buffers.upload` as ``<cache>:values``,
        ``<cache>:grids`` and ``<cache>:details``: kept on the device across frames and uploaded only when their
        contents change (the returned arrays are then shared: do not write into them). ``table_offset`` shifts the
        species' table indices (tables appended after theirs); ``values`` reuses the field values of buffers
        already uploaded for the same fields, so only the grid structs are new (and ``occupancy`` their cell
        maxima). With ``cells`` each grid gets its cell maxima (:data:`OCCUPANCY_BLOCK`), which the shadow marches
        skip empty cells by; without, a shadow march walks each grid as one (the path tracer, which has its own
        majorants, uploads without)."""
        infos = []
        chunks = []
        cell_chunks = []
        column_chunks = []
        offset = 0
        cell_offset = 0
        for medium in media:
            index_from_world = np.linalg.inv(medium.world_from_index)
            grid = grid_struct(medium, index_from_world, camera_position, offset, species, table_offset)
            grid.cells = CoarseCells()
            grid.cells.offset = cell_offset
            grid.cells.block = float(effective_block(medium.shape, OCCUPANCY_BLOCK))
            if cells:
                if occupancy is None:
                    cell_chunks.append(cell_maxima(medium.density, OCCUPANCY_BLOCK).reshape(-1))
                grid.cells.shape = wp.vec3i(*(-(-n // int(grid.cells.block)) for n in medium.shape))
                cell_offset += int(np.prod(grid.cells.shape))
                grid.up_metres = upright_metres(index_from_world)
                column_chunks.append(column_sums(medium.density).reshape(-1) if grid.up_metres > 0.0 else
                                     np.zeros(medium.density.size, np.float32))
            infos.append(grid)
            if values is None:
                chunks.append(medium.density.reshape(-1))
            offset += medium.density.size
        if offset >= 2**31:
            raise ResourceError(f"the voxel media hold {offset:,} values, more than the 2^31 one buffer can index: "
                                "split them or use coarser grids")
        flat = np.concatenate(chunks) if chunks else np.zeros(1, dtype=np.float32)
        sizes = [float(m.voxel_size.min()) for m in media]
        entries = medium_details(tuple(media), time_s, camera_position, device)
        grid_list, entries_or_dummy = infos if infos else [VoxelGrid()], entries if entries else [MediumDetail()]
        if values is not None:  # the grids of other buffers of the same fields (other coefficients or tables)
            grids = wp.array(grid_list, dtype=VoxelGrid, device=device)
            details = wp.array(entries_or_dummy, dtype=MediumDetail, device=device)
        elif cache is None:
            values = wp.array(flat, dtype=float, device=device)
            grids = wp.array(grid_list, dtype=VoxelGrid, device=device)
            details = wp.array(entries_or_dummy, dtype=MediumDetail, device=device)
        else:
            values = device_buffers.upload(f"{cache}:values", flat.astype(np.float32, copy=False), float, device)
            # structs travel as NumPy records so that their bytes key the upload
            # grids without cells under a name of their own: the path tracer's upload after the march's, of the same
            # values, would otherwise replace the march's grids every frame
            grids = device_buffers.upload(f"{cache}:grids" if cells else f"{cache}:grids:no_cells",
                                          wp.array(grid_list, dtype=VoxelGrid, device="cpu").numpy(), VoxelGrid, device)
            details = device_buffers.upload(
                f"{cache}:details", wp.array(entries_or_dummy, dtype=MediumDetail, device="cpu").numpy(),
                MediumDetail, device)
        if not any(g.up_metres > 0.0 for g in infos):
            column_chunks = []  # no grid reads them
        occupancy, columns = cell_buffers(cell_chunks, column_chunks, occupancy, cache, device)
        return cls(values, grids, len(infos), min(sizes) if sizes else 1.0, details, entries is not None, occupancy,
                   columns)
