"""Velocity blur: a Volume's density moved along its velocity field to each sub-frame's time."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

import warpsky
from warpsky.media.voxels.fields import load_vector_field
from warpsky.media.voxels.velocity import advected_grid

FAST = {"technique": "single_scatter", "resolution": (32, 16), "device": "cpu", "settings": {"step_length": "0.5"}}
#: A speed [m/s] that moves the blob 8 voxels (of 1 m) per frame at 24 frames per second.
SPEED = 192.0


def blob(n: int = 24) -> np.ndarray:
    """A smooth blob that is zero on the grid's border, so a shifted copy has no edge of its own."""
    x = np.arange(n) - (n - 1) / 2
    r2 = x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2
    return np.where(r2 < 8.0 ** 2, np.exp(-r2 / 18.0), 0.0).astype(np.float32)


def stage_text(density: str, *, velocity: str | None = None, moving: bool = False) -> str:
    translate = ("double3 xformOp:translate.timeSamples = {1: (0, 0, 0), 2: (8, 0, 0)}" if moving
                 else "double3 xformOp:translate = (0, 0, 0)")
    field = (f'rel field:vel = </World/Smoke/vel>\n        def OpenVDBAsset "vel"\n        {{\n'
             f'            asset filePath = @{velocity}@\n            token fieldDataType = "vector3f"\n        }}'
             if velocity else "")
    return f"""#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
    startTimeCode = 1
    endTimeCode = 2
    timeCodesPerSecond = 24
)
def Xform "World"
{{
    def Camera "Camera"
    {{
        float focalLength = 20
        float horizontalAperture = 36
        float verticalAperture = 18
        double shutter:open = 0
        double shutter:close = 1
        double3 xformOp:translate = (4, 0, 50)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = (-45, 30, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }}
    def Volume "Smoke"
    {{
        float3[] extent = [(-12, -12, -12), (12, 12, 12)]
        {translate}
        uniform token[] xformOpOrder = ["xformOp:translate"]
        rel field:density = </World/Smoke/density>
        def OpenVDBAsset "density"
        {{
            asset filePath = @{density}@
            float warpsky:extinctionScale = 0.3
        }}
        {field}
    }}
}}
"""


@pytest.fixture
def smoke(tmp_path):
    density, velocity = tmp_path / "density.npy", tmp_path / "vel.npy"
    np.save(density, blob())
    np.save(velocity, np.broadcast_to(np.array([SPEED, 0.0, 0.0], np.float32), (24, 24, 24, 3)).copy())
    paths = {}
    for name, text in {"velocity": stage_text(density, velocity=velocity), "still": stage_text(density),
                       "moving": stage_text(density, moving=True)}.items():
        paths[name] = tmp_path / f"{name}.usda"
        paths[name].write_text(text)
    return paths


def test_a_velocity_blurred_frame_is_the_average_of_the_moved_volume(smoke):
    """A blob whose velocity field moves it 8 m per frame, shutter [0, 1], 4 sub-frames: the frame equals the mean
    of unblurred renders of the same blob translated by its xform to 1, 3, 5 and 7 m (whole voxels, where one
    semi-Lagrangian step is exact) to the march's precision; without an open shutter the velocity changes nothing."""
    blurred = warpsky.render_stage(str(smoke["velocity"]), 1.0, motion_samples=4, **FAST)
    subs = [warpsky.render_stage(str(smoke["moving"]), t, shutter=(0.0, 0.0), **FAST)
            for t in (1.125, 1.375, 1.625, 1.875)]
    mean = np.mean([s.frame.rgba for s in subs], axis=0)
    # the moved grid is larger (padded), so the march's samples start elsewhere: 1.4e-4 at 0.5 m steps, 3e-5 at 0.1
    np.testing.assert_allclose(blurred.frame.rgba, mean, atol=3e-4 * mean.max())
    still = warpsky.render_stage(str(smoke["velocity"]), 1.0, shutter=(0.0, 0.0), **FAST)
    plain = warpsky.render_stage(str(smoke["still"]), 1.0, shutter=(0.0, 0.0), **FAST)
    np.testing.assert_array_equal(still.frame.rgba, plain.frame.rgba)
    assert np.abs(blurred.frame.rgba - still.frame.rgba).max() > 0.05 * still.frame.rgba.max()


