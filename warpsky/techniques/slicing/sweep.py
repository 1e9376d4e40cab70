"""One frame's slicing sweep: its buffers kept across frames, its launches replayed as one CUDA graph.

A frame of half-angle slicing is a few hundred small launches (per slice an eye gather and a light step). On a GPU,
issuing them from Python one by one costs more host time than the GPU spends running them, so on CUDA the whole
sweep, the clears of its buffers included, is recorded once with ``wp.ScopedCapture`` and replayed with
``wp.capture_launch`` by the frames after it.

A captured graph holds every kernel argument by value (the structs: media, Ams tables, camera, slice frame, sun;
the plane positions and the light's starting irradiance) and every array by address. The graph is therefore kept
under a key made of exactly those: the structs' bytes (which include the addresses of the arrays inside them), the
work buffers' addresses and shapes, the kernels, the planes. A frame whose key differs (another camera or sun, a
grid whose contents changed and so were uploaded anew, another slice count or resolution) captures again; one
graph per device is kept, and it holds references to everything it reads so no address in it is reused while it
lives. The buffers come from :mod:`warpsky.core.device_buffers` (names ``slicing:*``), so a batch's frames keep the same
addresses and, with the same camera, sun and grids, replay the same graph.

Capture rules followed: nothing is allocated, copied to or from the host, or synchronised inside the capture
(the clears are device memsets and a by-value fill kernel); the kernels' modules are loaded before it starts
(``force_module_load=False``: loading every module Warp knows would compile unrelated techniques).

On the CPU the sweep runs as plain launches, the eye gather in row bands over every core
(:func:`~warpsky.core.device.launch_rows`), exactly as before graphs existed. If a capture raises, the frame runs as
plain launches, one warning line is printed per process, and that device is not captured again in the process.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.interrupt import check_stop
from warpsky.light.skylight import SkyEnvironment
from warpsky.light.sun import Sun
from warpsky.media.voxels.voxel import VoxelMedia
from warpsky.model.camera_rays import PinholeCamera
from warpsky.optics.oriented_phase import OrientedPhases
from warpsky.techniques.slicing.occlusion import SkyShadow
from warpsky.techniques.slicing.slicing_kernels import (
    AmsTables,
    EyeBuffers,
    LightBuffers,
    PlaneRange,
    SliceFrame,
    eye_span_kernel,
)

#: Capture and replay graphs on CUDA; False: plain launches everywhere (benchmarks compare the two).
USE_GRAPHS = True

#: Also capture on the CPU (Warp replays CPU graphs itself). Off in production: a CPU frame's eye gathers run in row
#: bands over every core, which one captured launch per slice would not. Tests turn it on to run the graph path.
CAPTURE_ON_CPU = False

#: How each sweep of this process ran: ``captured`` (recorded, then launched), ``replayed``, ``plain``.
COUNTS = {"captured": 0, "replayed": 0, "plain": 0}

_GRAPHS: dict[str, tuple] = {}  # device -> (key, graph, sweep whose arrays and structs the graph reads)
_CAPTURE_FAILED: set[str] = set()  # devices whose capture raised: plain launches from then on
_WARNED = [False]
#: The failed capture's warning by device, until a frame's layer carries it (:func:`capture_warning`).
_UNREPORTED: dict[str, str] = {}
_LOCKS: dict[str, threading.Lock] = {}
_LOCKS_LOCK = threading.Lock()


def sweep_lock(device) -> threading.Lock:
    """The lock a frame holds from its sweep to its downloads: the ``slicing:*`` buffers are one set per device."""
    name = str(wp.get_device(device))
    with _LOCKS_LOCK:
        return _LOCKS.setdefault(name, threading.Lock())


#: Bytes the light buffer's copies at a chunk's slice planes may take, per device kind: the sweep runs in as few
#: chunks as fit (a 256^2 light buffer keeps 42 planes per chunk on the CPU, 170 on a GPU).
STACK_BYTES = {"cpu": 64 << 20, "cuda": 256 << 20}


def chunk_planes(plane_count: int, light_res: int, device) -> int:
    """Planes per chunk of a sweep of ``plane_count`` planes: as many as :data:`STACK_BYTES` allows, evened out
    over the chunks so that none is a short remainder."""
    per_plane = 2 * 12 * light_res * light_res
    kind = "cpu" if is_cpu(device) else "cuda"
    most = max(1, STACK_BYTES[kind] // per_plane)
    chunks = -(-max(plane_count, 1) // most)
    return -(-max(plane_count, 1) // chunks)


@dataclass
class SweepBuffers:
    """The sweep's work arrays on one device: eye accumulators (height, width), light buffers (res, res), the
    light buffers' copies at a chunk's planes (chunk, res, res) and the plane positions."""

    radiance: wp.array  # radiance towards the eye, RGB
    transmittance: wp.array  # transmittance of the media along the eye ray, RGB
    depth_sum: wp.array  # (sum of weight * depth [m], sum of weight)
    spans: wp.array  # each eye ray's interval [m] inside the media's boxes
    light_i: wp.array  # light-buffer irradiance, RGB
    light_n: wp.array  # light-buffer expected scattering count, RGB
    stack_i: wp.array  # light_i at each plane of a chunk
    stack_n: wp.array  # light_n at each plane of a chunk
    planes: wp.array  # slice positions along the slice axis [m], in sweep order

    @classmethod
    def kept(cls, height: int, width: int, light_res: int, planes: np.ndarray, device) -> SweepBuffers:
        """The buffers kept under ``slicing:*`` for this frame size, light resolution and plane count (contents
        not cleared, except the planes, uploaded when they change)."""
        eye, light = (height, width), (light_res, light_res)
        stack = (chunk_planes(len(planes), light_res, device), light_res, light_res)
        arrays = [device_buffers.reusable(f"slicing:{name}", shape, dtype, device) for name, shape, dtype in (
            ("radiance", eye, wp.vec3), ("transmittance", eye, wp.vec3), ("depth_sum", eye, wp.vec2),
            ("spans", eye, wp.vec2), ("light_i", light, wp.vec3), ("light_n", light, wp.vec3),
            ("stack_i", stack, wp.vec3), ("stack_n", stack, wp.vec3))]
        return cls(*arrays, device_buffers.upload("slicing:planes", np.asarray(planes, dtype=np.float32), float,
                                                  device))

    def arrays(self) -> tuple[wp.array, ...]:
        return (self.radiance, self.transmittance, self.depth_sum, self.spans, self.light_i, self.light_n,
                self.stack_i, self.stack_n, self.planes)

    def eye(self) -> EyeBuffers:
        eye = EyeBuffers()
        eye.radiance, eye.transmittance, eye.depth_sum, eye.spans = (self.radiance, self.transmittance,
                                                                     self.depth_sum, self.spans)
        return eye

    def light(self) -> LightBuffers:
        light = LightBuffers()
        light.intensity, light.count, light.stack_intensity, light.stack_count = (self.light_i, self.light_n,
                                                                                  self.stack_i, self.stack_n)
        return light


@dataclass
class SliceSweep:
    """Every launch of one frame's sweep: clears, the eye spans, the light's entry, then per slice plane an eye
    gather and a light step (see :mod:`warpsky.techniques.slicing.slicing_kernels`)."""

    device: str
    eye_kernel: Any
    light_kernel: Any
    media: VoxelMedia
    tables: AmsTables
    oriented: OrientedPhases
    shadow: SkyShadow
    cam: PinholeCamera
    frame: SliceFrame
    sun: Sun
    ambient: SkyEnvironment  # the sky around the media (:mod:`warpsky.light.skylight`)
    sample_length: float  # longest eye sample [m]
    planes: np.ndarray  # slice positions along the slice axis [m], in sweep order
    start: tuple[float, float, float]  # irradiance the light buffer starts with, RGB
    buffers: SweepBuffers

    def key(self) -> tuple:
        """Everything a captured graph of this sweep holds by value or by address."""
        structs = tuple(bytes(s.__ctype__()) for s in (self.media, self.tables, self.oriented, self.shadow, self.cam,
                                                        self.frame, self.sun, self.ambient))
        arrays = tuple((a.ptr, a.shape) for a in self.buffers.arrays())
        return (self.eye_kernel, self.light_kernel, structs, arrays, float(self.sample_length),
                np.asarray(self.planes, dtype=np.float64).tobytes(), tuple(self.start))

    def issue(self, *, capturing: bool) -> None:
        """Clear the buffers and launch the sweep, two launches per chunk of planes (the light carried through the
        chunk, then the eye composited through it): plain, through :func:`launch_rows` (row bands on the CPU, a
        stop request honoured between bands); ``capturing``, one launch each."""
        b, device = self.buffers, self.device
        height, width = b.radiance.shape
        res = b.light_i.shape[0]
        b.radiance.zero_()
        b.transmittance.fill_(wp.vec3(1.0, 1.0, 1.0))
        b.depth_sum.zero_()
        b.light_i.fill_(wp.vec3(*self.start))
        b.light_n.zero_()
        wp.launch(eye_span_kernel, dim=(height, width), inputs=[self.media, self.cam, b.spans], device=device)
        eye, light = b.eye(), b.light()
        chunk_size = b.stack_i.shape[0]
        for first in range(0, len(self.planes), chunk_size):
            chunk = PlaneRange()
            chunk.planes, chunk.first = b.planes, first
            chunk.count, chunk.entry = min(chunk_size, len(self.planes) - first), int(first == 0)
            light_inputs = [self.media, self.tables, self.frame, chunk, light]
            eye_inputs = [self.media, self.tables, self.oriented, self.shadow, self.cam, self.frame, chunk, light,
                          self.sun,
                          self.sample_length, self.ambient, eye]
            if capturing:
                wp.launch(self.light_kernel, dim=(res, res), inputs=[*light_inputs, 0], device=device)
                wp.launch(self.eye_kernel, dim=(height, width), inputs=[*eye_inputs, 0], device=device)
            else:
                launch_rows(self.light_kernel, res, res, light_inputs, device)
                launch_rows(self.eye_kernel, height, width, eye_inputs, device)


def run_sweep(sweep: SliceSweep) -> str:
    """Run ``sweep`` on its device: replay the kept graph when the key matches, else capture one (CUDA), else plain
    launches. Returns how it ran (``captured``, ``replayed``, ``plain``; see :data:`COUNTS`)."""
    device = wp.get_device(sweep.device)
    name = str(device)
    if not USE_GRAPHS or not (device.is_cuda or CAPTURE_ON_CPU) or name in _CAPTURE_FAILED:
        return _plain(sweep)
    check_stop()
    key = sweep.key()
    kept = _GRAPHS.get(name)
    if kept is not None and kept[0] == key:
        wp.capture_launch(kept[1])
        return _counted("replayed")
    _GRAPHS.pop(name, None)  # no frame will replay it: let go of it and of the arrays it held
    try:
        graph = _capture(sweep)
    except Exception as error:  # noqa: BLE001 - any capture failure falls back to the launches it would replay
        _CAPTURE_FAILED.add(name)
        if not _WARNED[0]:
            _WARNED[0] = True
            _UNREPORTED[name] = (f"CUDA graph capture of the slicing sweep failed on {name} "
                                 f"({type(error).__name__}: {error}); running plain launches")
        return _plain(sweep)
    _GRAPHS[name] = (key, graph, sweep)
    wp.capture_launch(graph)
    return _counted("captured")


def capture_warning(device) -> str | None:
    """The warning of a failed graph capture on ``device`` that no frame has reported yet (once per process)."""
    return _UNREPORTED.pop(str(wp.get_device(device)), None)


def _capture(sweep: SliceSweep):
    """The sweep recorded as a graph (nothing runs)."""
    for kernel in (eye_span_kernel, sweep.eye_kernel, sweep.light_kernel):
        wp.load_module(kernel.module, device=sweep.device)
    with wp.ScopedCapture(device=sweep.device, force_module_load=False) as capture:
        sweep.issue(capturing=True)
    return capture.graph


def _plain(sweep: SliceSweep) -> str:
    sweep.issue(capturing=False)
    return _counted("plain")


def _counted(how: str) -> str:
    COUNTS[how] += 1
    return how


def forget_graphs() -> None:
    """Drop the kept graphs and the record of failed captures (tests; a long-lived process changing devices)."""
    _GRAPHS.clear()
    _CAPTURE_FAILED.clear()
