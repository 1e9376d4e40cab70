"""Frame sequences on one machine or a Dask cluster: resume, retries, a per-shot JSON log and a summary.

A batch is a list of :class:`FrameJob`. Workers (this process, a Dask ``LocalCluster`` or an existing Dask
scheduler) run :func:`run_frame` on each: open the stage themselves, plan the frame once (in this process the
first frame's plan, made for the up-front checks by :func:`plan_first_frame`, is the one it renders), skip it when
its EXR already exists and validates (opens, has every channel, carries the same settings hash, which covers the
settings and the stage's and field files' size and modification time), else render and write it atomically. They
return a small record (path, seconds, device, hash, error), never pixels. The client retries failed frames whose
error was not the input's (``retries`` times; a missing file fails the same way again), appends one run to the
shot's log after every frame (so a killed batch keeps what it finished), and prints a summary table.

Test hook: the environment variable ``WARPSKY_FAIL_FRAMES`` (comma-separated time codes, each optionally ``@N`` for
"only on attempt N") makes those frames raise before rendering, to exercise failure, retry and resume; it is read
by the worker, so it reaches Dask workers started after it is set.
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from warpsky.batch.frames import PLACEHOLDER, PlainLines
from warpsky.core.device import init_warp
from warpsky.core.errors import UsageError, WarpskyError
from warpsky.core.files import atomic_write
from warpsky.core.interrupt import Interrupted, request_stop, sigint_ignored, stop_requested, stop_scope
from warpsky.output.exr import validate_exr
from warpsky.render.frame import write_frame
from warpsky.render.planned import PlannedFrame, planned_frame
from warpsky.usd.stage import StageReader

FAIL_FRAMES_ENV = "WARPSKY_FAIL_FRAMES"


@dataclass(frozen=True)
class FrameJob:
    """One frame to render: everything a worker needs, picklable, no pixels."""

    stage: str
    time_code: float | None
    out: str
    options: object  # warpsky.render.options.RenderOptions
    overwrite: bool = False
    siblings: tuple = ()  # (out, RenderOptions) of products with the same camera and resolution: one render


@dataclass
class FrameRecord:
    """What a worker reports for one frame (one JSON object in the shot's log)."""

    frame: float | None
    path: str
    status: str  # "done", "skipped" or "failed"
    seconds: float = 0.0
    device: str = ""
    settings_hash: str = ""
    worker: str = ""
    attempt: int = 1
    error: str | None = None
    png: str | None = None  # the preview written beside the EXR, if asked for
    also: list = field(default_factory=list)  # sibling products written from the same render
    retryable: bool = False  # errors in the input (a missing file, a bad attribute) fail the same way again
    timings: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)  # Monte Carlo figures: spp, passes, error estimate, capped paths
    warnings: list = field(default_factory=list)  # one line each, printed by the client as the frame finishes


_READERS: dict[tuple, object] = {}


def _reader_key(stage: str, options) -> tuple:
    return str(Path(stage).resolve()), Path(stage).stat().st_mtime if Path(stage).exists() else 0.0, options


def share_reader(stage: str, options, reader) -> None:
    """Let this process's batch read ``stage`` with ``reader``, which the caller opened with the composition
    ``options`` (the jobs' ``options.stage``), instead of opening the stage again."""
    _READERS.clear()
    _READERS[_reader_key(stage, options)] = reader


def _reader(stage: str, options=None):
    """The stage opened once per worker process with its composition ``options`` (reopened when the file or the
    options change)."""
    key = _reader_key(stage, options)
    if key not in _READERS:
        _READERS.clear()
        _READERS[key] = StageReader(stage) if options is None else StageReader(stage, options)
    return _READERS[key]


@dataclass(frozen=True)
class PlannedJob:
    """A job's frame planned in this process: the job, the reader that read it, the frame and its siblings'
    (:meth:`~warpsky.render.planned.PlannedFrame.for_options`), each planned once."""

    job: FrameJob
    reader: object
    frame: PlannedFrame
    siblings: tuple[PlannedFrame, ...]


