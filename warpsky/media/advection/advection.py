"""Advected textures (Neyret 2003, "Advected Textures", SCA): a periodic texture carried by a flow, in several
layers that are regenerated in turn and blended so that the pattern neither smears out nor pops.

Two consumers:

* :class:`AdvectedTexture` — a 2D texture (e.g. a stratiform layer's thickness map) over a layer's horizontal
  extent, advected by a :class:`Flow2D`; ``.at(t)`` gives the blended texture on its own grid.
* :class:`AdvectedDetail` — a 3D detail texture over a box, advected by a :class:`Flow3D`; ``.state(t)`` gives a
  :class:`~warpsky.media.advection.advection_kernels.DetailState` for the ``@wp.func`` ``advected_detail`` /
  ``modulated_density``, which a density sampler calls at each sample point (the coarse grid is not rewritten).

Flows. A flow is a uniform ``wind`` plus a periodic field that the wind carries along (frozen turbulence: the
velocity at ``x`` and time ``t`` is ``wind + field(x - wind t)``). The wind part is applied exactly as one wrapped
translation per frame; only the field is integrated. A flow of zero field therefore shows the texture translated
by ``wind * t``, exactly up to bilinear interpolation.

Layers and time (parameters of both classes):

=============  ======  ===============  ====================================================================
name           unit    default          meaning
=============  ======  ===============  ====================================================================
``layers``     --      3                number of layers L, 3..8
``period_s``   s       (required)      a layer lives ``period_s``; layer k is regenerated (coordinates reset
                                        to identity) at ``t = k period_s / L + m period_s`` for every integer m
``step_s``     s       period_s / 32    internal step of the semi-Lagrangian integration; any value is stable
=============  ======  ===============  ====================================================================

ImageLayer k's blend weight is ``sin^2(pi age / period_s)``: zero at its regeneration and again just before the next,
so every layer has faded out when it is reset (for L equally staggered layers the weights sum to L/2).

Random access. The state at time t depends only on each layer's history since its last regeneration: frame t is
computed from scratch by ``floor(age / step_s) <= period_s / step_s`` full steps per layer on a grid of step times
aligned to the regeneration time, then one partial step to t. Sequential playback reuses the previous frame's full
steps and adds the missing ones; the arithmetic is the same, so both give bit-identical results on one device.
Time codes become seconds as ``time_code / timeCodesPerSecond``; negative times are fine.

The flows, their curl noise and the noise textures live in :mod:`warpsky.media.advection.flows`; their names are
importable from here too.

Choose ``period_s`` about one or two of the flow's ``strain_time_s()`` (1 / rms velocity gradient): longer
periods stretch the texture into visible streaks before the layer fades out; much shorter ones show the blend.
"""


from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.media.advection import advection_kernels as kern
from warpsky.media.advection.flows import Flow2D, Flow3D, autocorrelation, periodic_noise

__all__ = ["MAX_STEPS_PER_PERIOD", "AdvectedDetail", "AdvectedTexture", "Flow2D", "Flow3D", "LayerSchedule",
           "autocorrelation", "layer_schedule", "periodic_noise"]

MAX_STEPS_PER_PERIOD = 100_000


@dataclass(frozen=True)
class LayerSchedule:
    """Where each layer stands at one time (arrays of length L)."""

    regeneration: np.ndarray  # index m of the layer's last regeneration (int64)
    age_s: np.ndarray  # time since it [s], in [0, period_s)
    full_steps: np.ndarray  # whole internal steps since it (int64)
    partial_s: np.ndarray  # the remaining partial step [s]
    weights: np.ndarray  # blend weights sin^2(pi age / period)


def layer_schedule(time_s: float, layers: int, period_s: float, step_s: float) -> LayerSchedule:
    """Regeneration index, age, step counts and blend weight of each layer at ``time_s`` (float64, floor-based, so
    negative times behave like positive ones)."""
    max_steps = int(math.floor(period_s / step_s))
    regeneration = np.zeros(layers, np.int64)
    age = np.zeros(layers)
    steps = np.zeros(layers, np.int64)
    partial = np.zeros(layers)
    for k in range(layers):
        start = k * period_s / layers
        m = math.floor((time_s - start) / period_s)
        a = time_s - (start + m * period_s)
        if a >= period_s:  # float rounding at a boundary
            m, a = m + 1, a - period_s
        if a < 0.0:
            m, a = m - 1, a + period_s
        n = min(int(math.floor(a / step_s)), max_steps)
        regeneration[k], age[k], steps[k], partial[k] = m, a, n, max(a - n * step_s, 0.0)
    weights = np.sin(math.pi * age / period_s) ** 2
    return LayerSchedule(regeneration, age, steps, partial, weights)


