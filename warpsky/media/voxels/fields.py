"""Read scalar density grids (and a velocity's vector grids) from disk: dense ``.npy``, NanoVDB ``.nvdb`` and
OpenVDB ``.vdb``.

The format is told by the file's magic bytes, not its extension. OpenVDB files are converted once with
``nanovdb_convert`` (Debian package ``libnanovdb-tools``) and cached by content hash under
``$WARPSKY_CACHE/nanovdb`` (default ``~/.cache/warpsky/nanovdb``); the conversion keeps every grid in file order, so
one cached file serves every grid name and index. NanoVDB grids are loaded by Warp and copied into a dense array
over their allocated voxels, padded by one voxel of background (zero) on each side so that trilinear interpolation
fades out at the grid's edge exactly as OpenVDB's sampler does.

A grid is picked by name and by index among the grids of that name (UsdVol's ``fieldName`` and ``fieldIndex``;
without a name the index counts every grid in the file). Only scalar float fog volumes render: a level set (grid
class ``GRID_LEVEL_SET``, which ``nanovdb_convert`` carries over from OpenVDB) or a vector grid is refused with the
command that converts it.
"""

from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import struct
import subprocess
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.core.errors import SceneError
from warpsky.core.files import atomic_write, cache_dir
from warpsky.media.voxels.nanovdb_dense import dense_from_leaves, grid_map

NPY_MAGIC = b"\x93NUMPY"
NANOVDB_MAGICS = (b"NanoVDB0", b"NanoVDB1", b"NanoVDB2")
OPENVDB_MAGIC = struct.pack("<i", 0x56444220)
_NVDB_HEADER = struct.Struct("<QIHH")  # magic, version, grid count, codec
_NVDB_META_SIZE = 176  # sizeof(nanovdb::io::FileMetaData), followed by the grid name
_NVDB_CODEC_OFFSET = 168
_NVDB_CLASS_OFFSET = 36  # nanovdb::GridClass (uint32), after the grid type
GRID_CLASS_LEVEL_SET = 1  # nanovdb::GridClass::LevelSet


class NanoGrid(NamedTuple):
    """One grid of a NanoVDB file, re-framed as an uncompressed single-grid file that Warp's loader accepts."""

    name: str
    blob: bytes
    grid_class: int  # nanovdb::GridClass (0 unknown, 1 level set, 2 fog volume, ...)


@dataclass(frozen=True)
class FieldGrid:
    """A dense scalar grid as read from a file.

    Attributes:
        values: float32 array indexed ``[x, y, z]``; of shape (0, 0, 0) for a grid without active voxels (an
            empty medium, :attr:`empty`).
        local_from_index: 4x4 affine from index coordinates (voxel centres at integers) to the file's own
            space, or None for ``.npy`` grids, which are placed by the Volume's authored extent.
        source: The file the grid came from.
        grid_name: Name of the grid inside the file ("" when unnamed).
    """

    values: np.ndarray
    local_from_index: np.ndarray | None
    source: str
    grid_name: str = ""

    @property
    def empty(self) -> bool:
        """Whether the grid has no active voxels (nothing to render)."""
        return self.values.size == 0