#: Frames planned before their batch runs (:func:`plan_first_frame`), by (stage, time code, output): the batch's
#: up-front work and the frame's render take the plan from here instead of making it again.
_PLANNED: dict[tuple, PlannedJob] = {}


def _job_key(job: FrameJob) -> tuple:
    return job.stage, job.time_code, job.out


def plan_job(job: FrameJob, *, keep: bool = False) -> PlannedJob:
    """``job``'s frame planned once in this process: the plan kept for it (by :func:`plan_first_frame`, for the same
    job read by the same reader) when there is one, else planned now (stage read, plan, outputs and limits checked,
    files stat'ed and settings hashed) and, with ``keep``, kept for the frame's render."""
    reader = _reader(job.stage, job.options.stage)
    kept = _PLANNED.get(_job_key(job))
    if kept is not None and kept.job == job and kept.reader is reader:
        return kept
    frame = planned_frame(reader, job.time_code, job.options)
    planned = PlannedJob(job, reader, frame, tuple(frame.for_options(options) for _, options in job.siblings))
    if keep:
        _PLANNED[_job_key(job)] = planned
    return planned


def plan_first_frame(job: FrameJob, *, keep_reader: bool = True) -> None:
    """Read the stage and plan ``job``'s frame here, before anything is written: an input error that every frame
    shares (no camera, a bad setting) is raised once, as a :class:`WarpskyError`, and leaves no output directory
    and no log behind. ``keep_reader``: keep the stage read, and the plan, for frames rendered in this process
    (the batch's preparation and the frame's render reuse it)."""
    _PLANNED.pop(_job_key(job), None)
    plan_job(job, keep=keep_reader)
    if not keep_reader:
        _READERS.clear()


def _hook_fails(time_code: float | None, attempt: int) -> bool:
    """Whether the ``WARPSKY_FAIL_FRAMES`` test hook asks this frame's attempt to fail."""
    if time_code is None:
        return False
    for item in os.environ.get(FAIL_FRAMES_ENV, "").split(","):
        frame, _, only = item.strip().partition("@")
        if frame and float(frame) == float(time_code) and (not only or int(only) == attempt):
            return True
    return False


def run_frame(job: FrameJob, attempt: int = 1) -> FrameRecord:
    """Render (or skip) one frame; every error becomes a failed record naming what went wrong.

    The stage is read and the frame planned once: the plan's settings hash decides the skip and goes into the
    EXR's metadata."""
    init_warp()
    started = time.perf_counter()
    record = FrameRecord(job.time_code, job.out, "failed", device=job.options.device,
                         worker=f"{socket.gethostname()}:{os.getpid()}", attempt=attempt)
    try:
        t0 = time.perf_counter()
        planned = plan_job(job)
        _PLANNED.pop(_job_key(job), None)  # rendered once: a later batch plans the frame again
        frame = planned.frame
        record.timings["stage_load"] = time.perf_counter() - t0
        record.settings_hash = frame.settings_hash
        record.also = [out for out, _ in job.siblings]
        if not job.overwrite and _up_to_date(job, planned):
            record.status = "skipped"
            return record
        if _hook_fails(job.time_code, attempt):
            raise RuntimeError(f"{FAIL_FRAMES_ENV} asks frame {job.time_code:g} to fail (test hook)")
        siblings = [(Path(out), sibling) for (out, _), sibling in zip(job.siblings, planned.siblings, strict=True)]
        result = write_frame(frame, Path(job.out), siblings=siblings, reader=planned.reader, started=t0)
        record.timings.update(result.timings)
        record.timings["technique"] = result.render_seconds
        record.quality = result.quality
        record.warnings = result.warnings
        record.png = str(result.png) if result.png is not None else None
        record.status = "done"
    except WarpskyError as exc:
        record.error = f"{type(exc).__name__}: {exc}"
    except Interrupted:  # the batch is being stopped: nothing to report or retry
        raise
    except Exception as exc:  # a worker must report, not die: the client decides about retries
        record.error = f"{type(exc).__name__}: {exc}"
        record.retryable = True
    finally:
        record.seconds = time.perf_counter() - started
    return record


