"""The same grid as a real OpenVDB .vdb (written by vdb_tool), as NanoVDB .nvdb and as dense .npy renders the same."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from conftest import StageSpec, render_layer, write_stage

from warpsky.core.errors import SceneError
from warpsky.media.voxels.fields import load_field

needs_tools = pytest.mark.skipif(
    not (shutil.which("vdb_tool") and shutil.which("nanovdb_convert")),
    reason="needs vdb_tool (libopenvdb-tools) and nanovdb_convert (libnanovdb-tools); .ci/run installs them",
)


@pytest.fixture
def sphere_files(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    vdb = tmp_path / "sphere.vdb"
    subprocess.run(["vdb_tool", "-sphere", "r=4", "voxel=0.5", "center=1,0.5,-1", "-l2f", "-write", str(vdb)],
                   check=True, capture_output=True)
    nvdb = tmp_path / "sphere.nvdb"
    subprocess.run(["nanovdb_convert", "-f", str(vdb), str(nvdb)], check=True, capture_output=True)
    grid = load_field(nvdb)
    # The dense copy fills an extent equal to the grid's index box [-0.5, n - 0.5] mapped to world space.
    n = np.array(grid.values.shape)
    xf = grid.local_from_index
    lo = xf[:3, :3] @ np.full(3, -0.5) + xf[:3, 3]
    hi = xf[:3, :3] @ (n - 0.5) + xf[:3, 3]
    npy = tmp_path / "sphere.npy"
    np.save(npy, grid.values)
    return vdb, nvdb, npy, (tuple(lo), tuple(hi))


@needs_tools
def test_vdb_nvdb_and_npy_render_the_same(tmp_path, sphere_files, device):
    vdb, nvdb, npy, extent = sphere_files
    images = {}
    for path in (vdb, nvdb, npy):
        spec = StageSpec(volume_file=path, volume_extent=extent, camera_position=(2.0, 3.0, 30.0),
                         extinction_scale=0.8, phase="hg", g=0.5, volume_translate=(0.5, 0.0, 0.0))
        _, layer = render_layer(write_stage(tmp_path / f"{path.suffix[1:]}.usda", spec), device, 24, 24)
        images[path.suffix] = layer
    peak = images[".vdb"].radiance.max()
    assert peak > 0 and images[".vdb"].transmittance.min() < 0.5
    for other in (".nvdb", ".npy"):
        assert np.abs(images[other].radiance - images[".vdb"].radiance).max() <= 1e-5 * peak
        assert np.abs(images[other].transmittance - images[".vdb"].transmittance).max() <= 1e-5
    # the conversion is cached by content hash: one .nvdb in the cache
    assert len(list((tmp_path / "cache" / "nanovdb").glob("*.nvdb"))) == 1


@needs_tools
def test_field_name_picks_the_grid(tmp_path):
    vdb = tmp_path / "two.vdb"
    subprocess.run(["vdb_tool", "-sphere", "r=3", "voxel=1", "name=small", "-l2f", "-sphere", "r=6", "voxel=1",
                    "name=big", "-l2f", "-write", str(vdb)], check=True, capture_output=True)
    names = {}
    for name in ("ls2fog_small", "ls2fog_big"):
        grid = load_field(vdb, grid_name=name)
        names[name] = np.count_nonzero(grid.values)
    assert names["ls2fog_big"] > 4 * names["ls2fog_small"]
    with pytest.raises(SceneError, match="ls2fog_small"):
        load_field(vdb, grid_name="density")


def test_missing_converter_names_the_package(tmp_path, monkeypatch):
    vdb = tmp_path / "x.vdb"
    vdb.write_bytes(b" BDV" + bytes(64))
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(SceneError, match="libnanovdb-tools"):
        load_field(vdb)


@needs_tools
def test_an_empty_grid_is_an_empty_medium(tmp_path, sphere_files, capsys):
    """A simulation's first frame holds no voxels (Blender and Houdini caches): that frame renders without the
    medium and says so in one warning line naming the field; the sequence goes on, and info works at that time."""
    from conftest import run_cli
    from pxr import Sdf, Usd

    vdb = sphere_files[0]
    empty = tmp_path / "smoke_000001.vdb"
    subprocess.run(["vdb_tool", "-sphere", "r=1", "dim=32", "-l2f", "-clip", "bbox=(100,100,100),(101,101,101)",
                    "-write", str(empty)], check=True, capture_output=True)
    assert load_field(empty).empty
    spec = StageSpec(volume_file=vdb, camera_position=(2.0, 3.0, 30.0), extinction_scale=0.8)
    stage_path = write_stage(tmp_path / "smoke.usda", spec)
    stage = Usd.Stage.Open(str(stage_path))
    attr = stage.GetPrimAtPath("/World/Cloud/density").GetAttribute("filePath")
    attr.Clear()
    attr.Set(Sdf.AssetPath(str(empty)), 1.0)
    attr.Set(Sdf.AssetPath(str(vdb)), 2.0)
    stage.SetStartTimeCode(1.0)
    stage.SetEndTimeCode(2.0)
    stage.Save()
    code, out, err = run_cli(["info", str(stage_path)], capsys)
    assert code == 0, err
    assert err.count("warning:") == 1 and "/World/Cloud/density" in err and "no active voxels" in err
    code, out, err = run_cli(["render", str(stage_path), str(tmp_path / "out" / "f.####.exr"), "--frames", "1:2",
                              "--res", "16x16", "--technique", "single_scatter"], capsys)
    assert code == 0, err
    assert (tmp_path / "out" / "f.0001.exr").is_file() and (tmp_path / "out" / "f.0002.exr").is_file()
    assert "no active voxels" in err
