"""What a frame will cost, estimated from its plan before anything is allocated or launched, and the guards that refuse
a frame that cannot fit or would never finish.

Memory: the estimate is the peak resident size of the process that renders the frame. It holds, before the frame,
what the process already holds (:data:`PROCESS_BYTES`: Python, NumPy, Warp, USD and the opened stage) and what
reading the stage's data cost (:func:`warpsky.render.memory.stage_memory`); every technique and pass then estimates
its own buffers (``memory_estimate``: per-pixel images and accumulators, uploaded grids, light buffers, denoiser
copies, the sky's and the layers' images, the tables it builds); the plan (:func:`warpsky.render.plan.frame_memory`)
adds them up with the composite and the EXR's copies. ``evaluation/benchmarks/bench_memory.py`` measures it
against the peak resident size of ``warpsky render`` on every shipped stage. The guards compare the frame's own
part (the estimate less what the process holds before it, :meth:`MemoryEstimate.frame_host`) with what is free: on
the host ``MemAvailable`` of ``/proc/meminfo`` (within the cgroup's limit, if any), on a CUDA device its free
memory; ``--max-memory SIZE`` replaces both. On the CPU device, device arrays are host memory and count there.

Work: every technique estimates the inner-loop iterations of its kernels (``work_estimate``: grid lookups of the
single-scattering march, slices, paths x bounce cap), as worst cases from the settings and the media's extent. A
frame is refused when one pixel would take more than :data:`MAX_WORK_PER_PIXEL` (a tiny ``step_length``) or the
frame more than :data:`MAX_WORK_PER_FRAME` in all (a huge resolution or ``spp``); ``--no-work-limit`` renders it
anyway. On two CPU cores about 2.5e7 lookups run per second and the worst case overstates the demo cumulus' real
lookups about 140 times, so the frame bound is about an hour of CPU rendering.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

from warpsky.core.device import is_cpu
from warpsky.core.errors import ResourceError

#: Most worst-case kernel iterations (grid lookups, path events) one pixel may take.
MAX_WORK_PER_PIXEL = 1.0e8
#: Most worst-case kernel iterations a frame may take in all.
MAX_WORK_PER_FRAME = 1.0e13
#: Resident size of a ``warpsky render`` process when it has opened its stage, before it reads the stage's data:
#: Python with NumPy, Warp (initialised on the CPU) and USD imported, warpsky's modules and the USD stage opened.
#: Measured as VmRSS after ``StageReader`` on every shipped stage (Warp 1.19, USD 0.26, CPU only, this project's
#: 2-core x86_64 machine): 285 MiB (289 MiB where the stage references the terrain mesh). A CUDA context adds its
#: own host memory, not measured here.
PROCESS_BYTES = 285 * 2**20
#: Memory a frame's render adds besides the parts the passes estimate: Warp's kernel modules loaded, the air's and
#: sky's tables, NumPy temporaries. Measured as the render's peak resident growth less the estimated parts at
#: 96x64: stratocumulus 11 MiB, the storm 18 MiB.
WORKING_MEMORY = 16 * 2**20

#: Bytes per pixel of the image buffers every frame keeps on the host: the composite (radiance, transmittance,
#: depth, RGBA and its temporaries, 72 B) and the EXR's channel copies (RGBA as float32 and 3 transmittance
#: channels, 32 B). Measured on the demo cumulus at 1536x1024 on the CPU (peak RSS growth over the render, the
#: estimate without the working memory): single_scatter 214 / 305 MiB, path_tracer 344 / 571 MiB, slicing
#: 223 / 450 MiB, hybrid 1302 / 1668 MiB.
COMPOSITE_BYTES = 72 + 32
#: Bytes per pixel of an AOV (RGB float32) through the composite and the EXR (techniques add their AOVs).
AOV_BYTES = 3 * 12
#: Bytes per pixel of one ImageLayer on the host (radiance and transmittance RGB, depth, float32).
LAYER_BYTES = 28


# ------------------------------------------------------------------------------------------------- sizes
_UNITS = {"": 1, "b": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


def parse_size(text: str) -> int:
    """``8G``, ``512M``, ``1.5GiB``, ``2048`` (bytes) -> bytes (binary units; a trailing B or iB is optional)."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)(i?b)?\s*", str(text).lower())
    if match is None or float(match.group(1)) <= 0.0:
        raise ValueError(f"expected a size such as 8G, 512M or 1.5GiB, got {text!r}")
    return int(float(match.group(1)) * _UNITS[match.group(2)])