def sniff_format(path: Path) -> str:
    """Return ``"npy"``, ``"nvdb"`` or ``"vdb"`` from the file's first bytes."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as exc:
        raise SceneError(f"cannot read field file {path}: {exc.strerror or exc}") from exc
    if head.startswith(NPY_MAGIC):
        return "npy"
    if head in NANOVDB_MAGICS:
        return "nvdb"
    if head.startswith(OPENVDB_MAGIC):
        return "vdb"
    raise SceneError(f"field file {path} is not a .npy, NanoVDB or OpenVDB file (unrecognised magic bytes {head!r})")


def load_field(path: str | os.PathLike, *, grid_name: str | None = None, grid_index: int = 0,
               vector: bool = False) -> FieldGrid:
    """Load one scalar grid from ``path`` (with ``vector``, one Vec3f grid such as a velocity: ``values`` of shape
    (X, Y, Z, 3)).

    Args:
        path: A ``.npy``, ``.nvdb`` or ``.vdb`` file (told apart by magic bytes).
        grid_name: Picks the grids of this name in a VDB file; None: every grid.
        grid_index: Which of those grids, 0 for the first in file order (UsdVol's ``fieldIndex``).
        vector: Read a vector grid instead of a scalar one.
    """
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"field file {path} does not exist")
    kind = sniff_format(path)
    if kind == "npy":
        if grid_index != 0:
            raise SceneError(f"dense grid {path} holds one grid, so fieldIndex {grid_index} is out of range")
        return _load_npy(path, vector)
    nvdb = convert_vdb(path) if kind == "vdb" else path
    name, blob, _ = _pick_grid(nanovdb_grids(nvdb.read_bytes(), path), grid_name, grid_index, path)
    return _dense_grid(blob, name, path, vector=vector)


def load_vector_field(path: str | os.PathLike, *, grid_name: str | None = None, grid_index: int = 0) -> FieldGrid:
    """:func:`load_field` of a vector grid (a velocity): a ``.npy`` (X, Y, Z, 3) array or a VDB Vec3f grid."""
    return load_field(path, grid_name=grid_name, grid_index=grid_index, vector=True)


def level_set_advice(source: str | os.PathLike, grid_name: str | None) -> str:
    """How to turn a level-set grid into the fog volume warpsky renders (OpenVDB's ``vdb_tool``)."""
    source = Path(source)
    name = grid_name or "density"
    kind = sniff_format(source)
    if kind == "npy":
        return "warpsky renders fog volumes (density), not level sets; a dense .npy grid holds density"
    vdb = source
    convert = ""
    if kind == "nvdb":
        vdb = Path(f"{source.stem}.vdb")
        convert = f"nanovdb_convert {shlex.quote(str(source))} {shlex.quote(str(vdb))}, then "
    convert += (f"vdb_tool -read {shlex.quote(str(vdb))} grids={shlex.quote(name)} -ls2fog name={shlex.quote(name)} "
                f"-write {shlex.quote(source.stem + '_fog.vdb')}")
    return f"warpsky renders fog volumes (density), not level sets; convert it with {convert}"


def _load_npy(path: Path, vector: bool) -> FieldGrid:
    try:
        values = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise SceneError(f"cannot read dense grid {path}: {exc}") from exc
    if vector and (values.ndim != 4 or values.shape[3] != 3):
        raise SceneError(f"dense vector grid {path} must be a 4-D array indexed [x, y, z, component] of shape "
                         f"(X, Y, Z, 3), got shape {values.shape}")
    if not vector and values.ndim != 3:
        raise SceneError(f"dense grid {path} must be a 3-D array indexed [x, y, z], got shape {values.shape}")
    if not np.issubdtype(values.dtype, np.floating) and not np.issubdtype(values.dtype, np.integer):
        raise SceneError(f"dense grid {path} must hold numbers, got dtype {values.dtype}")
    return FieldGrid(np.ascontiguousarray(values, dtype=np.float32), None, str(path))


def convert_vdb(path: Path) -> Path:
    """Convert an OpenVDB file to NanoVDB with ``nanovdb_convert``, cached by the file's content hash."""
    tool = shutil.which("nanovdb_convert")
    if tool is None:
        raise SceneError(
            f"reading OpenVDB file {path} needs the nanovdb_convert tool from Debian's libnanovdb-tools package "
            "(apt-get install libnanovdb-tools); or convert it to .nvdb yourself"
        )
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    target = cache_dir() / "nanovdb" / f"{digest}.nvdb"
    if target.is_file():
        return target

    def convert(tmp):
        proc = subprocess.run([tool, "-f", str(path), str(tmp)], capture_output=True, text=True, timeout=600)
        if proc.returncode != 0 or os.path.getsize(tmp) == 0:
            detail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            raise SceneError(f"nanovdb_convert failed on {path}: {detail[0]}")

    atomic_write(target, convert)
    return target


def nanovdb_grids(data: bytes, source: Path) -> list[NanoGrid]:
    """Split a NanoVDB file into its grids, in file order."""
    grids = []
    offset = 0
    while offset + _NVDB_HEADER.size <= len(data):
        magic, version, grid_count, codec = _NVDB_HEADER.unpack_from(data, offset)
        if data[offset : offset + 8] not in NANOVDB_MAGICS:
            break
        offset += _NVDB_HEADER.size
        metas = []
        for _ in range(grid_count):
            meta = bytearray(data[offset : offset + _NVDB_META_SIZE])
            grid_size, file_size = struct.unpack_from("<QQ", meta, 0)
            (name_size,) = struct.unpack_from("<I", meta, 136)
            name = data[offset + _NVDB_META_SIZE : offset + _NVDB_META_SIZE + name_size].split(b"\0")[0]
            metas.append((meta, name, grid_size, file_size))
            offset += _NVDB_META_SIZE + name_size
        for meta, name, grid_size, _file_size in metas:
            # the grid's bytes as pieces, joined once below (a cloud's grid is tens of MB: each copy costs)
            if codec == 0:
                pieces = [memoryview(data)[offset : offset + grid_size]]
                offset += grid_size
            elif codec == 1:
                # Zip chunks, each prefixed by its byte count. Writers disagree on whether the metadata's file
                # size counts the prefixes, so read chunks until the grid is complete instead of trusting it.
                pieces = []
                while sum(map(len, pieces)) < grid_size and offset + 8 <= len(data):
                    (chunk,) = struct.unpack_from("<Q", data, offset)
                    try:
                        pieces.append(zlib.decompress(memoryview(data)[offset + 8 : offset + 8 + chunk]))
                    except zlib.error as exc:
                        raise SceneError(f"NanoVDB file {source} is corrupt: {exc}") from exc
                    offset += 8 + chunk
            else:
                raise SceneError(
                    f"NanoVDB file {source} uses codec {codec} (blosc); re-save it uncompressed or with zip"
                )
            if sum(map(len, pieces)) != grid_size:
                raise SceneError(f"NanoVDB file {source} is truncated or corrupt (grid {name.decode()!r})")
            # Re-frame the grid as an uncompressed single-grid file that Warp's loader accepts.
            struct.pack_into("<Q", meta, 8, grid_size)
            struct.pack_into("<I", meta, 136, len(name) + 1)
            struct.pack_into("<H", meta, _NVDB_CODEC_OFFSET, 0)
            single = b"".join([_NVDB_HEADER.pack(magic, version, 1, 0), meta, name, b"\0", *pieces])
            (grid_class,) = struct.unpack_from("<I", meta, _NVDB_CLASS_OFFSET)
            grids.append(NanoGrid(name.decode("utf-8", "replace"), single, grid_class))
    if not grids:
        raise SceneError(f"NanoVDB file {source} holds no grids")
    return grids


# A dense grid's launch runs over rows (i, j) flattened, from row_offset, and k: the rows are shared by the CPU's
# threads (launch_rows).


@wp.kernel
def _densify_kernel(volume: wp.uint64, origin: wp.vec3i, out: wp.array3d(dtype=float), row_offset: int):
    row, k = wp.tid()
    i = (row + row_offset) // out.shape[1]
    j = (row + row_offset) - i * out.shape[1]
    out[i, j, k] = wp.volume_lookup_f(volume, i + origin[0], j + origin[1], k + origin[2])


@wp.kernel
def _densify_vector_kernel(volume: wp.uint64, origin: wp.vec3i, out: wp.array3d(dtype=wp.vec3), row_offset: int):
    row, k = wp.tid()
    i = (row + row_offset) // out.shape[1]
    j = (row + row_offset) - i * out.shape[1]
    out[i, j, k] = wp.volume_lookup_v(volume, i + origin[0], j + origin[1], k + origin[2])


def _pick_grid(grids: list[NanoGrid], grid_name: str | None, grid_index: int, source: Path) -> NanoGrid:
    """The ``grid_index``-th grid named ``grid_name`` (of all grids when no name is given)."""
    if grid_name:
        matches = [g for g in grids if g.name == grid_name]
        if not matches:
            names = ", ".join(repr(g.name) for g in grids)
            raise SceneError(f"field file {source} has no grid named {grid_name!r}; it holds {names}")
        what = f"grid(s) named {grid_name!r}"
    else:
        matches, what = grids, "grid(s)"
    if not 0 <= grid_index < len(matches):
        raise SceneError(
            f"field file {source} holds {len(matches)} {what}, so fieldIndex {grid_index} is out of range "
            f"(0 to {len(matches) - 1})"
        )
    grid = matches[grid_index]
    if grid.grid_class == GRID_CLASS_LEVEL_SET:
        raise SceneError(f"grid {grid.name!r} of {source} is a level set: {level_set_advice(source, grid.name)}")
    return grid


def _dense_grid(blob: bytes, name: str, source: Path, *, vector: bool) -> FieldGrid:
    """A NanoVDB grid copied into a dense array over its active voxels, one voxel of background on each side: a
    float grid of leaves alone by NumPy (:mod:`~warpsky.media.voxels.nanovdb_dense`, no Warp volume), any other
    grid by looking up every voxel in Warp."""
    grid = memoryview(blob)[_single_grid_offset(blob):]
    try:
        decoded = None if vector else dense_from_leaves(grid)
    except (ValueError, IndexError):  # a buffer the leaves cannot be read from: Warp's loader says what is wrong
        decoded = None
    if decoded is not None:
        (values, lo), (linear, translation) = decoded, grid_map(grid)
    else:
        values, lo, linear, translation = _walked_grid(blob, name, source, vector)
    if values.size == 0:  # a simulation's first frame: an empty medium, not an error
        return FieldGrid(np.zeros((0, 0, 0) + ((3,) if vector else ()), dtype=np.float32), np.eye(4), str(source),
                         name)
    local_from_index = np.eye(4)
    local_from_index[:3, :3] = linear
    local_from_index[:3, 3] = translation + linear @ lo
    return FieldGrid(values, local_from_index, str(source), name)


def _walked_grid(blob: bytes, name: str, source: Path, vector: bool):
    """(values, lo, 3x3 matrix, translation) of a grid loaded by Warp, checked for its value type."""
    try:
        volume = wp.Volume.load_from_nvdb(blob, device="cpu")
    except RuntimeError as exc:
        raise SceneError(f"cannot load grid {name!r} of {source}: {exc}") from exc
    info = volume.get_grid_info()
    is_vector = info.type_str.lower().startswith("vec")
    if vector and info.type_str.lower() != "vec3f":
        raise SceneError(f"grid {name!r} of {source} holds {info.type_str!r} values; a velocity is a Vec3f grid")
    if not vector and info.type_str != "float":
        if is_vector:
            raise SceneError(
                f"grid {name!r} of {source} is a vector grid of {info.type_str!r} values; warpsky renders scalar "
                "float (fog) grids: point fieldName at the density grid"
            )
        raise SceneError(f"grid {name!r} of {source} holds {info.type_str!r} values; expected a float (fog) grid")
    values, lo = _walked(volume, vector, name, source)
    linear = np.array(info.transform_matrix, dtype=np.float64).reshape(3, 3)
    return values, lo, linear, np.array(info.translation, dtype=np.float64)


def _single_grid_offset(blob: bytes) -> int:
    """Where the grid's own buffer starts in a single-grid file made by :func:`nanovdb_grids`."""
    (name_size,) = struct.unpack_from("<I", blob, _NVDB_HEADER.size + 136)
    return _NVDB_HEADER.size + _NVDB_META_SIZE + name_size


def _walked(volume, vector: bool, name: str, source: Path) -> tuple[np.ndarray, np.ndarray]:
    """(values, lo) of :func:`_dense_grid` by looking up every voxel of the active voxels' box in the tree."""
    voxels = volume.get_voxels().numpy()
    if len(voxels) == 0:
        return np.zeros((0, 0, 0), dtype=np.float32), np.zeros(3, dtype=np.int64)
    # per column: numpy reduces an (N, 3) array along its long axis several times slower
    lo = np.array([voxels[:, c].min() for c in range(3)]) - 1
    shape = tuple(int(voxels[:, c].max() - lo[c] + 2) for c in range(3))
    if np.prod(shape, dtype=np.int64) > 2**31 - 1:
        raise SceneError(f"grid {name!r} of {source} spans {shape} voxels, too large for a dense grid")
    dense = wp.zeros(shape, dtype=wp.vec3 if vector else float, device="cpu")
    kernel = _densify_vector_kernel if vector else _densify_kernel
    launch_rows(kernel, shape[0] * shape[1], shape[2], [volume.id, wp.vec3i(*lo.tolist()), dense], "cpu")
    return dense.numpy(), lo
