"""``warpsky prepare`` builds what a frame needs and says how long each part took; first-time work (a kernel compile,
the air's table) says so on stderr, once, and ``--quiet`` silences it."""

from __future__ import annotations

import numpy as np
from conftest import StageSpec, run_cli, write_stage


def test_prepare_plans_builds_and_summarises(tmp_path, homogeneous_npy, capsys, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))
    code, out, err = run_cli(["prepare", stage, "--res", "16x12", "--technique", "single_scatter"], capsys)
    assert code == 0, err
    lines = out.strip().splitlines()
    assert lines[0].startswith(f"prepared {stage} in ") and "16x12 frame of single_scatter on cpu" in lines[0]
    names = [line.split()[0] for line in lines[1:]]
    assert names == ["plan", "optics", "kernels", "other", "warm-up"], out
    assert "passes media" in lines[1] and "8x6 pixels" in lines[-1] and "nothing written" in lines[-1]
    assert not list(tmp_path.glob("*.exr"))

    code, out, err = run_cli(["--quiet", "prepare", stage, "--res", "16x12", "--technique", "single_scatter"], capsys)
    assert code == 0 and out.startswith("prepared") and err == "", err


def test_prepare_refuses_a_bad_input_in_one_line(tmp_path, homogeneous_npy, capsys):
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))
    code, _, err = run_cli(["prepare", stage, "--camera", "/NoSuchCamera", "--technique", "single_scatter"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "/NoSuchCamera" in err, err


def test_a_first_compile_says_so_once(tmp_path, monkeypatch, capsys):
    """A module missing from Warp's kernel cache prints a start line (for the technique named, with the cache) and
    a done line with its time; the next process finds it cached and prints nothing; quiet prints nothing either."""
    import warp as wp

    from warpsky.core import progress
    from warpsky.core.device import init_warp
    from warpsky.render.compile_progress import compiling_for, install

    init_warp()
    install()
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "kernels"))
    monkeypatch.setattr(progress, "DONE", [])

    @wp.kernel
    def doubled(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = 2.0 * float(i)

    values = wp.zeros(3, dtype=float, device="cpu")
    with compiling_for("toy"):
        wp.launch(doubled, dim=3, inputs=[values], device="cpu")
    np.testing.assert_array_equal(values.numpy(), [0.0, 2.0, 4.0])
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2, err
    assert err[0].startswith("warpsky: compiling kernels for toy on cpu: test_prepare (about ")
    assert f"first use only; cached in {tmp_path / 'kernels'}) ..." in err[0]
    assert err[1].startswith("warpsky: ... test_prepare compiled in ") and err[1].endswith(" s")
    assert [work.kind for work in progress.DONE] == ["kernels"]

    doubled.module.unload()  # as a new process would: the module is loaded again, from the cache
    wp.launch(doubled, dim=3, inputs=[values], device="cpu")
    assert capsys.readouterr().err == ""


def test_the_air_table_is_built_once_and_read_from_the_disk_cache(tmp_path, monkeypatch, capsys):
    from warpsky.core.device import init_warp
    from warpsky.media.air import round_earth_multiple as rem
    from warpsky.model.scene import Atmosphere

    init_warp()
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    atm = Atmosphere(planet_radius=6.371e6)
    rem._cached.cache_clear()
    built = rem.round_table(atm, 0.0, (0.1, 0.1, 0.1), "cpu")
    err = capsys.readouterr().err
    assert err.count("building the air's multiple-scattering table on cpu") == 1
    assert f"then loaded from {tmp_path / 'air'})" in err
    assert len(list((tmp_path / "air").glob("round-earth-*.npz"))) == 1

    rem._cached.cache_clear()  # a new process
    loaded = rem.round_table(atm, 0.0, (0.1, 0.1, 0.1), "cpu")
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(loaded.values, built.values)
    assert (loaded.floor, loaded.height, loaded.mie_g, loaded.radius) == (built.floor, built.height, built.mie_g,
                                                                          built.radius)
    rem._cached.cache_clear()


def test_a_long_frame_says_every_interval_where_it_stands(capsys, monkeypatch):
    """Work inside ``working`` prints ``... still <doing> (N s; status)`` every interval with the last status the
    work reported, nothing after the block, and nothing under ``--quiet``; ``status`` outside one does nothing."""
    import time

    from warpsky.core import progress

    progress.status("ignored: no work is being timed")
    monkeypatch.delenv(progress.QUIET_ENV, raising=False)
    with progress.working("rendering frame 3", every=0.05):
        progress.status("hybrid: 8 of at most 256 paths per pixel")
        time.sleep(0.18)
    time.sleep(0.1)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) >= 2
    assert all(line.startswith("warpsky: ... still rendering frame 3 (") for line in lines)
    assert lines[-1].endswith("; hybrid: 8 of at most 256 paths per pixel)")
    with progress.quieted(), progress.working("rendering frame 4", every=0.02):
        time.sleep(0.1)
    assert capsys.readouterr().err == ""