def format_size(size: float) -> str:
    """Bytes as a short binary size: ``120.4 GiB``, ``512 MiB``, ``96 KiB``."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if size >= scale:
            value = size / scale
            return f"{value:.3g} {unit}" if value < 1000 else f"{value:.0f} {unit}"
    return f"{int(size)} B"


def available_host_memory() -> int:
    """Bytes the host can still give: ``MemAvailable`` (else free pages), within a cgroup v2 limit if set."""
    free = None
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    free = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if free is None:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        limit = open("/sys/fs/cgroup/memory.max").read().strip()
        used = int(open("/sys/fs/cgroup/memory.current").read().strip())
        if limit != "max":
            free = min(free, max(int(limit) - used, 0))
    except (OSError, ValueError):
        pass
    return int(free)


def available_device_memory(device: str) -> int | None:
    """Free bytes on a CUDA device; None for the CPU (its arrays are host memory)."""
    if is_cpu(device):
        return None
    import warp as wp

    return int(wp.get_device(device).free_memory)


# ---------------------------------------------------------------------------------------------- estimates
@dataclass
class MemoryEstimate:
    """Bytes a frame's process holds at its peak, by part: ``parts[name] = (host bytes, device bytes)``. On the CPU
    device the device bytes are host memory too (see :meth:`host_total`). The parts named in ``held`` (host
    memory only) are what the process holds before the frame allocates anything: the interpreter and its
    libraries, the stage and its data."""

    parts: dict[str, tuple[int, int]] = field(default_factory=dict)
    held: set[str] = field(default_factory=set)

    def add(self, name: str, host: float = 0, device: float = 0, *, held: bool = False) -> MemoryEstimate:
        old = self.parts.get(name, (0, 0))
        self.parts[name] = (old[0] + int(host), old[1] + int(device))
        if held:
            self.held.add(name)
        return self

    def merge(self, other: MemoryEstimate) -> MemoryEstimate:
        for name, (host, device) in other.parts.items():
            self.add(name, host, device, held=name in other.held)
        return self

    @property
    def host(self) -> int:
        return sum(h for h, _ in self.parts.values())

    @property
    def device(self) -> int:
        return sum(d for _, d in self.parts.values())

    @property
    def held_host(self) -> int:
        """Host bytes the process holds before the frame (the ``held`` parts)."""
        return sum(self.parts[name][0] for name in self.held)

    def host_total(self, device: str) -> int:
        """Host bytes, with the device's when the device is the CPU: the process's whole peak."""
        return self.host + (self.device if is_cpu(device) else 0)

    def frame_host(self, device: str) -> int:
        """Host bytes the frame adds to what the process holds before it (:meth:`host_total` less ``held``)."""
        return self.host_total(device) - self.held_host

    def largest_parts(self, count: int = 4, *, held: bool = True) -> str:
        """The ``count`` largest parts with their sizes (host and device together); ``held=False`` leaves out
        what the process holds before the frame."""
        parts = [kv for kv in self.parts.items() if held or kv[0] not in self.held]
        biggest = sorted(parts, key=lambda kv: -(kv[1][0] + kv[1][1]))[:count]
        return ", ".join(f"{name} {format_size(h + d)}" for name, (h, d) in biggest)

    def describe(self, device: str) -> str:
        before = f"{format_size(self.held_host)} held before the frame"
        if is_cpu(device):
            return (f"about {format_size(self.host_total(device))} at the peak ({before}; "
                    f"{self.largest_parts(held=False)})")
        return (f"about {format_size(self.host)} host ({before}) + {format_size(self.device)} on {device} "
                f"({self.largest_parts(held=False)})")


@dataclass(frozen=True)
class WorkItem:
    """One kind of kernel work: ``per_pixel`` worst-case iterations over ``pixels`` pixels (or texels), and the
    settings that set it (named in the refusal)."""

    name: str
    per_pixel: float
    pixels: int
    settings: str

    @property
    def total(self) -> float:
        return self.per_pixel * self.pixels


@dataclass
class WorkEstimate:
    items: list[WorkItem] = field(default_factory=list)

    @property
    def total(self) -> float:
        return sum(item.total for item in self.items)

    def describe(self) -> str:
        parts = [f"{item.name} {item.per_pixel:.3g}/pixel" for item in self.items]
        return f"about {self.total:.3g} kernel iterations" + (f" ({', '.join(parts)})" if parts else "")


# -------------------------------------------------------------------------------------------------- guards
def memory_limits(device: str, max_memory: int | None) -> tuple[int, int | None]:
    """(host limit, device limit or None on the CPU) [bytes]: ``max_memory`` for both, else what is free."""
    if max_memory is not None:
        return int(max_memory), None if is_cpu(device) else int(max_memory)
    return available_host_memory(), available_device_memory(device)


def check_memory(plan, max_memory: int | None = None) -> None:
    """Raise :class:`ResourceError` when the plan's memory estimate exceeds the host's or the device's limit."""
    estimate = plan.memory
    host_limit, device_limit = memory_limits(plan.device, max_memory)
    source = "set by --max-memory" if max_memory is not None else "available"
    what = f"{plan.width}x{plan.height} with {plan.technique}"
    advice = "lower --res or raise the limit with --max-memory SIZE (e.g. --max-memory 16G)"
    need = estimate.frame_host(plan.device)
    if need > host_limit:
        raise ResourceError(f"the frame ({what}) needs about {format_size(need)} of host memory "
                            f"({estimate.largest_parts(held=False)}), more than the {format_size(host_limit)} "
                            f"{source}; {advice}")
    if device_limit is not None and estimate.device > device_limit:
        raise ResourceError(f"the frame ({what}) needs about {format_size(estimate.device)} on {plan.device}, more "
                            f"than the {format_size(device_limit)} {source} there; {advice}")


