"""Bouthors 2006 §5: inter-reflections between the cloud base and the ground, two parallel planes ``h`` apart.

Buffers (all (nu, nv, 3) irradiances [sun units], one shared grid of pixel size p = h / 2^detail):

- ``R_G``, ``R_C``: light received by the ground and the cloud base (the ground's direct sun S_G^d excluded);
- ``dR_G``, ``dR_C``: exitance to emit at the next pass.

Initialisation: S_G^i = gather(S_C) (the cloud base's diffuse source: T_3+ sun plus T_ms sky, so the sky through
gaps arrives here too), R_G = S_G^i, dR_G = ρ_G (S_G^d + S_G^i). One iteration = the pair of passes
ground -> cloud (E_C = gather(dR_G), R_C += E_C, dR_C = ρ_C E_C) and cloud -> ground (E_G, R_G += E_G,
dR_G = ρ_G E_G). The residual after an iteration is the luminance of E_G over that of everything the ground has
received (S_G^d + R_G); iterations stop when it falls below ``tolerance``, or at ``max_iterations`` with a warning
stating the residual. Each iteration's exchanged energy stays on the device (one value per iteration); the host
reads them every ``check_every`` iterations (on a GPU each read waits for the device, so by default every 8: up to
7 iterations run past convergence, each adding less than the tolerance; on the CPU a read is free: every
iteration, the stopping point exactly).

Buffers are :func:`warpsky.core.device_buffers.reusable` arrays (``radiosity:NAME``) kept across frames; a solve reads
back R_G after the first gather (the total the residual divides by), the exchanged energies, and R_G and R_C at
the end. :attr:`RadiosityResult.device_received` keeps R_G and R_C on the device for the shading kernel.

Gathers: ``rings`` — §5.3's three square rings of exterior size h, 2h, 8h, read as MIP levels detail, detail + 1 and
detail + 3 of the emitter with weights 0.4, 0.387, 0.213 (the form factors 0.5, 0.3, 0.18 rounded up to keep the
energy of an infinite uniform plane); ``exact`` — the per-texel analytic form factor summed over the whole other
buffer (O(N⁴), the reference).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.passes.stratiform.radiosity_kernels import (
    downsample_kernel,
    exact_gather_kernel,
    ground_direct_kernel,
    ring_gather_kernel,
)


@dataclass
class RadiosityResult:
    """Converged buffers and how they got there.

    Attributes:
        ground_received: R_G (nu, nv, 3): ground irradiance from the sky, the cloud base and inter-reflection.
        cloud_received: R_C (nu, nv, 3): cloud-base irradiance from the ground.
        ground_direct: S_G^d (nu, nv, 3), as given.
        iterations: Iterations (pairs of passes) run.
        residual: Exchanged-energy ratio of the last iteration.
        converged: Whether the residual fell below the tolerance.
        history: Residual after each iteration.
        seconds: Wall time of the iterations (initialisation excluded).
        warning: One line when the iteration stopped at its cap before the exchanged energy fell below the
            tolerance (the stratiform pass's layer carries it to the frame's warnings), else None.
    """

    ground_received: np.ndarray
    cloud_received: np.ndarray
    ground_direct: np.ndarray
    iterations: int
    residual: float
    converged: bool
    history: list[float] = field(default_factory=list)
    seconds: float = 0.0
    warning: str | None = None
    device_received: tuple | None = None  # (R_G, R_C) as device arrays, valid until the next solve

    @property
    def ground_total(self) -> np.ndarray:
        """S_G^d + R_G: everything the ground receives."""
        return self.ground_direct + self.ground_received


def _rgb(values, shape) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    return np.ascontiguousarray(np.broadcast_to(arr, (*shape, 3)), dtype=np.float32)


def pyramid_shape(shape: tuple[int, int], levels: int) -> tuple[int, int]:
    """``shape`` rounded up to multiples of 2^levels (the pyramid needs even sizes down to its top level)."""
    step = 2**levels
    return tuple(int(-(-n // step) * step) for n in shape)


class Radiosity:
    """Ground <-> cloud-base inter-reflection solver (see the module docstring).

    Args:
        pixel_over_h: Buffer pixel size over the plane distance h; must be 2^-detail (1, 0.5, 0.25 ...) for
            ``rings``; any positive value for ``exact``.
        method: ``rings`` or ``exact``.
        tolerance: Stop when an iteration's exchanged energy ratio falls below this.
        max_iterations: Cap on iterations (a warning reports the residual when reached).
        device: Warp device.
        check_every: Iterations between host reads of the exchanged energy; default 1 on the CPU, 8 on GPUs.
    """

    def __init__(self, *, pixel_over_h: float = 1.0, method: str = "rings", tolerance: float = 1e-4,
                 max_iterations: int = 64, device: str = "cpu", check_every: int | None = None):
        if method not in ("rings", "exact"):
            raise ValueError(f"method must be 'rings' or 'exact', got {method!r}")
        detail = -math.log2(pixel_over_h) if pixel_over_h > 0 else float("nan")
        if method == "rings" and not (detail >= 0 and float(detail).is_integer()):
            raise ValueError(f"rings need pixel_over_h = 2^-k (k >= 0), got {pixel_over_h}")
        if not (tolerance > 0 and max_iterations >= 1):
            raise ValueError("tolerance must be > 0 and max_iterations >= 1")
        if check_every is None:
            check_every = 1 if is_cpu(device) else 8
        if not check_every >= 1:
            raise ValueError(f"check_every must be >= 1, got {check_every}")
        self.check_every = int(check_every)
        self.pixel_over_h = float(pixel_over_h)
        self.detail = int(detail) if method == "rings" else 0
        self.method = method
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.device = device

    def __repr__(self) -> str:
        return (f"Radiosity(method={self.method}, pixel_over_h={self.pixel_over_h:g}, tolerance={self.tolerance:g}, "
                f"max_iterations={self.max_iterations})")

    # ------------------------------------------------------------------------------------------------ gathers
    def _gather(self, source, reflectance, received, emitted, exchanged):
        shape = source.shape
        exchanged.zero_()
        if self.method == "exact":
            wp.launch(exact_gather_kernel, dim=shape,
                      inputs=[source, self.pixel_over_h, reflectance, received, emitted, exchanged])
            return
        levels = [source]
        for _ in range(self.detail + 3):
            src = levels[-1]
            dst = device_buffers.reusable(f"radiosity:level{len(levels)}", (src.shape[0] // 2, src.shape[1] // 2),
                                          wp.vec3, self.device)
            wp.launch(downsample_kernel, dim=dst.shape, inputs=[src, dst])
            levels.append(dst)
        m = self.detail
        wp.launch(ring_gather_kernel, dim=shape, inputs=[
            levels[m], levels[m + 1], levels[m + 3], float(2**m), float(2 ** (m + 1)), float(2 ** (m + 3)),
            reflectance, received, emitted, exchanged])

    def _buffer(self, name: str, shape, values=None) -> wp.array:
        """The kept (nu, nv) vec3 buffer ``radiosity:name``: zeroed, or, read-only, holding ``values`` (nu, nv[, 3])
        (copied only when they changed since the last solve, :func:`warpsky.core.device_buffers.refill`)."""
        if values is not None:
            return device_buffers.refill(f"radiosity:{name}", _rgb(values, shape), wp.vec3, self.device)
        array = device_buffers.reusable(f"radiosity:{name}", shape, wp.vec3, self.device)
        array.zero_()
        return array

    def gather(self, exitance) -> np.ndarray:
        """One pass: irradiance (nu, nv, 3) received from the other plane's ``exitance`` (nu, nv[, 3])."""
        shape = np.asarray(exitance).shape[:2]
        with wp.ScopedDevice(self.device), device_buffers.exclusive("radiosity", self.device):
            received = self._buffer("received", shape)
            emitted = self._buffer("emitted", shape)
            ones = self._buffer("ones", shape, 1.0)
            exchanged = device_buffers.reusable("radiosity:exchanged", 1, float, self.device)
            self._gather(self._buffer("source", shape, exitance), ones, received, emitted, exchanged)
            return device_buffers.download("radiosity:received", received)

    def solve(self, *, ground_albedo, cloud_reflectance, ground_direct, cloud_source=None) -> RadiosityResult:
        """Iterate to convergence.

        Args:
            ground_albedo: ρ_G (nu, nv, 3) or (nu, nv).
            cloud_reflectance: ρ_C = R_ms of the cloud base (nu, nv[, 3]); 0 where there is no cloud.
            ground_direct: S_G^d (nu, nv, 3) [irradiance].
            cloud_source: S_C (nu, nv, 3) downward diffuse exitance of the cloud base, or None.
        """
        direct = np.asarray(ground_direct, dtype=np.float32)
        shape = direct.shape[:2]
        if self.method == "rings":
            padded = pyramid_shape(shape, self.detail + 3)
            if padded != tuple(shape):
                raise ValueError(f"rings need buffer sizes that are multiples of {2 ** (self.detail + 3)}, got {shape}"
                                 f" (use pyramid_shape)")
        with wp.ScopedDevice(self.device), device_buffers.exclusive("radiosity", self.device):
            rho_g = self._buffer("ground_albedo", shape, ground_albedo)
            rho_c = self._buffer("cloud_reflectance", shape, cloud_reflectance)
            r_g, r_c = self._buffer("ground_received", shape), self._buffer("cloud_received", shape)
            d_g, d_c = self._buffer("ground_emitted", shape), self._buffer("cloud_emitted", shape)
            exchanged = device_buffers.reusable("radiosity:exchanged", 1, float, self.device)
            source = _rgb(cloud_source if cloud_source is not None else 0.0, shape)
            if np.any(source > 0):
                self._gather(self._buffer("source", shape, source), self._buffer("ones", shape, 1.0), r_g, d_g,
                             exchanged)
            initial = device_buffers.download("radiosity:ground_received", r_g) + _rgb(direct, shape)
            d_g.assign(initial * _rgb(ground_albedo, shape))
            total = float(initial.reshape(-1, 3).sum(axis=0) @ LUMINANCE_WEIGHTS)
            started = time.perf_counter()
            history, residual = self._iterate(rho_g, rho_c, r_g, r_c, d_g, d_c, total)
            wp.synchronize_device()
            seconds = time.perf_counter() - started
            converged = residual < self.tolerance
            warning = None if converged else (
                f"radiosity stopped at the cap of {self.max_iterations} iterations with residual {residual:.3g} "
                f"(tolerance {self.tolerance:g}): ground and cloud albedos near 1 converge slowly")
            return RadiosityResult(device_buffers.download("radiosity:ground_received", r_g),
                                   device_buffers.download("radiosity:cloud_received", r_c), _rgb(direct, shape),
                                   len(history), residual, converged, history, seconds, warning,
                                   device_received=(r_g, r_c))

    def _iterate(self, rho_g, rho_c, r_g, r_c, d_g, d_c, total: float) -> tuple[list[float], float]:
        """Iterations from the initial state (``total``: luminance the ground has received so far): (residual
        after each, the last). Iteration i leaves its exchanged energy in ``gains[i]``; the host reads them every
        :attr:`check_every` iterations and stops at the first residual below the tolerance it has read."""
        gains = device_buffers.reusable("radiosity:gains", self.max_iterations, float, self.device)
        scratch = device_buffers.reusable("radiosity:exchanged", 1, float, self.device)
        history: list[float] = []
        residual = 0.0 if total <= 0 else float("inf")
        iterations = 0
        while total > 0 and iterations < self.max_iterations and not residual < self.tolerance:
            batch = min(self.check_every, self.max_iterations - iterations)
            for i in range(iterations, iterations + batch):
                self._gather(d_g, rho_c, r_c, d_c, scratch)
                self._gather(d_c, rho_g, r_g, d_g, gains[i:i + 1])
            read = device_buffers.download("radiosity:gains", gains)
            for gained in read[iterations:iterations + batch]:
                total += float(gained)
                residual = float(gained) / total
                history.append(residual)
            iterations += batch
        return history, residual


