"""A NanoVDB float grid copied into a dense array by NumPy, straight from the grid's leaf nodes.

A NanoVDB tree keeps its nodes level by level in contiguous arrays (root, upper 32^3 nodes, lower 16^3 nodes,
8^3 leaves), at offsets the tree header gives. When no internal node or root tile carries an active value or a value
other than the background, every voxel's value is its leaf's stored value (active or not) where a leaf covers it and
the background elsewhere: exactly what ``wp.volume_lookup_f`` returns voxel by voxel, so the leaves' 512-value
tables can be placed as blocks, a memory copy instead of a tree walk per voxel (about 30 M lookups/s on one CPU
core). Grids with such tiles, and vector grids, are left to the walk (:func:`warpsky.media.voxels.fields.load_field`).

Byte offsets are those of NanoVDB's C header for a float grid (``PNanoVDB.h``, ``pnanovdb_grid_type_constants``):
grid 672 bytes, tree 64, root 64 plus 32 per tile, upper node 270,400, lower 33,856, leaf 2,144.
"""

from __future__ import annotations

import numpy as np

GRID_TYPE_FLOAT = 1
_GRID_SIZE = 672
_GRID_TYPE_OFFSET = 636
_MAP_OFFSET = 296  # the grid's map: its float32 3x3 matrix (index to world), then the float32 translation at + 72
_ROOT_SIZE, _ROOT_TILE_SIZE, _ROOT_BACKGROUND = 64, 32, 28
#: (node size, value-mask offset, child-mask offset, table offset, table entries) of the upper and lower nodes.
_INTERNAL = ((270_400, 32, 4128, 8256, 32_768), (33_856, 32, 544, 1088, 4096))
_LEAF_SIZE, _LEAF_MASK, _LEAF_TABLE = 2144, 16, 96


def _records(buffer: np.ndarray, offset: int, count: int, size: int) -> np.ndarray:
    """``count`` records of ``size`` bytes from ``offset`` as a (count, size) uint8 array."""
    return buffer[offset : offset + count * size].reshape(count, size)


def _tiles_are_background(buffer: np.ndarray, tree: int, background: np.uint32) -> bool:
    """Whether every root tile and internal-node tile (an entry without a child) is inactive and holds the
    background (compared bit for bit)."""
    offsets = buffer[tree : tree + 32].view("<u8")
    counts = buffer[tree + 32 : tree + 44].view("<u4")  # leaves, lower, upper
    root = tree + int(offsets[3])
    tile_count = int(buffer[root + 24 : root + 28].view("<u4")[0])
    tiles = _records(buffer, root + _ROOT_SIZE, tile_count, _ROOT_TILE_SIZE)
    child = tiles[:, 8:16].copy().view("<i8")[:, 0]
    state = tiles[:, 16:20].copy().view("<u4")[:, 0]
    value = tiles[:, 20:24].copy().view("<u4")[:, 0]
    if np.any((child == 0) & ((state != 0) | (value != background))):
        return False
    for (size, value_mask, child_mask, table, entries), node_offset, count in zip(
            _INTERNAL, (offsets[2], offsets[1]), (counts[2], counts[1]), strict=True):
        nodes = _records(buffer, tree + int(node_offset), int(count), size)
        mask_bytes = entries // 8
        active = np.unpackbits(nodes[:, value_mask : value_mask + mask_bytes], axis=1, bitorder="little")
        has_child = np.unpackbits(nodes[:, child_mask : child_mask + mask_bytes], axis=1, bitorder="little")
        values = nodes[:, table : table + 8 * entries].copy().view("<u4")[:, ::2]  # a tile's value: its slot's 1st word
        is_tile = has_child == 0
        if np.any(active.astype(bool) & is_tile) or np.any(values[is_tile] != background):
            return False
    return True


def grid_map(grid: bytes | memoryview) -> tuple[np.ndarray, np.ndarray]:
    """(3x3 matrix, translation) float64 of the grid's index-to-world map: the float32 values Warp's
    ``Volume.get_grid_info`` gives as ``transform_matrix`` and ``translation``."""
    buffer = np.frombuffer(grid, dtype=np.uint8)
    matrix = buffer[_MAP_OFFSET : _MAP_OFFSET + 36].view("<f4").reshape(3, 3)
    return matrix.astype(np.float64), buffer[_MAP_OFFSET + 72 : _MAP_OFFSET + 84].view("<f4").astype(np.float64)


