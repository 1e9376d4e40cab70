"""What the program loads to start and to render one small frame: nothing a frame does not use (the start-up's
import time is most of a small frame's command; docs/validation/startup.md has the figures)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CUMULUS = ROOT / "usd_scenes" / "cumulus.usda"

#: Never loaded to start or to render: the evaluation code beside the package, peers, farms and plotting.
NEVER = ("evaluation", "mitsuba", "drjit", "dask", "distributed", "pyvista", "vtk", "matplotlib", "scipy")
#: Not loaded by a frame of a cloud under a clear sky (no stratiform layer, no mesh, no fog, no preview): the
#: stratiform pass's optics, radiosity and kernels, the surfaces pass's kernels, the meshes, the shadowed air in
#: front and OpenColorIO (the default view needs it only to write a preview).
UNUSED_BY_A_CLOUD = ("warpsky.passes.stratiform.stratiform_kernels", "warpsky.passes.stratiform.radiosity",
                     "warpsky.passes.stratiform.optics", "warpsky.passes.stratiform.slab",
                     "warpsky.passes.stratiform.model1d", "warpsky.passes.surfaces.surfaces_kernels",
                     "warpsky.surfaces.mesh", "warpsky.passes.sky.shadowed_air", "PyOpenColorIO")


def _modules_after(code: str) -> set[str]:
    """The names in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    script = code + "\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))\n"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


def _loaded(names: set[str], prefixes) -> list[str]:
    return sorted(n for n in names if any(n == p or n.startswith(p + ".") for p in prefixes))


def test_the_command_line_loads_neither_warp_usd_nor_peers():
    names = _modules_after("import warpsky.cli.main")
    assert "warpsky.cli.main" in names
    assert not _loaded(names, NEVER + ("warp", "pxr", "OpenEXR", "PyOpenColorIO"))


@pytest.mark.skipif(not (ROOT / "data" / "cumulus.nvdb").is_file(), reason="needs make data (data/cumulus.nvdb)")
def test_a_small_cloud_frame_loads_only_what_it_draws(tmp_path):
    out = tmp_path / "c.exr"
    names = _modules_after(
        "from warpsky.cli.main import main\n"
        f"assert main(['render', {str(CUMULUS)!r}, {str(out)!r}, '--res', '32x32', '--technique', 'single_scatter',"
        " '-q']) == 0")
    assert out.is_file()
    assert "warpsky.passes.sky.round_sky" in names  # the frame did draw its round earth's sky
    assert not _loaded(names, NEVER), _loaded(names, NEVER)
    assert not _loaded(names, UNUSED_BY_A_CLOUD), _loaded(names, UNUSED_BY_A_CLOUD)


def test_the_round_earths_depth_table_comes_back_from_disk_bit_for_bit(tmp_path, monkeypatch):
    """The optical depth table is built once per air and floor and read back from the disk cache by the next
    process exactly as built; an unreadable cache entry is built again."""
    import numpy as np

    from warpsky.media.air import round_earth_kernels as ar
    from warpsky.model.scene import Atmosphere

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    monkeypatch.setattr(ar, "_TABLES", {})
    atm = Atmosphere(planet_radius=6.36e6)
    built = ar.depth_table(atm, 0.0, "cpu").numpy()
    (entry,) = (tmp_path / "air").glob("round-depth-*.npy")
    assert np.all(np.isfinite(built)) and built.min() >= 0.0 and built.max() > 0.0
    monkeypatch.setattr(ar, "_TABLES", {})  # a new process: nothing in memory
    np.testing.assert_array_equal(ar.depth_table(atm, 0.0, "cpu").numpy(), built)
    entry.write_bytes(b"not an array")
    monkeypatch.setattr(ar, "_TABLES", {})
    np.testing.assert_array_equal(ar.depth_table(atm, 0.0, "cpu").numpy(), built)
    np.testing.assert_array_equal(np.load(entry), built)
    # another floor is another table
    monkeypatch.setattr(ar, "_TABLES", {})
    other = ar.depth_table(atm, 500.0, "cpu").numpy()
    assert len(list((tmp_path / "air").glob("round-depth-*.npy"))) == 2 and not np.array_equal(other, built)


@pytest.mark.skipif(not (ROOT / "data" / "cumulus.nvdb").is_file(), reason="needs make data (data/cumulus.nvdb)")
def test_the_view_table_is_kept_by_the_value_of_its_inputs(tmp_path, monkeypatch):
    """The sky's view table read back from disk is the one the kernel builds; another sun is another table; the
    least recently used tables go beyond VIEW_TABLES_KEPT."""
    import numpy as np
    import warp as wp

    from warpsky.passes.sky import round_sky
    from warpsky.usd.stage import StageReader

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    scene = StageReader(CUMULUS).scene_at(None)
    _, air, ra, ms, view, sun, radius = round_sky.round_front_inputs(scene, scene.camera, 32, 32, "cpu")
    first = view.table.numpy().copy()
    fresh = wp.zeros(first.shape[:2] + (4,), dtype=wp.vec3, device="cpu")
    wp.launch(round_sky.view_table_kernel, dim=first.shape[:2], inputs=[air, ra, ms, sun, radius, fresh, 0],
              device="cpu")
    np.testing.assert_array_equal(first, fresh.numpy())  # built over row bands = one launch
    assert len(list((tmp_path / "air").glob("round-views-*.npy"))) == 1

    def no_launch(*args):
        raise AssertionError("the view table was built again")

    monkeypatch.setattr(round_sky, "launch_rows", no_launch)
    np.testing.assert_array_equal(round_sky.view_table([air, ra, ms, sun, radius], "cpu").numpy(), first)
    monkeypatch.undo()
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    monkeypatch.setattr(round_sky, "VIEW_TABLES_KEPT", 2)
    for angle in (0.1, 0.2):
        sun.disk_direction = wp.vec3(np.sin(angle), np.cos(angle), 0.0)
        other = round_sky.view_table([air, ra, ms, sun, radius], "cpu").numpy()
        assert not np.array_equal(other, first)
    assert len(list((tmp_path / "air").glob("round-views-*.npy"))) == 2