def _up_to_date(job: FrameJob, planned: PlannedJob) -> bool:
    """Whether the job's EXR and its siblings' exist, open, hold their channels and carry their settings hash (and
    the deep EXR beside the job's exists, when it is asked for; a deep product's own file carries the hash)."""
    from warpsky.output.deep import deep_path, deep_up_to_date

    frame = planned.frame
    if job.options.deep_product:
        return deep_up_to_date(job.out, frame.settings_hash)
    if job.options.deep and not Path(deep_path(job.out)).is_file():
        return False
    outputs = [(job.out, frame)]
    outputs += [(out, sibling) for (out, _), sibling in zip(job.siblings, planned.siblings, strict=True)]
    return all(validate_exr(out, required_channels=sibling.options.required_channels,
                            metadata_expect={"settingsHash": sibling.settings_hash}) for out, sibling in outputs)


def run_frame_in_scope(job: FrameJob, attempt: int, stop_token: str) -> FrameRecord:
    """:func:`run_frame` that stops when its batch's client calls ``request_stop(stop_token)`` on the worker."""
    with stop_scope(stop_token):
        return run_frame(job, attempt)


# ------------------------------------------------------------------------------------------------ executors
class InProcessExecutor:
    """Frames one after another in this process (the default)."""

    name = "in-process"

    def map(self, jobs: list[FrameJob], attempt: int):
        for job in jobs:
            yield job, run_frame(job, attempt)

    def close(self) -> None:
        pass


class DaskExecutor:
    """Frames as Dask futures: a ``LocalCluster`` of ``workers`` single-threaded processes, or an existing
    scheduler at ``address``. Workers load the stage and the optics cache themselves (shared storage).

    Ctrl-C reaches only this process (the LocalCluster's workers ignore SIGINT); :meth:`close` after it stops this
    batch's frames on every worker (``request_stop`` of the batch's token), cancels the rest and shuts down
    quietly."""

    def __init__(self, *, workers: int | None = None, address: str | None = None, timeout: float = 10.0):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise UsageError("--workers/--scheduler need Dask distributed: pip install 'warpsky[farm]'") from None
        self.cluster = None
        self.stop_token = uuid.uuid4().hex
        self.futures: list = []
        if address is not None:
            self.name = f"dask scheduler {address}"
            try:
                self.client = Client(address, timeout=f"{timeout}s")
            except (OSError, TimeoutError) as exc:
                raise UsageError(f"--scheduler {address}: cannot reach a Dask scheduler within {timeout:g} s "
                                 f"({type(exc).__name__}: {exc}); nothing was rendered") from None
        else:
            import logging

            # the cores shared out: each worker's CPU launches use its share (pixels do not depend on it)
            threads = max(1, (os.cpu_count() or 1) // workers)
            self.name = f"dask LocalCluster, {workers} worker process(es) x {threads} CPU thread(s)"
            # SIGINT ignored while the workers start, which inherit it (a Ctrl-C in these seconds is lost); the
            # HTTP server on a free port, so that another cluster on 8787 prints no warning
            with sigint_ignored():
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=":0", silence_logs=logging.ERROR,
                                            env={"WARPSKY_CPU_THREADS": str(threads)})
                self.client = Client(self.cluster)

    def map(self, jobs: list[FrameJob], attempt: int):
        from dask.distributed import as_completed

        futures = {self.client.submit(run_frame_in_scope, job, attempt, self.stop_token, pure=False): job
                   for job in jobs}
        self.futures += list(futures)
        for future in as_completed(futures):
            job = futures[future]
            try:
                record = future.result()
            except Exception as exc:  # the worker process died (killed, out of memory)
                record = FrameRecord(job.time_code, job.out, "failed", device=job.options.device, attempt=attempt,
                                     error=f"worker lost: {type(exc).__name__}: {exc}", retryable=True)
            yield job, record

    def close(self) -> None:
        if stop_requested():
            with sigint_ignored():
                self._close_interrupted()
            return
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def _close_interrupted(self) -> None:
        """Stop this batch's frames where they run, cancel the others and shut down without Dask's log noise (the
        cluster's teardown errors on the tasks it cuts short)."""
        import logging

        for name in ("distributed", "tornado", "asyncio"):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        try:
            self.client.run(request_stop, self.stop_token, on_error="ignore")
            self.client.cancel(self.futures, force=True)
            self.client.close(timeout=5)
            if self.cluster is not None:
                self.cluster.close(timeout=10)
        except Exception:  # noqa: BLE001 - already stopping: a cluster that does not answer is left to its timeouts
            pass


