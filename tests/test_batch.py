"""Batch renders: Dask executors give the same pixels, resume skips finished frames, failures cost nothing else."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from warpsky.cli.main import main
from warpsky.output.exr import read_exr

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import make_storm  # noqa: E402

pytestmark = pytest.mark.slow  # the module fixture builds four species' tables, then Dask starts workers

FRAMES = 6
FAST = ["--res", "32x22", "--device", "cpu", "--technique", "slicing", "--set", "slice_count=12",
        "--set", "light_resolution=32", "--set", "orders=12"]


@pytest.fixture(scope="module")
def tiny_storm(tmp_path_factory, species_phase):
    """A 6-frame storm at 16 voxels across (every species present from frame 2 on)."""
    for name in ("cloud", "rain", "snow", "ice"):
        species_phase(name)
    root = tmp_path_factory.mktemp("storm")
    make_storm.write_frames(root / "data", FRAMES, res=16)
    return make_storm.write_stage(root / "storm.usda", root / "data", FRAMES)


def render(args, capsys):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def pixels(path: Path) -> dict:
    image = read_exr(path)
    return {name: np.asarray(values) for name, values in image.channels.items()}


def run_log(out_dir: Path) -> list:
    return json.loads((out_dir / "storm.log.json").read_text())["runs"]


def test_local_cluster_gives_identical_pixels(tiny_storm, tmp_path, capsys):
    code, _, err = render(["render", tiny_storm, tmp_path / "a" / "storm.####.exr", *FAST], capsys)
    assert code == 0, err
    code, _, err = render(["render", tiny_storm, tmp_path / "b" / "storm.####.exr", *FAST, "--workers", "2"], capsys)
    assert code == 0, err
    assert "LocalCluster, 2 worker" in err and "6 asked: 6 rendered" in err
    workers = {frame["worker"] for frame in run_log(tmp_path / "b")[-1]["frames"]}
    assert len(workers) == 2 and all(w.split(":")[1] != str(os.getpid()) for w in workers)
    for frame in range(1, FRAMES + 1):
        a = pixels(tmp_path / "a" / f"storm.{frame:04d}.exr")
        b = pixels(tmp_path / "b" / f"storm.{frame:04d}.exr")
        assert a.keys() == b.keys()
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"frame {frame} channel {name}")


def test_failed_frame_is_resumed_without_rerendering_the_others(tiny_storm, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    monkeypatch.setenv("WARPSKY_FAIL_FRAMES", "3")
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--retries", "0"], capsys)
    assert code != 0 and "frame 3" in err and "test hook" in err
    assert not (out / "storm.0003.exr").exists()
    finished = {f: (out / f"storm.{f:04d}.exr").stat().st_mtime_ns for f in (1, 2, 4, 5, 6)}
    monkeypatch.delenv("WARPSKY_FAIL_FRAMES")
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST], capsys)
    assert code == 0, err
    assert "1 rendered, 5 skipped" in err
    assert {f: (out / f"storm.{f:04d}.exr").stat().st_mtime_ns for f in finished} == finished
    assert (out / "storm.0003.exr").is_file()
    first, second = run_log(out)[-2:]
    assert first["summary"]["failed"] == 1 and first["summary"]["done"] == 5
    assert second["summary"]["done"] == 1 and second["summary"]["skipped"] == 5
    assert [f["frame"] for f in second["frames"] if f["status"] == "done"] == [3.0]
    # a changed setting changes the hash: nothing is skipped
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--set", "xi=0.2",
                           "--frames", "1:2"], capsys)
    assert code == 0 and "2 rendered, 0 skipped" in err


def test_retry_recovers_a_transient_failure(tiny_storm, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    monkeypatch.setenv("WARPSKY_FAIL_FRAMES", "2@1")  # only the first attempt fails
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--frames", "1:3"], capsys)
    assert code == 0, err
    assert "retrying" in err and "3 rendered" in err
    records = [f for f in run_log(out)[-1]["frames"] if f["frame"] == 2.0]
    assert [(r["status"], r["attempt"]) for r in records] == [("failed", 1), ("done", 2)]


def test_truncated_exr_and_rewritten_data_are_rendered_again(tiny_storm, tmp_path, capsys):
    out = tmp_path / "out"
    assert render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--frames", "1:2"], capsys)[0] == 0
    path = out / "storm.0002.exr"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--frames", "1:2"], capsys)
    assert code == 0 and "1 rendered, 1 skipped" in err
    assert read_exr(path).width == 32
    # a rewritten field file (new modification time) makes its frame stale: the hash covers the inputs
    field = tiny_storm.parent / "data" / "cloud.0001.nvdb"
    stat = field.stat()
    os.utime(field, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--frames", "1:2"], capsys)
    assert code == 0 and "1 rendered, 1 skipped" in err
    assert [f["frame"] for f in run_log(out)[-1]["frames"] if f["status"] == "done"] == [1.0]


def test_missing_frame_file_fails_only_that_frame(tiny_storm, tmp_path, capsys):
    import shutil

    stage_dir = tmp_path / "copy"
    shutil.copytree(tiny_storm.parent, stage_dir)
    (stage_dir / "data" / "cloud.0004.nvdb").unlink()
    out = tmp_path / "out"
    code, _, err = render(["render", stage_dir / "storm.usda", out / "storm.####.exr", *FAST], capsys)
    assert code == 2 and "cloud.0004.nvdb" in err
    assert sorted(p.name for p in out.glob("*.exr")) == [f"storm.{f:04d}.exr" for f in (1, 2, 3, 5, 6)]
    assert "retrying" not in err  # an input error fails the same way again


def test_frames_outside_the_stage_warn_and_render(tiny_storm, tmp_path, capsys):
    code, _, err = render(["render", tiny_storm, tmp_path / "storm.####.exr", *FAST, "--frames", "7"], capsys)
    assert code == 0 and "outside the stage's time range 1..6" in err
    assert (tmp_path / "storm.0007.exr").is_file()


def test_unreachable_scheduler_and_unwritable_output(tiny_storm, tmp_path, capsys):
    out = tmp_path / "out"
    code, _, err = render(["render", tiny_storm, out / "storm.####.exr", *FAST, "--scheduler", "tcp://127.0.0.1:9",
                           "--scheduler-timeout", "2"], capsys)
    assert code == 2 and "tcp://127.0.0.1:9" in err and "nothing was rendered" in err
    assert not list(out.glob("*.exr"))
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code, _, err = render(["render", tiny_storm, blocker / "sub" / "storm.####.exr", *FAST], capsys)
    assert code == 2 and str(blocker / "sub") in err


def test_existing_scheduler_renders_the_same_pixels(tiny_storm, tmp_path, capsys):
    """--scheduler: a cluster the user runs (here a one-worker LocalCluster started by the test)."""
    from dask.distributed import LocalCluster

    assert render(["render", tiny_storm, tmp_path / "a" / "storm.####.exr", *FAST, "--frames", "5:6"], capsys)[0] == 0
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        code, _, err = render(["render", tiny_storm, tmp_path / "b" / "storm.####.exr", *FAST, "--frames", "5:6",
                               "--scheduler", cluster.scheduler_address], capsys)
    assert code == 0, err
    assert f"dask scheduler {cluster.scheduler_address}" in err
    for frame in (5, 6):
        a = pixels(tmp_path / "a" / f"storm.{frame:04d}.exr")
        b = pixels(tmp_path / "b" / f"storm.{frame:04d}.exr")
        for name in a:
            np.testing.assert_array_equal(a[name], b[name])


def test_an_in_process_batch_reads_and_plans_each_frame_once(tiny_storm, tmp_path, capsys, monkeypatch):
    """The storm's 6 frames rendered in this process: the stage is opened once (the command's reader, which lists
    the products and the frames, is the one the batch reads them with) and each frame's scene is read, planned, its
    files stat'ed and its settings hashed once; the first frame's plan, made for the checks before anything is
    written, is the one the batch prepares the tables from and the one it renders."""
    from warpsky.batch import run
    from warpsky.render import planned
    from warpsky.usd.stage import StageReader

    monkeypatch.setattr(run, "_READERS", {})  # no reader kept from an earlier test
    calls = {"open": 0, "scene_at": [], "make_plan": 0, "input_files": 0, "settings_hash": 0}
    opened, scene_at = StageReader.__init__, StageReader.scene_at

    def counted(name, function):
        def call(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)
        return call

    def counted_read(self, time=None, **kwargs):
        calls["scene_at"].append(time)
        return scene_at(self, time, **kwargs)

    monkeypatch.setattr(StageReader, "__init__", counted("open", opened))
    monkeypatch.setattr(StageReader, "scene_at", counted_read)
    for name in ("make_plan", "input_files", "settings_hash"):
        monkeypatch.setattr(planned, name, counted(name, getattr(planned, name)))
    code, _, err = render(["render", tiny_storm, tmp_path / "storm.####.exr", *FAST], capsys)
    assert code == 0 and "6 rendered" in err, err
    frames = [float(f) for f in range(1, FRAMES + 1)]
    assert calls == {"open": 1, "scene_at": frames, "make_plan": FRAMES, "input_files": FRAMES,
                     "settings_hash": FRAMES}
