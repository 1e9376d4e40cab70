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
lives. The buffers come from :mod:`warpsky.device_buffers` (names ``slicing:*``), so a batch's frames keep the same
addresses and, with the same camera, sun and grids, replay the same graph.

Capture rules followed: nothing is allocated, copied to or from the host, or synchronised inside the capture
(the clears are device memsets and a by-value fill kernel); the kernels' modules are loaded before it starts
(``force_module_load=False``: loading every module Warp knows would compile unrelated techniques).

On the CPU the sweep runs as plain launches, the eye gather in row bands over every core
(:func:`~warpsky.device.launch_rows`), exactly as before graphs existed. If a capture raises, the frame runs as
plain launches, one warning line is printed per process, and that device is not captured again in the process.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warpsky import device_buffers
from warpsky.device import launch_rows
from warpsky.interrupt import check_stop
from warpsky.media.voxel import VoxelMedia
from warpsky.techniques.common import PinholeCamera, Sun
from warpsky.techniques.slicing.kernels import AmsTables, SliceFrame, eye_span_kernel

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
_LOCKS: dict[str, threading.Lock] = {}
_LOCKS_LOCK = threading.Lock()


def sweep_lock(device) -> threading.Lock:
    """The lock a frame holds from its sweep to its downloads: the ``slicing:*`` buffers are one set per device."""
    name = str(wp.get_device(device))
    with _LOCKS_LOCK:
        return _LOCKS.setdefault(name, threading.Lock())


@dataclass
class SweepBuffers:
    """The sweep's work arrays on one device: eye accumulators (height, width) and light buffers (res, res)."""

    radiance: wp.array  # radiance towards the eye, RGB
    transmittance: wp.array  # transmittance of the media along the eye ray, RGB
    depth_sum: wp.array  # (sum of weight * depth [m], sum of weight)
    spans: wp.array  # each eye ray's interval [m] inside the media's boxes
    light_i: wp.array  # light-buffer irradiance, RGB
    light_n: wp.array  # light-buffer expected scattering count, RGB

    @classmethod
    def kept(cls, height: int, width: int, light_res: int, device) -> SweepBuffers:
        """The buffers kept under ``slicing:*`` for this frame size and light resolution (contents not cleared)."""
        eye, light = (height, width), (light_res, light_res)
        return cls(*(device_buffers.reusable(f"slicing:{name}", shape, dtype, device) for name, shape, dtype in (
            ("radiance", eye, wp.vec3), ("transmittance", eye, wp.vec3), ("depth_sum", eye, wp.vec2),
            ("spans", eye, wp.vec2), ("light_i", light, wp.vec3), ("light_n", light, wp.vec3))))

    def arrays(self) -> tuple[wp.array, ...]:
        return (self.radiance, self.transmittance, self.depth_sum, self.spans, self.light_i, self.light_n)


@dataclass
class SliceSweep:
    """Every launch of one frame's sweep: clears, the eye spans, the light's entry, then per slice plane an eye
    gather and a light step (see :mod:`warpsky.techniques.slicing.kernels`)."""

    device: str
    eye_kernel: Any
    light_kernel: Any
    media: VoxelMedia
    tables: AmsTables
    cam: PinholeCamera
    frame: SliceFrame
    sun: Sun
    ambient: wp.vec3  # the dome's mean radiance, RGB
    sample_length: float  # longest eye sample [m]
    planes: np.ndarray  # slice positions along the slice axis [m], in sweep order
    start: tuple[float, float, float]  # irradiance the light buffer starts with, RGB
    buffers: SweepBuffers

    def key(self) -> tuple:
        """Everything a captured graph of this sweep holds by value or by address."""
        structs = tuple(bytes(s.__ctype__()) for s in (self.media, self.tables, self.cam, self.frame, self.sun))
        arrays = tuple((a.ptr, a.shape) for a in self.buffers.arrays())
        return (self.eye_kernel, self.light_kernel, structs, arrays, tuple(float(v) for v in self.ambient),
                float(self.sample_length), np.asarray(self.planes, dtype=np.float64).tobytes(), tuple(self.start))

    def issue(self, *, capturing: bool) -> None:
        """Clear the buffers and launch the sweep: plain, the eye gathers through :func:`launch_rows` (row bands on
        the CPU, a stop request honoured between slices); ``capturing``, one launch each."""
        b, device = self.buffers, self.device
        height, width = b.radiance.shape
        res = b.light_i.shape[0]
        b.radiance.zero_()
        b.transmittance.fill_(wp.vec3(1.0, 1.0, 1.0))
        b.depth_sum.zero_()
        b.light_i.fill_(wp.vec3(*self.start))
        b.light_n.zero_()
        wp.launch(eye_span_kernel, dim=(height, width), inputs=[self.media, self.cam, b.spans], device=device)
        spacing = float(self.frame.spacing)
        # the light enters the media's extent half a slice before the first plane: carry it there first
        # (starting it unattenuated at the first plane is a first-order error in the slice count)
        wp.launch(self.light_kernel, dim=(res, res), inputs=[
            self.media, self.tables, self.frame, float(self.planes[0]) - 0.5 * spacing, 0.5 * spacing, b.light_i,
            b.light_n], device=device)
        for plane in self.planes:
            eye_inputs = [self.media, self.tables, self.cam, self.frame, float(plane), b.light_i, b.light_n, self.sun,
                          b.spans, self.sample_length, self.ambient, b.radiance, b.transmittance, b.depth_sum]
            if capturing:
                wp.launch(self.eye_kernel, dim=(height, width), inputs=[*eye_inputs, 0], device=device)
            else:
                launch_rows(self.eye_kernel, height, width, eye_inputs, device)
            wp.launch(self.light_kernel, dim=(res, res), inputs=[
                self.media, self.tables, self.frame, float(plane), spacing, b.light_i, b.light_n], device=device)


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
            print(f"warpsky: warning: CUDA graph capture of the slicing sweep failed on {name} "
                  f"({type(error).__name__}: {error}); running plain launches", file=sys.stderr)
        return _plain(sweep)
    _GRAPHS[name] = (key, graph, sweep)
    wp.capture_launch(graph)
    return _counted("captured")


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