class _AdvectedLayers:
    """Shared host logic: buffers, schedule and stepping (cold or reusing the previous frame)."""

    def __init__(self, texture: np.ndarray, flow, dims: int, *, layers: int, period_s: float,
                 step_s: float | None, coordinate_shape, device):
        texture = np.asarray(texture, dtype=np.float32)
        if texture.ndim != dims or min(texture.shape) < 2:
            raise ValueError(f"texture must be a {dims}D array with every side >= 2, got shape {texture.shape}")
        if not np.all(np.isfinite(texture)):
            raise ValueError("texture contains NaN or infinite values")
        if not 3 <= layers <= int(kern.MAX_LAYERS):
            raise ValueError(f"layers must lie in [3, {int(kern.MAX_LAYERS)}], got {layers}")
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0, got {period_s}")
        step_s = period_s / 32.0 if step_s is None else float(step_s)
        if not step_s > 0.0 or period_s / step_s > MAX_STEPS_PER_PERIOD:
            raise ValueError(f"step_s must be > 0 and at least period_s / {MAX_STEPS_PER_PERIOD}, got {step_s}")
        self.flow, self.layer_count, self.period_s, self.step_s = flow, layers, float(period_s), step_s
        self.device = str(wp.get_device(device))
        self.mean = float(texture.astype(np.float64).mean())
        self.std = float(texture.astype(np.float64).std())
        self.texture_shape = texture.shape  # numpy order ([z,] y, x)
        grid = tuple(coordinate_shape) if coordinate_shape is not None else flow.velocity.shape[:dims]
        self.coordinate_shape = grid
        n_tex = np.array(texture.shape[::-1], np.float64)  # x first
        n_grid = np.array(grid[::-1], np.float64)
        n_vel = np.array(flow.velocity.shape[:dims][::-1], np.float64)
        self._texels_per_m = n_tex / np.asarray(flow.extent_m)
        self._texels_per_cell = (n_tex / n_grid).astype(np.float32)
        self._velocity_cells_per_cell = (n_vel / n_grid).astype(np.float32)
        vec = wp.vec2 if dims == 2 else wp.vec3
        velocity = (flow.velocity.astype(np.float64) * self._texels_per_m).astype(np.float32)  # texels/s
        with wp.ScopedDevice(self.device):
            self._texture = wp.array(texture, dtype=float)
            self._correlation = wp.array(autocorrelation(texture), dtype=float)
            self._velocity = wp.array(velocity, dtype=vec)
            shape = (layers, *grid)
            self._full = wp.zeros(shape, dtype=vec)
            self._scratch = wp.zeros(shape, dtype=vec)
            self._show = wp.zeros(shape, dtype=vec)
            self._table_host = np.zeros((int(math.floor(period_s / step_s)) + 2, layers), np.float32)
            self._table = wp.zeros(self._table_host.shape, dtype=float)
            self._reset_mask = wp.zeros(layers, dtype=int)
        self._cached: list[tuple[int, int] | None] = [None] * layers
        self._vec = vec

    def reset(self) -> None:
        """Forget the cached state: the next call computes its frame from scratch."""
        self._cached = [None] * self.layer_count

    def schedule(self, time_s: float) -> LayerSchedule:
        return layer_schedule(float(time_s), self.layer_count, self.period_s, self.step_s)

    def _wind_shift(self, time_s: float) -> np.ndarray:
        """``wind * t`` in texels, wrapped into [0, n) in float64 (exact for any t)."""
        n_tex = np.array(self.texture_shape[::-1], np.float64)
        shift = np.asarray(self.flow.wind_m_s, np.float64) * float(time_s) * self._texels_per_m
        return np.mod(shift, n_tex).astype(np.float32)

    def _advance(self, sched: LayerSchedule) -> None:
        """Bring ``_full`` to each layer's last whole step and ``_show`` to the exact time."""
        reset = np.zeros(self.layer_count, np.int32)
        todo = np.zeros(self.layer_count, np.int64)
        for k in range(self.layer_count):
            cached = self._cached[k]
            m, n = int(sched.regeneration[k]), int(sched.full_steps[k])
            if cached is None or cached[0] != m or cached[1] > n:
                reset[k], todo[k] = 1, n
            else:
                todo[k] = n - cached[1]
        rows = int(todo.max())
        table = self._table_host
        table[:] = 0.0
        for k in range(self.layer_count):
            table[: todo[k], k] = self.step_s
            table[rows, k] = sched.partial_s[k]
        self._table.assign(table)
        self._reset_mask.assign(reset)
        step, reset_kernel = (kern.advect_step_2d, kern.reset_layers_2d) if self._vec is wp.vec2 else (
            kern.advect_step_3d, kern.reset_layers_3d)
        vec = self._vec
        constants = [self._velocity, vec(*self._velocity_cells_per_cell.tolist()),
                     vec(*self._texels_per_cell.tolist()), self._table]
        dim = self._full.shape
        wp.launch(reset_kernel, dim=dim, inputs=[self._reset_mask, self._full], device=self.device)
        for row in range(rows):
            wp.launch(step, dim=dim, inputs=[*constants, row, self._full, self._scratch], device=self.device)
            self._full, self._scratch = self._scratch, self._full
        wp.launch(step, dim=dim, inputs=[*constants, rows, self._full, self._show], device=self.device)
        self._cached = [(int(sched.regeneration[k]), int(sched.full_steps[k])) for k in range(self.layer_count)]

    def _weights(self, sched: LayerSchedule):
        w = np.zeros(int(kern.MAX_LAYERS), np.float32)
        w[: self.layer_count] = sched.weights
        return kern.vec8(*w.tolist())