def dense_from_leaves(grid: bytes | memoryview) -> tuple[np.ndarray, np.ndarray] | None:
    """(values, lo) of a float grid's buffer (one grid, uncompressed): ``values`` float32 indexed ``[x, y, z]`` over
    the active voxels' bounding box grown by one voxel of background on each side, ``lo`` the index of its
    ``[0, 0, 0]`` (int64, 3); values of shape (0, 0, 0) when no voxel is active. None when the grid is not a float
    grid or holds tiles (see the module's docstring): the caller walks the tree instead."""
    buffer = np.frombuffer(grid, dtype=np.uint8)
    if (len(buffer) < _GRID_SIZE + 64 or bytes(buffer[:7]) != b"NanoVDB"
            or int(buffer[16:20].view("<u4")[0]) >> 21 != 32  # the layout of NanoVDB's major version 32
            or int(buffer[_GRID_TYPE_OFFSET : _GRID_TYPE_OFFSET + 4].view("<u4")[0]) != GRID_TYPE_FLOAT):
        return None
    tree = _GRID_SIZE
    offsets = buffer[tree : tree + 32].view("<u8")
    leaf_count = int(buffer[tree + 32 : tree + 36].view("<u4")[0])
    root = tree + int(offsets[3])
    background = buffer[root + _ROOT_BACKGROUND : root + _ROOT_BACKGROUND + 4].view("<u4")[0]
    if not _tiles_are_background(buffer, tree, background):
        return None
    first = tree + int(offsets[0])
    leaves = _records(buffer, first, leaf_count, _LEAF_SIZE)
    origins = leaves[:, 0:12].copy().view("<i4").astype(np.int64) & ~7  # a leaf's bbox minimum, aligned down
    # the value mask's bit x << 6 | y << 3 | z: byte 8 x + y holds z = 0..7
    mask = leaves[:, _LEAF_MASK : _LEAF_MASK + 64].reshape(-1, 8, 8) != 0
    present = (mask.any(axis=2), mask.any(axis=1),
               np.unpackbits(np.bitwise_or.reduce(leaves[:, _LEAF_MASK : _LEAF_MASK + 64], axis=1)[:, None], axis=1,
                             bitorder="little").astype(bool))
    if not present[0].any():
        return np.zeros((0, 0, 0), dtype=np.float32), np.zeros(3, dtype=np.int64)
    coordinates = [origins[:, axis, None] + np.arange(8) for axis in range(3)]
    lo = np.array([coordinates[a][present[a]].min() - 1 for a in range(3)])
    hi = np.array([coordinates[a][present[a]].max() + 1 for a in range(3)])
    if np.prod(hi + 1 - lo) > 2**31 - 1:
        return None  # too large for a dense grid: the walk says so
    corner = (lo // 8) * 8  # the leaf-aligned box over the dense one
    blocks = -(-(hi + 1 - corner) // 8)
    if background == 0:
        aligned = np.zeros(8 * blocks, dtype=np.float32)
    else:
        aligned = np.full(8 * blocks, background.view(np.float32), dtype=np.float32)
    index = (origins - corner) // 8
    inside = np.all((index >= 0) & (index < blocks), axis=1)
    values = np.ndarray((leaf_count, 8, 8, 8), dtype="<f4", buffer=buffer, offset=first + _LEAF_TABLE,
                        strides=(_LEAF_SIZE, 256, 32, 4))
    if not inside.all():  # leaves without an active voxel outside the box
        index, values = index[inside], values[inside]
    as_blocks = aligned.reshape(blocks[0], 8, blocks[1], 8, blocks[2], 8).transpose(0, 2, 4, 1, 3, 5)
    as_blocks[index[:, 0], index[:, 1], index[:, 2]] = values
    start = lo - corner
    stop = start + (hi - lo + 1)
    return np.ascontiguousarray(aligned[start[0] : stop[0], start[1] : stop[1], start[2] : stop[2]]), lo
