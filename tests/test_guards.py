"""Resource guards and Ctrl-C: a frame that cannot fit in memory or would never finish is refused (exit 2) before
anything is allocated, and an interrupted render stops within a second or two (exit 130) leaving no file."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import StageSpec, write_stage
from conftest import run_cli as run

from warpsky.cli.main import main
from warpsky.core.device import RowBands
from warpsky.core.resources import MAX_WORK_PER_PIXEL, format_size, parse_size

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def box_stage(tmp_path, homogeneous_npy):
    """A 20 m box of constant density 40 m in front of the camera (4^3 voxels of 5 m)."""
    return write_stage(tmp_path / "box.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))


def files_in(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir()) if directory.exists() else []


# ------------------------------------------------------------------------------------------------------ memory
def test_sizes_parse_and_print():
    assert parse_size("8G") == 8 * 2**30 and parse_size("512M") == 512 * 2**20 and parse_size("1.5GiB") == 3 * 2**29
    assert parse_size("2048") == 2048 and parse_size("64kb") == 64 * 2**10
    for bad in ("", "lots", "-1G", "0"):
        with pytest.raises(ValueError):
            parse_size(bad)
    assert format_size(120.4 * 2**30) == "120 GiB" and format_size(2**20) == "1 MiB" and format_size(12) == "12 B"


def test_huge_frame_is_refused_by_the_estimate_without_allocating(tmp_path, box_stage, capsys, monkeypatch):
    """100000^2 and 20000^2 exit 2 naming the estimate, the limit and --max-memory; no buffer of more than 1e8
    elements is ever asked for (every array constructor of numpy and Warp is watched) and nothing is written."""
    import warp as wp

    asked = []

    def watch(module, name):
        original = getattr(module, name)

        def guarded(shape, *args, **kwargs):
            elements = int(np.prod(shape)) if not hasattr(shape, "size") else int(np.size(shape))
            if elements > 1e8:
                asked.append((name, shape))
                raise AssertionError(f"{name}{shape}: allocated before the guard")
            return original(shape, *args, **kwargs)

        monkeypatch.setattr(module, name, guarded)

    for module, names in ((np, ("zeros", "empty", "full", "ones")), (wp, ("zeros", "empty", "full"))):
        for name in names:
            watch(module, name)
    for res in ("100000x100000", "20000x20000"):
        out = tmp_path / res / "f.exr"
        code, _, err = run(["render", box_stage, out, "--res", res, "--device", "cpu"], capsys)
        assert code == 2, err
        assert "needs about" in err and "GiB" in err and "--max-memory" in err and "available" in err
        assert len(err.strip().splitlines()) == 1
        assert files_in(out.parent) == []
    assert asked == []


def test_huge_frame_is_refused_with_a_small_peak_memory(tmp_path, box_stage):
    """The process refusing 100000^2 never grows far beyond its imports. The child reports its own peak resident
    set (VmHWM, which starts afresh at exec; rusage's ru_maxrss would count the pytest process it forked from)."""
    out = tmp_path / "o" / "f.exr"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    argv = ["render", str(box_stage), str(out), "--res", "100000x100000", "--device", "cpu"]
    child = ("import sys\nfrom warpsky.cli.main import main\ncode = main(sys.argv[1:])\n"
             "print(next(line for line in open('/proc/self/status') if line.startswith('VmHWM')))\nsys.exit(code)")
    proc = subprocess.run([sys.executable, "-c", child, *argv], capture_output=True, text=True, env=env, cwd=REPO)
    assert proc.returncode == 2, proc.stderr
    peak_kib = int(proc.stdout.split()[1])
    assert peak_kib * 1024 < 2 * 2**30, proc.stdout  # imports take about 0.3 GiB
    assert "TiB of host memory" in proc.stderr and not out.exists()


def test_max_memory_refuses_a_small_frame_and_the_default_renders_it(tmp_path, box_stage, capsys):
    out = tmp_path / "o" / "f.exr"
    args = ["render", box_stage, out, "--res", "16x12", "--device", "cpu", "--technique", "single_scatter"]
    code, _, err = run([*args, "--max-memory", "1M"], capsys)
    assert code == 2 and "1 MiB set by --max-memory" in err and "--max-memory SIZE" in err
    assert files_in(out.parent) == []
    code, _, err = run(args, capsys)
    assert code == 0 and out.is_file(), err
    code, _, err = run([*args, "--max-memory", "4G", "--overwrite"], capsys)
    assert code == 0, err


def test_bad_max_memory_is_a_usage_error(tmp_path, box_stage, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["render", str(box_stage), str(tmp_path / "f.exr"), "--max-memory", "lots"])
    assert exc.value.code == 2 and "8G" in capsys.readouterr().err


def test_info_prints_the_estimates_and_the_limits(box_stage, capsys):
    code, stdout, _ = run(["info", box_stage, "--device", "cpu", "--res", "100000x100000"], capsys)
    assert code == 0
    assert "memory      about" in stdout and "REFUSED" in stdout and "available" in stdout
    code, stdout, _ = run(["info", box_stage, "--device", "cpu", "--max-memory", "64G"], capsys)
    assert code == 0 and "64 GiB set by --max-memory: fits" in stdout and "work        about" in stdout


def test_every_technique_estimates_memory_that_grows_with_the_frame(box_stage):
    from warpsky.render.plan import make_plan
    from warpsky.render.registry import technique_names
    from warpsky.usd.stage import StageReader

    scene = StageReader(box_stage).scene_at(None)
    for name in technique_names():
        small = make_plan(scene, technique=name, resolution=(100, 100))
        large = make_plan(scene, technique=name, resolution=(1000, 1000))
        per_pixel = (large.memory.host_total("cpu") - small.memory.host_total("cpu")) / (1000**2 - 100**2)
        assert 100 < per_pixel < 2000, (name, per_pixel)  # bytes per pixel: images, sums, copies, EXR
        assert small.memory.parts["grids"][1] >= 4 * 4**3, name
        assert small.work.items and all(item.per_pixel > 0 for item in small.work.items), name


# -------------------------------------------------------------------------------------------------------- work
def test_tiny_step_is_refused_naming_the_setting_and_the_way_past(tmp_path, box_stage, capsys):
    out = tmp_path / "o" / "f.exr"
    code, _, err = run(["render", box_stage, out, "--res", "16x12", "--device", "cpu", "--technique",
                        "single_scatter", "--set", "step_length=1e-6"], capsys)
    assert code == 2 and "step_length=1e-06 m" in err and "per pixel" in err and "--no-work-limit" in err
    assert files_in(out.parent) == []
    code, _, err = run(["render", box_stage, out, "--res", "16x12", "--device", "cpu", "--technique",
                        "path_tracer", "--spp", "1000000000"], capsys)
    assert code == 2 and "spp=1000000000 x max_bounces=1024" in err


def test_huge_frame_work_is_refused_and_no_work_limit_plans_it(box_stage):
    from warpsky.core.errors import ResourceError
    from warpsky.render.options import RenderOptions
    from warpsky.render.planned import plan_frame
    from warpsky.usd.stage import StageReader

    reader = StageReader(box_stage)
    options = RenderOptions(technique="path_tracer", settings={"spp": "60000"}, resolution=(2000, 2000),
                            max_memory=2**40)
    with pytest.raises(ResourceError, match="kernel iterations .* more than the limit of 1e"):
        plan_frame(reader, None, options)
    options.work_limit = False
    _, plan = plan_frame(reader, None, options)
    assert plan.work.total > 1e13 and max(item.per_pixel for item in plan.work.items) < MAX_WORK_PER_PIXEL


# ------------------------------------------------------------------------------------------------------ Ctrl-C
def test_row_bands_are_sized_by_time_and_stop_on_request():
    bands = RowBands(1000, 2)
    assert bands.take() == (0, 1)  # a probe first
    bands.record(1, 0.001)
    first, rows = bands.take()
    assert (first, rows) == (1, 4)  # grows at most fourfold
    bands.record(4, 0.004)
    assert bands.take()[1] == 16
    bands.record(16, 1.6)  # costly rows (0.1 s each): the estimate follows the slowest
    assert bands.take()[1] == 1
    from warpsky.core.interrupt import clear_stop, request_stop

    request_stop("batch-a")
    assert RowBands(10, 1, stop_token="batch-b").take() is not None
    assert RowBands(10, 1, stop_token="batch-a").take() is None
    request_stop()
    try:
        assert RowBands(10, 1).take() is None
    finally:
        clear_stop()


class Render:
    """``warpsky render`` in a subprocess of its own session, its stderr collected as it comes."""

    def __init__(self, args: list, cwd: Path):
        env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen([sys.executable, "-m", "warpsky", "render", *map(str, args)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=cwd,
                                     start_new_session=True)
        self.err = b""
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        while chunk := self.proc.stderr.read1(4096):
            self.err += chunk

    def wait_for(self, condition, timeout: float = 120.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            assert self.proc.poll() is None, f"render ended early: {self.err.decode()}"
            assert time.monotonic() < deadline, f"render did not start: {self.err.decode()}"
            time.sleep(0.05)

    def interrupt(self, *, within: float) -> tuple[int, float, str]:
        """Ctrl-C as a terminal sends it (to the whole process group); (exit code, seconds to exit, stderr)."""
        sent = time.monotonic()
        os.killpg(self.proc.pid, signal.SIGINT)
        try:
            code = self.proc.wait(timeout=within)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
            pytest.fail(f"still running {within} s after SIGINT: {self.err.decode()}")
        seconds = time.monotonic() - sent
        self.reader.join(5)
        return code, seconds, self.err.decode()


def test_ctrl_c_stops_a_long_single_launch_within_two_seconds(tmp_path, box_stage):
    """A single-scattering march of about a minute (rows of half a second) stops at once: exit 130, one line, no
    EXR and no temporary file."""
    out_dir = tmp_path / "o"
    render = Render([box_stage, out_dir / "f.exr", "--res", "96", "--device", "cpu", "--technique", "single_scatter",
                     "--set", "step_length=0.0005"], tmp_path)
    render.wait_for(out_dir.exists)  # made after the plan: the handler is in place, the render about to start
    time.sleep(2.0)
    code, seconds, err = render.interrupt(within=2.0)
    assert code == 130, err
    assert err.strip() == "warpsky: interrupted"
    assert not out_dir.exists()  # nor the directory the run made
    print(f"exited {seconds:.2f} s after SIGINT")


def test_ctrl_c_stops_path_tracer_passes(tmp_path, box_stage):
    out_dir = tmp_path / "o"
    render = Render([box_stage, out_dir / "f.exr", "--res", "64", "--device", "cpu", "--technique", "path_tracer",
                     "--spp", "50000"], tmp_path)
    render.wait_for(out_dir.exists)
    time.sleep(2.0)
    code, _, err = render.interrupt(within=2.0)
    assert code == 130 and "Traceback" not in err and files_in(out_dir) == []


@pytest.mark.slow
def test_ctrl_c_under_workers_shuts_the_cluster_down_quietly(tmp_path, box_stage):
    """Under a LocalCluster (about 12 s with its start on two busy cores) the workers ignore the terminal's
    SIGINT; the client stops the batch's frames on them, closes the cluster and exits 130 without Dask noise."""
    out_dir = tmp_path / "o"
    render = Render([box_stage, out_dir / "f.####.exr", "--frames", "1:2", "--res", "64", "--device", "cpu",
                     "--technique", "path_tracer", "--spp", "50000", "--workers", "1"], tmp_path)
    render.wait_for(lambda: b"frames to render" in render.err)  # the cluster is up, frames submitted
    time.sleep(3.0)
    code, seconds, err = render.interrupt(within=30.0)
    assert code == 130, err
    assert "Traceback" not in err and "distributed" not in err and err.rstrip().endswith("warpsky: interrupted")
    assert [name for name in files_in(out_dir) if name.endswith(".exr") or "tmp" in name] == []
    print(f"exited {seconds:.2f} s after SIGINT")


def test_first_stumbles_get_one_line_and_leave_nothing(tmp_path, box_stage, capsys, monkeypatch):
    """A bad flag is one line (the reason, then where --help is), not a usage block; an output under a regular file
    names that file; a run stopped before its first frame leaves no directory it made."""
    for flags, named in ((["--res", "abc"], "--res"), (["--technique", "nonsense"], "nonsense")):
        with pytest.raises(SystemExit) as stop:  # argparse exits itself
            main(["render", str(box_stage), str(tmp_path / "o.exr"), *flags])
        err = capsys.readouterr().err
        assert stop.value.code == 2 and len(err.strip().splitlines()) == 1 and named in err and "--help" in err
    blocker = tmp_path / "blocker"
    blocker.write_text("a file")
    code, _, err = run(["render", box_stage, blocker / "sub" / "o.exr", "--res", "8", "--technique", "single_scatter"],
                       capsys)
    assert code == 2 and f"{blocker} is a file, not a directory" in err

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("warpsky.batch.run.run_batch", stopped)
    out = tmp_path / "new" / "deeper" / "o.exr"
    code, _, err = run(["render", box_stage, out, "--res", "8", "--technique", "single_scatter"], capsys)
    assert code == 130 and not (tmp_path / "new").exists()
