"""Flows and noise for advected textures (Neyret 2003): periodic 2D and 3D velocity fields (uniform wind plus
divergence-free curl noise, or a ``.npy`` file), and the periodic noise textures they carry.

:mod:`warpsky.media.advection.advection` advects textures along these flows (and re-exports every public name here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError


def periodic_noise(shape: tuple[int, ...], *, smoothing_texels: float = 3.0, seed: int = 0) -> np.ndarray:
    """Periodic Gaussian-filtered white noise (2D or 3D), zero mean and unit standard deviation, float32.

    Args:
        shape: Array shape, (ny, nx) or (nz, ny, nx).
        smoothing_texels: Standard deviation of the Gaussian filter [texels]; features are a few times this.
        seed: Random seed.
    """
    shape = tuple(int(n) for n in shape)
    axes = tuple(range(len(shape)))
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfftn(rng.standard_normal(shape, dtype=np.float32), axes=axes)  # float32 FFT (NumPy >= 2)
    freqs = np.meshgrid(*[np.fft.fftfreq(n) for n in shape[:-1]], np.fft.rfftfreq(shape[-1]), indexing="ij",
                        sparse=True)
    k2 = sum(f * f for f in freqs)
    spectrum *= np.exp(-2.0 * (math.pi * smoothing_texels) ** 2 * k2).astype(np.float32)
    field = np.fft.irfftn(spectrum, s=shape, axes=axes).astype(np.float64)
    field -= field.mean()
    return (field / max(field.std(), 1e-30)).astype(np.float32)


def autocorrelation(texture: np.ndarray) -> np.ndarray:
    """Normalised periodic autocorrelation ``R(lag)`` of ``texture`` (same shape, float32, ``R[0...] = 1``)."""
    f = np.asarray(texture, dtype=np.float64)
    f = (f - f.mean()).astype(np.float32)  # float32 FFTs: a 4096^2 texture takes ~1.5 s, R needs ~1e-4
    axes = tuple(range(f.ndim))
    power = np.abs(np.fft.rfftn(f, axes=axes)) ** 2
    r = np.fft.irfftn(power, s=f.shape, axes=axes).astype(np.float64)
    if not np.any(f) or r.flat[0] <= 0.0:
        return np.ones(f.shape, dtype=np.float32)  # a constant texture: every lag is perfectly correlated
    r = (r / r.flat[0]).astype(np.float32)
    r.flat[0] = 1.0
    return r


def _curl_modes(extent: np.ndarray, scale_m: float, octaves: int, modes_per_octave: int, rng) -> list:
    """Random integer wave vectors (periodic over ``extent``) near wavelength ``scale_m / 2^o``, with phases and
    amplitudes (velocity amplitude halves per octave)."""
    dims = len(extent)
    modes = []
    for octave in range(octaves):
        wavelength = scale_m / 2**octave
        for _ in range(modes_per_octave):
            while True:
                direction = rng.standard_normal(dims)
                direction /= np.linalg.norm(direction)
                n = np.rint(extent / wavelength * direction)
                if np.any(n != 0):
                    break
            k = 2.0 * math.pi * n / extent  # [rad/m]
            modes.append((k, rng.uniform(0.0, 2.0 * math.pi), rng.standard_normal() * 0.5**octave,
                          rng.standard_normal(3)))
    return modes


def _node_positions(extent: np.ndarray, resolution: tuple[int, ...]) -> list[np.ndarray]:
    """Node coordinates [m] per axis (x first), broadcastable to an array indexed [..., y, x]."""
    axes = [np.arange(n) * (length / n) for n, length in zip(resolution, extent, strict=True)]
    grids = np.meshgrid(*axes[::-1], indexing="ij")  # [z,] y, x order
    return grids[::-1]  # x, y[, z]


def _validate_procedural(extent, resolution, scale_m, octaves, speed_m_s) -> None:
    if scale_m <= 0.0 or scale_m > min(extent) * (1.0 + 1e-9):
        raise ValueError(f"scale_m must lie in (0, {min(extent)}] (the extent's shortest side), got {scale_m}")
    if octaves < 1:
        raise ValueError(f"octaves must be >= 1, got {octaves}")
    if speed_m_s < 0.0:
        raise ValueError(f"speed_m_s must be >= 0, got {speed_m_s}")
    smallest = scale_m / 2 ** (octaves - 1)
    cell = max(e / n for e, n in zip(extent, resolution, strict=True))
    if smallest < 4.0 * cell:
        raise ValueError(f"the smallest eddy ({smallest:g} m) spans fewer than 4 cells of {cell:g} m: "
                         "raise the resolution or lower octaves")


def _normalise_speed(velocity: np.ndarray, speed_m_s: float) -> np.ndarray:
    rms = math.sqrt(float(np.mean(np.sum(velocity**2, axis=-1))))
    return (velocity * (speed_m_s / rms if rms > 0.0 else 0.0)).astype(np.float32)


def _strain_time(velocity: np.ndarray, extent_m) -> float:
    """1 / rms(|grad u|) [s] by central differences on the periodic grid (inf for a uniform field)."""
    u = velocity.astype(np.float64)
    dims = u.ndim - 1
    total = 0.0
    for c in range(dims):  # component
        for axis in range(dims):  # array axis; x is the last
            h = extent_m[dims - 1 - axis] / u.shape[axis]
            total += np.mean(((np.roll(u[..., c], -1, axis) - np.roll(u[..., c], 1, axis)) / (2.0 * h)) ** 2)
    return 1.0 / math.sqrt(total) if total > 0.0 else math.inf


def _load_velocity(path: Path, components: int) -> np.ndarray:
    try:
        velocity = np.load(path)
    except (OSError, ValueError) as exc:
        raise SceneError(f"cannot read velocity field {path}: {exc}") from exc
    if velocity.ndim != components + 1 or velocity.shape[-1] != components:
        want = "(ny, nx, 2)" if components == 2 else "(nz, ny, nx, 3)"
        raise SceneError(f"velocity field {path}: expected shape {want} in m/s, got {velocity.shape}")
    if not np.all(np.isfinite(velocity)):
        raise SceneError(f"velocity field {path}: contains NaN or infinite values")
    return velocity.astype(np.float32)


@dataclass(frozen=True, repr=False)
class Flow2D:
    """A periodic 2D flow over a layer's extent.

    ============  =====  ===================================================================================
    attribute     unit   meaning
    ============  =====  ===================================================================================
    extent_m      m      (Lx, Ly), the period of the flow and of the texture it carries
    velocity      m/s    (ny, nx, 2) float32, components (u_x, u_y) at nodes ``(i Lx/nx, j Ly/ny)``, periodic;
                         defined in the frame that moves with ``wind_m_s``
    wind_m_s      m/s    (w_x, w_y), uniform wind; carries the field along
    ============  =====  ===================================================================================

    A ``.npy`` file holds ``velocity`` as (ny, nx, 2) float in m/s (:meth:`from_npy`).
    """

    extent_m: tuple[float, float]
    velocity: np.ndarray
    wind_m_s: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        if len(self.extent_m) != 2 or min(self.extent_m) <= 0.0:
            raise ValueError(f"extent_m must be two positive lengths [m], got {self.extent_m}")
        if self.velocity.ndim != 3 or self.velocity.shape[2] != 2 or min(self.velocity.shape[:2]) < 2:
            raise ValueError(f"velocity must have shape (ny, nx, 2) with nx, ny >= 2, got {self.velocity.shape}")

    @classmethod
    def still(cls, extent_m, *, wind_m_s=(0.0, 0.0), resolution: tuple[int, int] = (4, 4)) -> Flow2D:
        """A uniform wind and no turbulence (zero wind: nothing moves)."""
        return cls(tuple(map(float, extent_m)), np.zeros((resolution[1], resolution[0], 2), np.float32),
                   tuple(map(float, wind_m_s)))

    @classmethod
    def from_npy(cls, path, extent_m, *, wind_m_s=(0.0, 0.0)) -> Flow2D:
        """Velocity field from a ``.npy`` file of shape (ny, nx, 2) [m/s], periodic over ``extent_m`` [m]."""
        return cls(tuple(map(float, extent_m)), _load_velocity(Path(path), 2), tuple(map(float, wind_m_s)))

    @classmethod
    def procedural(cls, extent_m, *, wind_m_s=(0.0, 0.0), speed_m_s: float = 2.0, scale_m: float | None = None,
                   octaves: int = 3, resolution: tuple[int, int] = (64, 64), seed: int = 0) -> Flow2D:
        """Uniform wind plus divergence-free curl noise: ``u = (d psi/dy, -d psi/dx)`` of a stream function made of
        8 random periodic Fourier modes per octave, differentiated analytically.

        Args:
            extent_m: (Lx, Ly) [m].
            wind_m_s: Uniform wind (w_x, w_y) [m/s].
            speed_m_s: RMS speed of the curl part over the grid [m/s].
            scale_m: Wavelength of the largest eddies [m], at most the extent's shortest side (default: half of
                it); each further octave halves it, with half the velocity amplitude.
            octaves: Number of octaves.
            resolution: (nx, ny) grid nodes; the smallest eddy must span >= 4 cells.
            seed: Random seed.
        """
        extent = np.asarray(extent_m, dtype=np.float64)
        scale_m = float(min(extent) / 2 if scale_m is None else scale_m)
        _validate_procedural(extent, resolution, scale_m, octaves, speed_m_s)
        rng = np.random.default_rng(seed)
        x, y = _node_positions(extent, resolution)
        velocity = np.zeros((resolution[1], resolution[0], 2))
        for k, phase, amplitude, _ in _curl_modes(extent, scale_m, octaves, 8, rng):
            wave = amplitude / np.linalg.norm(k) * np.cos(k[0] * x + k[1] * y + phase)  # d/dk of psi's sine
            velocity[..., 0] += k[1] * wave
            velocity[..., 1] -= k[0] * wave
        return cls(tuple(extent.tolist()), _normalise_speed(velocity, speed_m_s), tuple(map(float, wind_m_s)))

    def strain_time_s(self) -> float:
        """1 / rms velocity gradient [s]: how long the field takes to stretch a texture noticeably."""
        return _strain_time(self.velocity, self.extent_m)

    def __repr__(self) -> str:
        speed = float(np.sqrt(np.sum(self.velocity.astype(np.float64) ** 2, axis=-1)).max())
        return (f"Flow2D(extent_m={self.extent_m}, grid={self.velocity.shape[1]}x{self.velocity.shape[0]}, "
                f"max_speed_m_s={speed:.3g}, wind_m_s={self.wind_m_s})")


@dataclass(frozen=True, repr=False)
class Flow3D:
    """A periodic 3D flow over a box: ``extent_m`` (Lx, Ly, Lz) [m]; ``velocity`` (nz, ny, nx, 3) float32 [m/s],
    components (u_x, u_y, u_z) along the box's axes (warpsky's world axes, Y up), in the frame moving with
    ``wind_m_s`` (w_x, w_y, w_z) [m/s]. A ``.npy`` file holds ``velocity`` (:meth:`from_npy`)."""

    extent_m: tuple[float, float, float]
    velocity: np.ndarray
    wind_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if len(self.extent_m) != 3 or min(self.extent_m) <= 0.0:
            raise ValueError(f"extent_m must be three positive lengths [m], got {self.extent_m}")
        if self.velocity.ndim != 4 or self.velocity.shape[3] != 3 or min(self.velocity.shape[:3]) < 2:
            raise ValueError(f"velocity must have shape (nz, ny, nx, 3) with each n >= 2, got {self.velocity.shape}")

    @classmethod
    def still(cls, extent_m, *, wind_m_s=(0.0, 0.0, 0.0), resolution=(4, 4, 4)) -> Flow3D:
        """A uniform wind and no turbulence."""
        shape = (resolution[2], resolution[1], resolution[0], 3)
        return cls(tuple(map(float, extent_m)), np.zeros(shape, np.float32), tuple(map(float, wind_m_s)))

    @classmethod
    def from_npy(cls, path, extent_m, *, wind_m_s=(0.0, 0.0, 0.0)) -> Flow3D:
        """Velocity field from a ``.npy`` file of shape (nz, ny, nx, 3) [m/s], periodic over ``extent_m`` [m]."""
        return cls(tuple(map(float, extent_m)), _load_velocity(Path(path), 3), tuple(map(float, wind_m_s)))

    @classmethod
    def procedural(cls, extent_m, *, wind_m_s=(0.0, 0.0, 0.0), speed_m_s: float = 2.0,
                   scale_m: float | None = None, octaves: int = 2, resolution=(32, 32, 32), seed: int = 0) -> Flow3D:
        """Uniform wind plus divergence-free curl noise ``u = curl A`` of a vector potential made of 8 random
        periodic Fourier modes per octave (``A_m = e_m sin(k.x + phi)``, so ``u_m = (k x e_m) cos(k.x + phi)``).
        Arguments as :meth:`Flow2D.procedural`; ``resolution`` is (nx, ny, nz)."""
        extent = np.asarray(extent_m, dtype=np.float64)
        scale_m = float(min(extent) / 2 if scale_m is None else scale_m)
        _validate_procedural(extent, resolution, scale_m, octaves, speed_m_s)
        rng = np.random.default_rng(seed)
        x, y, z = _node_positions(extent, resolution)
        velocity = np.zeros((resolution[2], resolution[1], resolution[0], 3))
        for k, phase, amplitude, e in _curl_modes(extent, scale_m, octaves, 8, rng):
            direction = np.cross(k, e) / np.linalg.norm(k)
            wave = amplitude * np.cos(k[0] * x + k[1] * y + k[2] * z + phase)
            for c in range(3):
                velocity[..., c] += direction[c] * wave
        return cls(tuple(extent.tolist()), _normalise_speed(velocity, speed_m_s), tuple(map(float, wind_m_s)))

    def strain_time_s(self) -> float:
        """1 / rms velocity gradient [s]."""
        return _strain_time(self.velocity, self.extent_m)

    def __repr__(self) -> str:
        nz, ny, nx = self.velocity.shape[:3]
        return f"Flow3D(extent_m={self.extent_m}, grid={nx}x{ny}x{nz}, wind_m_s={self.wind_m_s})"