def ground_direct(cloud_transmittance, *, pixel: float, h: float, sun_direction, sun_irradiance,
                  device: str = "cpu") -> np.ndarray:
    """S_G^d on the shared grid: E_sun μ_l T_C at the cloud-base point the sun ray crossed, h tan θ_l towards the
    sun (grid axis 0 = world x, axis 1 = world z). No sun below the horizon."""
    tc = _rgb(cloud_transmittance, np.asarray(cloud_transmittance).shape[:2])
    sun = np.asarray(sun_direction, dtype=np.float64)
    if sun[1] <= 0.0:
        return np.zeros_like(tc)
    shift = h / sun[1] * sun / pixel  # texels from the ground point to the sun ray's cloud-base crossing
    with wp.ScopedDevice(device), device_buffers.exclusive("radiosity", device):
        shape = tc.shape[:2]
        out = device_buffers.reusable("radiosity:ground_direct", shape, wp.vec3, device)
        out.zero_()
        transmittance = device_buffers.reusable("radiosity:cloud_transmittance", shape, wp.vec3, device)
        transmittance.assign(tc)
        wp.launch(ground_direct_kernel, dim=shape, inputs=[
            transmittance, float(shift[0]), float(shift[2]),
            wp.vec3(*(np.asarray(sun_irradiance, dtype=np.float64) * sun[1]).tolist()), out])
        return device_buffers.download("radiosity:ground_direct", out)


