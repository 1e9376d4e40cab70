"""A NanoVDB grid copied into a dense array leaf by leaf (NumPy) equals the voxel-by-voxel walk of Warp's lookup, bit
for bit; grids with tiles are left to the walk."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
import warp as wp

from warpsky.media.voxels import fields
from warpsky.media.voxels.nanovdb_dense import dense_from_leaves, grid_map


def _grid_buffer(blob: bytes) -> memoryview:
    return memoryview(blob)[fields._single_grid_offset(blob):]


def _only_grid(path):
    (grid,) = fields.nanovdb_grids(path.read_bytes(), path)
    return grid


def _walk(grid, source):
    volume = wp.Volume.load_from_nvdb(grid.blob, device="cpu")
    return fields._walked(volume, False, grid.name, source)


def _sparse_nvdb(tmp_path, values: np.ndarray, name: str, *, bg_value: float = 0.0):
    volume = wp.Volume.load_from_numpy(values, min_world=(-3.0, 2.0, 7.0), voxel_size=1.5, bg_value=bg_value,
                                       device="cpu")
    path = tmp_path / f"{name}.nvdb"
    volume.save_to_nvdb(str(path), codec="zip")
    return path


def test_leaves_copied_equal_the_walk(tmp_path):
    rng = np.random.default_rng(7)
    values = np.zeros((37, 21, 30), np.float32)
    values[3:30, 5:19, 2:25] = rng.random((27, 14, 23), dtype=np.float32)  # not aligned to the 8^3 leaves
    values[values < 0.3] = 0.0  # holes inside leaves
    values[0, 0, 0] = 2.5  # a lone voxel far from the rest
    path = _sparse_nvdb(tmp_path, values, "sparse")
    grid = _only_grid(path)
    decoded = dense_from_leaves(_grid_buffer(grid.blob))
    assert decoded is not None
    walked, lo = _walk(grid, path)
    assert decoded[0].shape == walked.shape
    np.testing.assert_array_equal(decoded[0].view(np.uint32), walked.view(np.uint32))
    np.testing.assert_array_equal(decoded[1], lo)
    # the map read from the buffer is the one Warp's loader gives
    info = wp.Volume.load_from_nvdb(grid.blob, device="cpu").get_grid_info()
    linear, translation = grid_map(_grid_buffer(grid.blob))
    np.testing.assert_array_equal(linear, np.array(info.transform_matrix, dtype=np.float64).reshape(3, 3))
    np.testing.assert_array_equal(translation, np.array(info.translation, dtype=np.float64))
    assert linear[0, 0] == 1.5
    # and load_field gives the same grid as the walk
    field = fields.load_field(path)
    np.testing.assert_array_equal(field.values.view(np.uint32), walked.view(np.uint32))
    # the source values come back where they were written (one voxel of background around the active box)
    start = -lo.astype(int)
    np.testing.assert_array_equal(field.values[start[0] : start[0] + 37, start[1] : start[1] + 21,
                                               start[2] : start[2] + 30][values > 0], values[values > 0])


def test_the_background_fills_the_rest(tmp_path):
    values = np.full((20, 9, 9), 0.25, np.float32)
    values[12:, :, 4] = 3.0
    path = _sparse_nvdb(tmp_path, values, "background", bg_value=0.25)
    grid = _only_grid(path)
    decoded = dense_from_leaves(_grid_buffer(grid.blob))
    assert decoded is not None
    walked, lo = _walk(grid, path)
    np.testing.assert_array_equal(decoded[0].view(np.uint32), walked.view(np.uint32))
    np.testing.assert_array_equal(decoded[1], lo)
    assert decoded[0][0, 0, 0] == 0.25 and decoded[0].max() == 3.0


@pytest.mark.skipif(not (shutil.which("vdb_tool") and shutil.which("nanovdb_convert")),
                    reason="needs vdb_tool (libopenvdb-tools) and nanovdb_convert (libnanovdb-tools)")
def test_a_grid_with_tiles_is_walked(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    vdb = tmp_path / "ball.vdb"
    # a fog ball of radius 20 voxels: OpenVDB keeps its constant interior as active tiles of value 1
    subprocess.run(["vdb_tool", "-sphere", "r=20", "voxel=1", "-l2f", "-write", str(vdb)], check=True,
                   capture_output=True)
    nvdb = fields.convert_vdb(vdb)
    grid = _only_grid(nvdb)
    assert dense_from_leaves(_grid_buffer(grid.blob)) is None
    walked, _ = _walk(grid, nvdb)
    field = fields.load_field(vdb)
    np.testing.assert_array_equal(field.values.view(np.uint32), walked.view(np.uint32))
    assert field.values.max() == 1.0  # the tiles' value reached the dense grid