# --------------------------------------------------------------------------------------------------- batch
@dataclass
class BatchResult:
    records: list[FrameRecord]
    seconds: float
    executor: str
    log: Path

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.records)

    @property
    def failed(self) -> list[FrameRecord]:
        return [r for r in self.records if r.status == "failed"]


def log_path_for(pattern: str) -> Path:
    """``out/storm.####.exr`` -> ``out/storm.log.json``: one log per shot, next to its frames; with the frame in a
    directory name, next to those directories: ``out/shot_####/beauty.exr`` -> ``out/shot.log.json``."""
    path = Path(pattern)
    parts = path.parts
    for i, part in enumerate(parts[:-1]):
        if PLACEHOLDER.search(part):
            stem = PLACEHOLDER.sub("", part).strip("._-") or "frames"
            return Path(*parts[:i], f"{stem}.log.json") if i else Path(f"{stem}.log.json")
    stem = PLACEHOLDER.sub("", path.name[: -len(".exr")]).rstrip("._-") or "frames"
    return path.with_name(f"{stem}.log.json")


def check_writable(directory: Path, created: list[Path] | None = None) -> None:
    """The output directory exists (made if needed) and accepts files; else a UsageError naming it. The top-most
    directory it had to make is appended to ``created`` (for :func:`remove_empty`)."""
    for parent in (directory, *directory.parents):
        if parent.exists() and not parent.is_dir():
            raise UsageError(f"output directory {directory} cannot be created: {parent} is a file, not a directory")
    top, probe_dir = None, directory
    while not probe_dir.exists() and probe_dir != probe_dir.parent:
        top, probe_dir = probe_dir, probe_dir.parent
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"output directory {directory} cannot be created: {exc.strerror or exc}") from None
    if top is not None and created is not None:
        created.append(top)
    probe = directory / f".warpsky-write-test-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UsageError(f"output directory {directory} does not accept files (writing a test file there failed: "
                         f"{exc.strerror or exc})") from None


def remove_empty(directories: list[Path]) -> None:
    """Remove each of ``directories`` (made by this run) with its subdirectories where none holds a file: an
    interrupted or failed run leaves no empty output directory behind."""
    for top in directories:
        if not top.is_dir():
            continue
        for root, _, files in sorted(os.walk(top), key=lambda entry: -len(entry[0])):
            if not files:
                try:
                    os.rmdir(root)
                except OSError:
                    pass