def _launch_rows(kernel, rows: int, width: int, inputs: list, device: str) -> None:
    """One launch for small outputs; row bands across all CPU cores for large ones."""
    if rows * width < 1 << 16:
        wp.launch(kernel, dim=(rows, width), inputs=[*inputs, 0], device=device)
    else:
        launch_rows(kernel, rows, width, inputs, device)


class AdvectedTexture(_AdvectedLayers):
    """A periodic 2D texture advected by a :class:`Flow2D` (e.g. a stratiform layer's thickness map).

    Args:
        texture: (ny, nx) float array, periodic; texel (j, i) sits at ``(i Lx/nx, j Ly/ny)``.
        extent_m: (Lx, Ly) [m]; must equal ``flow.extent_m``.
        flow: The flow.
        layers, period_s, step_s: See the module docstring.
        coordinate_shape: (ny, nx) of the grid carrying each layer's coordinates (default: the flow's grid).
        device: Warp device.

    ``at(t)`` returns the blended texture at ``t`` [s] on the texture's grid, with the texture's mean and variance.
    """

    def __init__(self, texture, extent_m, flow: Flow2D, *, layers: int = 3, period_s: float,
                 step_s: float | None = None, coordinate_shape: tuple[int, int] | None = None, device="cpu"):
        if not np.allclose(extent_m, flow.extent_m, rtol=1e-9):
            raise ValueError(f"extent_m {tuple(extent_m)} differs from the flow's extent {flow.extent_m}")
        super().__init__(texture, flow, 2, layers=layers, period_s=period_s, step_s=step_s,
                         coordinate_shape=coordinate_shape, device=device)
        self._out = wp.zeros(self.texture_shape, dtype=float, device=self.device)

    def state(self, time_s: float) -> kern.LayerState:
        """The layer's device state at ``time_s`` [s], for ``advected_value_2d`` in other kernels (arrays are this
        object's buffers: valid until the next call)."""
        sched = self.schedule(time_s)
        self._advance(sched)
        s = kern.LayerState()
        s.texture, s.correlation, s.displacement = self._texture, self._correlation, self._show
        s.cells_per_texel = wp.vec2(*(1.0 / self._texels_per_cell).tolist())
        s.weights = self._weights(sched)
        s.layer_count = self.layer_count
        s.shift = wp.vec2(*self._wind_shift(time_s).tolist())
        s.mean = self.mean
        return s

    def at(self, time_s: float) -> wp.array:
        """Blended texture at ``time_s`` [s]: a (ny, nx) float ``wp.array2d`` owned by this object, overwritten by
        the next call (on the CPU ``.numpy()`` is a view of it: copy what you keep)."""
        state = self.state(time_s)
        _launch_rows(kern.advected_layer_kernel, self.texture_shape[0], self.texture_shape[1], [state, self._out],
                     self.device)
        return self._out

    def __repr__(self) -> str:
        return (f"AdvectedTexture(texture={self.texture_shape[1]}x{self.texture_shape[0]}, flow={self.flow!r}, "
                f"layers={self.layer_count}, period_s={self.period_s:g}, step_s={self.step_s:g}, "
                f"device={self.device!r})")