#: Full-size (nu, nv) RGB float32 buffers the solver holds (rho_G, rho_C, ones, R_G, R_C, dR_G, dR_C) plus about a
#: third more for the MIP pyramid.
RADIOSITY_BUFFERS = 7 + 1 / 3


def radiosity_grid(layer, ground_height: float, detail: int):
    """The radiosity buffers' placement for ``layer`` over a ground at ``ground_height`` [m]: (x0, z0) [m], texel
    size [m] = h / 2^detail with h the ground-to-base height, and (nu, nv) texels covering the layer plus an 8 h
    margin, rounded up for the MIP pyramid."""
    h = layer.base_altitude - ground_height
    pixel = h / 2**detail
    margin = 8.0 * h
    shape = pyramid_shape((math.ceil((layer.size[0] + 2 * margin) / pixel),
                           math.ceil((layer.size[1] + 2 * margin) / pixel)), detail + 3)
    return (layer.origin[0] - margin, layer.origin[1] - margin), pixel, shape


def radiosity_bytes(layer, ground_height: float, detail: int) -> int:
    """Bytes of the solver's buffers for ``layer`` over a ground at ``ground_height`` [m] (:func:`radiosity_grid`)."""
    _, _, (nu, nv) = radiosity_grid(layer, ground_height, detail)
    return int(nu * nv * 12 * RADIOSITY_BUFFERS)