def test_one_step_conserves_a_translated_blob_and_grows_the_box():
    """A uniform velocity over 0.3 s moves the blob by 2.5 voxels: its sum is kept (the trilinear lookups of a
    blob zero at the border), its centre of mass moves by 2.5 voxels, the grid grows by 4 voxels a side and the
    index-to-space matrix keeps every voxel where it was."""
    density = blob()
    dens_from_index = np.eye(4)
    dens_from_index[:3, 3] = -11.5
    velocity = np.broadcast_to(np.array([0.0, 0.0, 2.5 / 0.3], np.float32), (24, 24, 24, 3))
    moved, grown = advected_grid(density, dens_from_index, velocity, dens_from_index, 0.3)
    assert moved.shape == (32, 32, 32) and np.allclose(grown[:3, 3], -15.5)
    assert moved.sum() == pytest.approx(density.sum(), rel=1e-5)
    z = np.arange(32) - 4.0
    centre = (moved.sum(axis=(0, 1)) * z).sum() / moved.sum()
    assert centre == pytest.approx(11.5 + 2.5, abs=1e-4)


@pytest.mark.skipif(shutil.which("vdb_tool") is None, reason="needs OpenVDB's vdb_tool")
def test_a_vec3_vdb_grid_reads_as_a_dense_velocity(tmp_path):
    """OpenVDB's closest-point transform of a unit sphere (a Vec3f grid) read through nanovdb_convert and Warp's
    vector lookups: each active voxel's vector is the closest point of the sphere to the voxel's centre (placed by
    the grid's own transform)."""
    out = tmp_path / "cpt.vdb"
    subprocess.run(["vdb_tool", "-sphere", "d=32", "r=1.0", "-cpt", "-write", str(out)], check=True,
                   capture_output=True)
    grid = load_vector_field(out)
    assert grid.values.ndim == 4 and grid.values.shape[3] == 3
    on = np.linalg.norm(grid.values, axis=-1) > 0.0
    index = np.argwhere(on)
    assert len(index) > 1000
    x = (grid.local_from_index @ np.c_[index, np.ones(len(index))].T).T[:, :3]  # each voxel's centre
    voxel = np.linalg.norm(grid.local_from_index[:3, 0])
    closest = x / np.linalg.norm(x, axis=1, keepdims=True)  # the sphere's closest point, in closed form
    error = np.linalg.norm(grid.values[on] - closest, axis=1) / voxel
    assert np.median(error) < 0.1 and error.max() < 2.5  # a narrow band's first-order transform, exact near it


def test_a_batch_renders_a_blurred_frame_again_when_its_velocity_file_changes(smoke, tmp_path, capsys):
    """The resume hash holds the velocity field's file as it holds the density's: a second run leaves the frame
    alone, a rewritten velocity grid renders it again (a new settings hash in its header)."""
    from conftest import run_cli

    from warpsky.output.exr import read_exr

    out = tmp_path / "b.0001.exr"
    args = ["render", str(smoke["velocity"]), tmp_path / "b.####.exr", "--frames", "1", "--res", "16x8",
            "--motion-samples", "2", "--device", "cpu", "--technique", "single_scatter", "--set", "step_length=2"]
    assert run_cli(args, capsys)[0] == 0
    first = (out.stat().st_mtime_ns, read_exr(out).metadata["settingsHash"])
    assert run_cli(args, capsys)[0] == 0
    assert (out.stat().st_mtime_ns, read_exr(out).metadata["settingsHash"]) == first  # up to date: skipped
    np.save(tmp_path / "vel.npy", np.broadcast_to(np.array([SPEED, 1.0, 0.0], np.float32), (24, 24, 24, 3)).copy())
    assert run_cli(args, capsys)[0] == 0
    assert read_exr(out).metadata["settingsHash"] != first[1]