class AdvectedDetail(_AdvectedLayers):
    """A periodic 3D detail texture over a box, advected by a :class:`Flow3D`, for voxel media detail.

    Args:
        texture: (nz, ny, nx) float array, periodic; tiles the box (and space beyond it).
        box_min_m: The box's minimum corner in world coordinates [m]; its size is ``flow.extent_m``.
        flow: The flow.
        layers, period_s, step_s: See the module docstring.
        coordinate_shape: (nz, ny, nx) of each layer's coordinate grid (default: the flow's grid).
        device: Warp device.

    ``state(t)`` gives the ``DetailState`` struct; kernels call ``advected_detail(state, p)`` or
    ``modulated_density(state, coarse, p, amplitude)`` from ``warpsky.media.advection.advection_kernels`` at each
    sample.
    """

    def __init__(self, texture, box_min_m, flow: Flow3D, *, layers: int = 3, period_s: float,
                 step_s: float | None = None, coordinate_shape: tuple[int, int, int] | None = None, device="cpu"):
        super().__init__(texture, flow, 3, layers=layers, period_s=period_s, step_s=step_s,
                         coordinate_shape=coordinate_shape, device=device)
        self.box_min_m = np.asarray(box_min_m, dtype=np.float64)
        if self.box_min_m.shape != (3,):
            raise ValueError(f"box_min_m must be a 3-vector [m], got {box_min_m}")

    def state(self, time_s: float, *, frame_origin_m=(0.0, 0.0, 0.0)) -> kern.DetailState:
        """Device state at ``time_s`` [s]. Kernels pass points relative to ``frame_origin_m`` (world metres, e.g.
        the camera position, for float32 precision far from the origin). Arrays are valid until the next call."""
        sched = self.schedule(time_s)
        self._advance(sched)
        s = kern.DetailState()
        s.texture, s.correlation, s.displacement = self._texture, self._correlation, self._show
        s.cells_per_texel = wp.vec3(*(1.0 / self._texels_per_cell).tolist())
        s.weights = self._weights(sched)
        s.layer_count = self.layer_count
        s.shift = wp.vec3(*self._wind_shift(time_s).tolist())
        s.origin = wp.vec3(*(self.box_min_m - np.asarray(frame_origin_m, np.float64)).tolist())
        s.texels_per_m = wp.vec3(*self._texels_per_m.tolist())
        s.mean = self.mean
        s.std = self.std if self.std > 0.0 else 1.0
        return s

    def sample_grid(self, time_s: float, shape: tuple[int, int, int], *, out: wp.array | None = None) -> wp.array:
        """``advected_detail`` at the nodes of a (nz, ny, nx) grid spanning the box (node (0,0,0) at its corner,
        spacing ``extent / n``): a float ``wp.array3d``. For tests, previews and benchmarks."""
        state = self.state(time_s)
        if out is None:
            out = wp.zeros(shape, dtype=float, device=self.device)
        spacing = np.asarray(self.flow.extent_m) / np.array(shape[::-1], np.float64)
        _launch_rows(kern.detail_grid_kernel, shape[0] * shape[1], shape[2],
                     [state, wp.vec3(*self.box_min_m.tolist()), wp.vec3(*spacing.tolist()), out], self.device)
        return out

    def __repr__(self) -> str:
        nz, ny, nx = self.texture_shape
        return (f"AdvectedDetail(texture={nx}x{ny}x{nz}, box_min_m={tuple(self.box_min_m.tolist())}, "
                f"flow={self.flow!r}, layers={self.layer_count}, period_s={self.period_s:g}, "
                f"step_s={self.step_s:g}, device={self.device!r})")