def check_work(plan) -> None:
    """Raise :class:`ResourceError` when one pixel or the whole frame would take more work than the bounds."""
    work = plan.work
    for item in work.items:
        if item.per_pixel > MAX_WORK_PER_PIXEL:
            raise ResourceError(
                f"{plan.technique} would take about {item.per_pixel:.3g} {item.name} per pixel ({item.settings}), "
                f"more than the limit of {MAX_WORK_PER_PIXEL:.0e}; change those settings, or pass --no-work-limit "
                "to render anyway")
    if work.total > MAX_WORK_PER_FRAME:
        items = ", ".join(f"{item.name} {item.per_pixel:.3g}/pixel x {item.pixels:,} ({item.settings})"
                          for item in work.items)
        raise ResourceError(
            f"the frame ({plan.width}x{plan.height} with {plan.technique}) would take about {work.total:.3g} kernel "
            f"iterations ({items}), more than the limit of {MAX_WORK_PER_FRAME:.0e}; lower --res or those settings, "
            "or pass --no-work-limit to render anyway")


def check_resources(plan, *, max_memory: int | None = None, work_limit: bool = True) -> None:
    """The frame's guards, before anything is allocated: memory, then (unless ``work_limit`` is off) work."""
    check_memory(plan, max_memory)
    if work_limit:
        check_work(plan)


def resource_lines(plan, max_memory: int | None = None) -> list[str]:
    """What ``warpsky info`` prints about the frame's cost: the estimates and the limits they are held to."""
    host_limit, device_limit = memory_limits(plan.device, max_memory)
    source = "set by --max-memory" if max_memory is not None else "available"
    fits = plan.memory.frame_host(plan.device) <= host_limit and (
        device_limit is None or plan.memory.device <= device_limit)
    limit = f"{format_size(host_limit)} {source}" + (
        "" if device_limit is None else f", {format_size(device_limit)} on {plan.device}")
    per_pixel = max((item.per_pixel for item in plan.work.items), default=0.0)
    work_fits = per_pixel <= MAX_WORK_PER_PIXEL and plan.work.total <= MAX_WORK_PER_FRAME
    return [
        f"memory      {plan.memory.describe(plan.device)}; limit {limit}: {'fits' if fits else 'REFUSED'}",
        f"work        {plan.work.describe()}; limits {MAX_WORK_PER_PIXEL:.0e}/pixel, {MAX_WORK_PER_FRAME:.0e}/frame: "
        + ("fits" if work_fits else "REFUSED (--no-work-limit renders it anyway)"),
    ]
