"""The shadow marches' shortcuts. Empty space skipped by the shadow marches and the single-scatter eye march: cells
whose dilated maxima are 0 hold exactly 0 at every trilinear lookup, so skipping them changes the quadrature's
sample points, never the integrand. Vertical optical depths from column sums: exact for the trilinear field."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpsky.media.voxels.bricks import cell_maxima
from warpsky.media.voxels.shadow import depth_functions, empty_until
from warpsky.media.voxels.voxel import OCCUPANCY_BLOCK, VoxelMedia, VoxelMediaBuffers, grid_value
from warpsky.model.scene import VoxelMedium

sun_optical_depth, vertical_optical_depth = depth_functions(False)


@wp.kernel
def depth_kernel(media: VoxelMedia, points: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3), step: float,
                 out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = sun_optical_depth(media, points[i], 0.0, dirs[i], dirs[i], step)


@wp.kernel
def vertical_kernel(media: VoxelMedia, points: wp.array(dtype=wp.vec3), down: int, step: float,
                    out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = vertical_optical_depth(media, points[i], 0.0, wp.vec3(1.0, 0.0, 0.0), down, step)


@wp.kernel
def empty_kernel(media: VoxelMedia, points: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
                 until: wp.array(dtype=float), worst: wp.array(dtype=float)):
    """``until`` per ray, and the largest field value sampled on 512 points of [0, min(until, 200 m))."""
    i = wp.tid()
    u = empty_until(media, points[i], dirs[i], 0.0)
    until[i] = u
    grid = media.grids[0]
    top = float(0.0)
    length = wp.min(u, 200.0)
    for k in range(512):
        p = points[i] + (length * (float(k) + 0.5) / 512.0) * dirs[i]
        top = wp.max(top, grid_value(media.values, grid, grid.eye_index + grid.index_from_world * p))
    worst[i] = top


def sparse_medium(shape=(40, 24, 32), seed=3, voxel=10.0) -> VoxelMedium:
    """Three Gaussian puffs lowered by 5 % of their peak and clipped at 0, in a box mostly empty; 10 m voxels."""
    rng = np.random.default_rng(seed)
    idx = np.stack(np.meshgrid(*[np.arange(n, dtype=np.float32) for n in shape], indexing="ij"), -1)
    density = np.zeros(shape, np.float32)
    for _ in range(3):
        centre = rng.uniform(6, np.array(shape) - 6)
        r = rng.uniform(2.5, 4.5)
        density += np.exp(-np.sum((idx - centre) ** 2, -1) / (2 * r * r)).astype(np.float32)
    density = np.maximum(density - 0.05, 0.0)
    world = np.diag([voxel, voxel, voxel, 1.0])
    world[:3, 3] = -0.5 * voxel * np.array(shape)
    return VoxelMedium("/puffs", density, world, extinction_scale=np.array([0.02, 0.03, 0.04]))


def rays(count=400, seed=1):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-220, 220, (count, 3)).astype(np.float32)
    points[:, 1] *= 0.6
    dirs = rng.normal(size=(count, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return points, dirs.astype(np.float32)


def depths(medium, device, cells: bool, step: float):
    buffers = VoxelMediaBuffers.upload((medium,), np.zeros(3), device, cells=cells)
    points, dirs = rays()
    out = wp.zeros(len(points), dtype=wp.vec4, device=device)
    wp.launch(depth_kernel, dim=len(points), inputs=[buffers.media, wp.array(points, dtype=wp.vec3, device=device),
                                                        wp.array(dirs, dtype=wp.vec3, device=device), step, out],
              device=device)
    return out.numpy()


def test_cells_hold_the_dilated_maxima():
    medium = sparse_medium()
    cells = cell_maxima(medium.density, OCCUPANCY_BLOCK)
    assert cells.shape == tuple(-(-n // OCCUPANCY_BLOCK) for n in medium.density.shape)
    assert 0.0 < np.mean(cells > 0.0) < 0.8  # the puffs leave empty cells to skip


def test_skipping_keeps_the_optical_depth_and_saves_lookups(device):
    medium = sparse_medium()
    skipped = depths(medium, device, True, 5.0)
    walked = depths(medium, device, False, 5.0)
    fine = depths(medium, device, False, 5.0 / 16.0)
    assert np.all(np.isfinite(skipped)) and np.all(skipped[:, :3] >= 0.0)
    hit = fine[:, 0] > 1e-3
    assert hit.sum() > 40
    # both marches are midpoint rules with steps of at most 5 m, one voxel being 10 m: each is within the same small
    # quadrature error of a 16x finer march, and misses of rays that cross no puff are exactly 0 in both
    for depth in (skipped, walked):
        np.testing.assert_allclose(depth[hit, :3], fine[hit, :3], rtol=2e-2, atol=3e-3)
    error = [np.sqrt(np.mean((d[hit, :3] - fine[hit, :3]) ** 2)) for d in (skipped, walked)]
    assert error[0] < 1.5 * error[1] + 1e-6
    np.testing.assert_array_equal(skipped[~hit & (walked[:, 0] == 0.0), :3], 0.0)
    assert skipped[:, 3].sum() < 0.8 * walked[:, 3].sum()


def test_a_fully_occupied_grid_is_walked_as_one_run(device):
    medium = sparse_medium()
    medium.density[...] += 0.5  # no empty cell: the run is the whole chord, the samples the same
    np.testing.assert_array_equal(depths(medium, device, True, 5.0), depths(medium, device, False, 5.0))


def test_empty_until_ends_where_the_medium_can_begin(device):
    medium = sparse_medium()
    buffers = VoxelMediaBuffers.upload((medium,), np.zeros(3), device)
    points, dirs = rays(seed=2)
    until = wp.zeros(len(points), dtype=float, device=device)
    worst = wp.zeros(len(points), dtype=float, device=device)
    wp.launch(empty_kernel, dim=len(points), inputs=[buffers.media, wp.array(points, dtype=wp.vec3, device=device),
                                                       wp.array(dirs, dtype=wp.vec3, device=device), until, worst],
              device=device)
    until, worst = until.numpy(), worst.numpy()
    assert np.all(until >= 0.0)
    np.testing.assert_array_equal(worst[until > 0.0], 0.0)  # nothing but zeros before ``until``
    assert np.mean(until > 0.0) > 0.3  # and most rays start in empty space here


def test_the_eye_march_skips_without_changing_the_image(device, tmp_path, monkeypatch):
    from conftest import StageSpec, render_layer, write_stage

    medium = sparse_medium()
    np.save(tmp_path / "puffs.npy", medium.density)
    half = 0.5 * 10.0 * np.array(medium.density.shape)
    stage = write_stage(tmp_path / "puffs.usda", StageSpec(
        camera_position=(0.0, 0.0, 700.0), volume_file=tmp_path / "puffs.npy",
        volume_extent=(tuple(-half), tuple(half)), extinction_scale=0.03, phase="hg", g=0.6))
    skipped = render_layer(stage, device, 32, 24)[1]
    original = VoxelMediaBuffers.upload.__func__

    def without_cells(cls, *args, **kwargs):
        kwargs["cells"] = False
        return original(cls, *args, **kwargs)

    monkeypatch.setattr(VoxelMediaBuffers, "upload", classmethod(without_cells))
    walked = render_layer(stage, device, 32, 24)[1]
    a, b = np.asarray(skipped.radiance), np.asarray(walked.radiance)
    assert b.max() > 0.0
    np.testing.assert_allclose(a, b, rtol=0.0, atol=2e-3 * float(b.max()))
    np.testing.assert_allclose(np.asarray(skipped.transmittance), np.asarray(walked.transmittance), atol=1e-6)


@pytest.mark.parametrize("down", [0, 1])
def test_column_sums_give_the_vertical_depth_exactly(device, down):
    medium = sparse_medium()
    medium.density[...] += np.random.default_rng(4).random(medium.density.shape).astype(np.float32) * 0.3
    points, _ = rays(seed=5)
    points[:40, 1] = [-130.0, 130.0] * 20  # below and above the box (its height is 240 m)
    out = {}
    for key, cells, step in (("columns", True, 5.0), ("fine", False, 10.0 / 64.0)):
        buffers = VoxelMediaBuffers.upload((medium,), np.zeros(3), device, cells=cells)
        result = wp.zeros(len(points), dtype=wp.vec4, device=device)
        wp.launch(vertical_kernel, dim=len(points), inputs=[
            buffers.media, wp.array(points, dtype=wp.vec3, device=device), down, step, result], device=device)
        out[key] = result.numpy()
    inside = out["fine"][:, 0] > 0.0
    assert inside.sum() > 100
    assert np.all(out["columns"][:, 3] == 4.0) and np.all(out["fine"][inside, 3] > 4.0)
    # the midpoint rule at 1/64 voxel is within ~1e-5 of the integral of the piecewise-linear field
    np.testing.assert_allclose(out["columns"][:, :3], out["fine"][:, :3], rtol=2e-4, atol=1e-6)


def test_only_a_grid_whose_index_y_is_vertical_sums_columns():
    from warpsky.media.voxels.voxel import upright_metres

    assert upright_metres(np.linalg.inv(np.diag([10.0, 25.0, 10.0, 1.0]))) == pytest.approx(25.0)
    c, s = np.cos(0.3), np.sin(0.3)
    tilted = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])
    assert upright_metres(np.linalg.inv(tilted)) == 0.0
    assert upright_metres(np.linalg.inv(np.diag([1.0, -1.0, 1.0, 1.0]))) == 0.0  # index y pointing down