def prepare_batch(jobs: list[FrameJob]) -> None:
    """Plan the first frame here, before any frame is dispatched: build the optics tables it needs, so that workers
    load them from the cache instead of each building them at once. A frame whose input is at fault is left to
    report it when it runs; frames that need other tables still build them themselves. (Kernel compiles say so
    where they happen: :mod:`warpsky.render.compile_progress`; ``warpsky prepare`` does all of it ahead.)"""
    if not jobs or all(Path(job.out).is_file() and not job.overwrite for job in jobs):
        return  # nothing to render unless a finished frame is stale, which then builds what it needs itself
    from warpsky.optics.prepare import prepare_tables

    try:
        frame = plan_job(jobs[0]).frame  # the frame planned for the up-front checks, else planned here
    except (WarpskyError, OSError):
        return
    prepare_tables(frame.scene, frame.plan)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def run_batch(stage: str, jobs: list[FrameJob], executor, *, retries: int = 0, log: Path) -> BatchResult:
    """Run ``jobs`` on ``executor``, retrying failures; append this run to ``log`` after every frame."""
    started = time.perf_counter()
    prepare_batch(jobs)
    run = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "stage": str(Path(stage).resolve()),
           "executor": executor.name, "argv": sys.argv[1:], "frames": []}
    history = _read_log(log)
    final: dict[int, FrameRecord] = {}
    pending = list(enumerate(jobs))
    # a bar redraws with carriage returns: only on a terminal (a log or a pipe gets the plain per-frame lines)
    terminal = _is_terminal(sys.stderr)
    if len(jobs) > 1 and terminal:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="frame", file=sys.stderr, dynamic_ncols=True)
    else:
        bar = PlainLines()
    if len(jobs) > 1 and not terminal:
        print(f"warpsky: {len(jobs)} frames to render ({executor.name}); each frame's path follows when written",
              file=sys.stderr, flush=True)
    for attempt in range(1, retries + 2):
        index_of = {id(job): i for i, job in pending}
        retry = []
        for job, record in executor.map([job for _, job in pending], attempt):
            i = index_of[id(job)]
            run["frames"].append(dataclasses.asdict(record))
            _write_log(log, history, run)
            label = "" if job.time_code is None else f" {job.time_code:g}"
            for warning in record.warnings:
                bar.write(f"warpsky: {f'frame{label}: ' if label else ''}warning: {warning}", file=sys.stderr)
            if record.status == "failed":
                will_retry = attempt <= retries and record.retryable
                bar.write(f"warpsky: frame{label}: error: {record.error}"
                          + (f" (retrying, attempt {attempt + 1} of {retries + 1})" if will_retry else ""),
                          file=sys.stderr)
                if will_retry:
                    retry.append((i, job))
                    continue
            elif record.status == "skipped":
                bar.write(f"{record.path} (up to date, skipped)")
            else:
                bar.write(record.path)
                for path in record.also:
                    bar.write(path)
                if record.png:
                    bar.write(record.png)
            final[i] = record
            bar.update(1)
        pending = retry
        if not pending:
            break
    bar.close()
    records = [final[i] for i in sorted(final)]
    run["summary"] = summary_dict(records, time.perf_counter() - started)
    _write_log(log, history, run)
    return BatchResult(records, time.perf_counter() - started, executor.name, log)


def summary_dict(records: list[FrameRecord], seconds: float) -> dict:
    rendered = [r for r in records if r.status == "done"]
    return {
        "frames": len(records), "done": len(rendered), "skipped": sum(r.status == "skipped" for r in records),
        "failed": sum(r.status == "failed" for r in records), "seconds": seconds,
        "seconds_per_rendered_frame": (sum(r.seconds for r in rendered) / len(rendered)) if rendered else 0.0,
    }


def format_summary(result: BatchResult) -> str:
    s = summary_dict(result.records, result.seconds)
    lines = [
        f"{'frames':<9} {s['frames']} asked: {s['done']} rendered, {s['skipped']} skipped (up to date), "
        f"{s['failed']} failed",
        f"{'time':<9} {s['seconds']:.1f} s in all, {s['seconds_per_rendered_frame']:.2f} s per rendered frame "
        f"({result.executor})",
        f"{'log':<9} {result.log}",
    ]
    for record in result.failed:
        label = "default time" if record.frame is None else f"{record.frame:g}"
        lines.append(f"{'failed':<9} frame {label}: {record.error}")
    return "\n".join(lines)


def _read_log(log: Path) -> dict:
    if log.is_file():
        try:
            data = json.loads(log.read_text())
            if isinstance(data, dict) and isinstance(data.get("runs"), list):
                return data
        except (OSError, ValueError):
            pass  # an unreadable log is replaced, never fatal
    return {"runs": []}


def _write_log(log: Path, history: dict, run: dict) -> None:
    data = {"runs": history["runs"] + [run]}
    atomic_write(log, lambda tmp: Path(tmp).write_text(json.dumps(data, indent=1, default=str)))
