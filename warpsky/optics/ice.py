"""Phase functions of ice crystals (ray-traced hexagonal prisms + diffraction) and of snow (smooth aggregates).

Ice (:func:`ice_optics`)
    Randomly oriented hexagonal prisms, large compared with the wavelength. Their extinction efficiency is 2: half
    the extinguished energy is diffracted around the crystal, half is reflected and refracted by it (van de Hulst's
    extinction paradox), so ``phase = 0.5 diffraction + 0.5 geometric optics``, each part normalised on its own.

    * Geometric optics: the Monte Carlo of :mod:`warpsky.optics.ice_kernels` (Fresnel reflection/refraction,
      total internal reflection, at most :data:`MAX_INTERACTIONS` internal face hits). Random orientation gives the
      22° halo (rays through two prism sides at 60°) and the 46° halo (prism side and basal face, 90°), red inside
      blue because the index falls with wavelength (:data:`ICE_INDEX_TABLE`). Each photon uses one of its
      channel's sample wavelengths (:func:`warpsky.optics.spectrum.band_samples`), in turn.
    * Diffraction: Fraunhofer diffraction by a disk of the crystal's orientation-averaged projected area (a fourth
      of its surface area for any convex body, Cauchy's theorem), with Kirchhoff's obliquity factor:
      ``[(1 + cos t) / 2]^2 [2 J1(x sin t) / (x sin t)]^2``, ``x = 2 pi r_eq / lambda``, averaged over the band's
      wavelengths.

    ========== ================ ========= ========= ===================================================
    habit      diameter [um]    length    r_eq [um] notes
    ========== ================ ========= ========= ===================================================
    column     40 (corners)     80 um     30.5      length / diameter 2 (default; Riley's COP data are columns)
    plate      100 (corners)    20 um     38.9      length / diameter 0.2
    ========== ================ ========= ========= ===================================================

Snow (:func:`snow_optics`)
    Aggregates of roughened crystals show no halos. A two-term Henyey-Greenstein model with the same 50/50 split:
    a diffraction-like forward peak ``HG(0.99)`` and a ray-optics part ``HG(0.51)``, total asymmetry
    ``g = (0.99 + 0.51) / 2 = 0.75`` (the large-particle relation g = (g_diffraction + g_rays) / 2, van de Hulst
    1957, §12.42, with g_diffraction ~ 1).
    g = 0.75 is the visible asymmetry reported for roughened/irregular ice crystals and aggregates: Macke, Mueller
    & Raschke 1996 (J. Atmos. Sci. 53, 2813) find g ~ 0.74-0.75 for irregular polycrystals; Yang et al. 2013
    (J. Atmos. Sci. 70, 330) give g ~ 0.75 for severely roughened aggregates. The same table serves all channels.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.device import cpu_thread_count, resolve_device
from warpsky.core.errors import SceneError
from warpsky.optics import ice_kernels as kernels
from warpsky.optics.analytic import henyey_greenstein
from warpsky.optics.grid import angle_grid, normalise, sphere_integral, sphere_weights
from warpsky.optics.spectrum import band_samples

#: Real refractive index of ice Ih, (wavelength [m], n), from Warren & Brandt 2008 (J. Geophys. Res. 113,
#: D14220, "Optical constants of ice from the ultraviolet to the microwave: a revised compilation"), sampled every
#: 50 nm; interpolated linearly in wavelength by :func:`ice_refractive_index`.
ICE_INDEX_TABLE = (
    (400e-9, 1.3194),
    (450e-9, 1.3157),
    (500e-9, 1.3130),
    (550e-9, 1.3110),
    (600e-9, 1.3094),
    (650e-9, 1.3080),
    (700e-9, 1.3069),
)
#: Internal face hits after which a photon still inside is dropped and tallied as trapped: ~4e-4 of the energy
#: for columns, ~6e-4 for plates (1e-3 and 1.5e-3 with a cap of 20; long total-internal-reflection orbits).
MAX_INTERACTIONS = 30
#: Photons launched per channel by default: one ice_optics() call takes ~7-8 s on two CPU cores with the kernel
#: cached (~9 s cold; ~6 M photons/s), ~1 % noise per 0.1° node at the 22° halo, ~2 % at the 46° halo.
DEFAULT_PHOTONS = 16_000_000
#: Share of the extinguished energy that is diffracted (extinction efficiency 2).
DIFFRACTED_SHARE = 0.5
#: Snow model: (weight, g) of the diffraction-like peak and of the ray-optics part.
SNOW_PEAK = (0.5, 0.99)
SNOW_RAYS = (0.5, 0.51)


@dataclass(frozen=True)
class Crystal:
    """A hexagonal prism.

    Attributes:
        diameter: Across opposite corners of the hexagon [m] (twice the side length).
        length: Along the c-axis [m].
    """

    diameter: float
    length: float

    @property
    def half_length_ratio(self) -> float:
        """Half length in units of the hexagon's circumradius (= length / diameter)."""
        return self.length / self.diameter

    @property
    def surface_area(self) -> float:
        """Total surface [m^2]: two hexagons of side a plus six a x length rectangles."""
        side = 0.5 * self.diameter
        return 3.0 * math.sqrt(3.0) * side * side + 6.0 * side * self.length

    @property
    def mean_projected_area(self) -> float:
        """Orientation-averaged projected area [m^2]: surface / 4 (Cauchy, any convex body)."""
        return 0.25 * self.surface_area

    @property
    def equal_area_radius(self) -> float:
        """Radius [m] of the disk with the mean projected area."""
        return math.sqrt(self.mean_projected_area / math.pi)


HABITS: dict[str, Crystal] = {
    "column": Crystal(diameter=40e-6, length=80e-6),
    "plate": Crystal(diameter=100e-6, length=20e-6),
}


@dataclass(frozen=True)
class IceOptics:
    """Phase function of a particle species per RGB channel on the shared grid.

    Attributes:
        habit: ``column``, ``plate`` or ``snow``.
        phase: (3, M) phase function [1/sr] per channel R, G, B, each row integrating to 1 over the sphere.
        asymmetry: (3,) mean cosine of the scattering angle per channel.
        photons: Photons launched per channel (0 for the analytic snow model).
        geometric: (3, M) normalised geometric-optics part alone [1/sr] (None for snow).
        trapped_fraction: (3,) share of the crystal-hitting photons still inside after :data:`MAX_INTERACTIONS`.
        projected_area: (3,) mean projected area [m^2] measured by the Monte Carlo's hit rate (Cauchy: surface / 4).
        crystal: The prism traced (None for snow).
    """

    habit: str
    phase: np.ndarray
    asymmetry: np.ndarray
    photons: int = 0
    geometric: np.ndarray | None = None
    trapped_fraction: np.ndarray | None = None
    projected_area: np.ndarray | None = None
    crystal: Crystal | None = None


@dataclass(frozen=True)
class PrismTrace:
    """Raw Monte Carlo result.

    Attributes:
        nodes: Histogram nodes [rad], 0 to pi every ``BIN_DEG``.
        histogram: (3, nodes) photons leaving per node, tent-weighted (sums to the photons that left).
        hits: (3,) photons that hit the crystal.
        misses: (3,) photons that missed it.
        trapped: (3,) photons still inside after the interaction cap.
        square_area: Area of the launch square in units of the circumradius squared.
    """

    nodes: np.ndarray
    histogram: np.ndarray
    hits: np.ndarray
    misses: np.ndarray
    trapped: np.ndarray
    square_area: float

    def density(self) -> np.ndarray:
        """(3, nodes) piecewise-linear density [1/sr] of the leaving photons; each row integrates to 1."""
        return self.histogram / (self.histogram.sum(axis=1, keepdims=True) * sphere_weights(self.nodes))


def ice_refractive_index(wavelength) -> np.ndarray:
    """Real refractive index of ice at ``wavelength`` [m] (400-700 nm), from :data:`ICE_INDEX_TABLE`."""
    table = np.asarray(ICE_INDEX_TABLE)
    wavelength = np.asarray(wavelength, dtype=np.float64)
    if np.any(wavelength < table[0, 0] - 1e-12) or np.any(wavelength > table[-1, 0] + 1e-12):
        raise SceneError("ice refractive index is tabulated for 400-700 nm only")
    return np.interp(wavelength, table[:, 0], table[:, 1])


def trace_prisms(
    half_length_ratio: float,
    photons: int,
    *,
    seed: int = 0,
    device: str | None = None,
    refractive_index: np.ndarray | None = None,
    rotation: tuple[float, float, float, float] | None = None,
    max_interactions: int = MAX_INTERACTIONS,
) -> PrismTrace:
    """Trace ``photons`` photons per channel through hexagonal prisms.

    Args:
        half_length_ratio: Prism length / diameter (half length over circumradius).
        photons: Photons launched per channel (hits and misses).
        seed: Random seed; results depend only on it, not on the device's thread count.
        device: Warp device (``auto`` when None).
        refractive_index: (3, samples) index per channel and wavelength sample; default the bands' 5 samples.
        rotation: Fixed crystal-from-world rotation as a quaternion (x, y, z, w) for every photon; random when None.
        max_interactions: Internal face hits before a photon counts as trapped.

    Returns:
        The raw histogram and tallies.
    """
    if photons <= 0 or 3 * photons >= 2**31:
        raise SceneError(f"photons per channel must lie in 1..{(2**31 - 1) // 3}, got {photons}")
    if half_length_ratio <= 0.0:
        raise SceneError(f"prism length / diameter must be positive, got {half_length_ratio}")
    device = resolve_device(device or "auto")
    if refractive_index is None:
        refractive_index = np.stack([ice_refractive_index(band_samples(c)[0]) for c in range(3)])
    index_wp = wp.array(np.asarray(refractive_index, dtype=np.float32), dtype=float, device=device)
    total = 3 * photons
    # CPU: several launches from a thread pool (each launch is single-threaded but releases the GIL); CUDA: one
    threads = cpu_thread_count() if device == "cpu" else 1
    bands = max(1, min(threads, total))
    histogram = wp.zeros((bands, 3, kernels.NODE_COUNT), dtype=wp.float64, device=device)
    tallies = wp.zeros((bands, 3, kernels.TALLY_COUNT), dtype=wp.int32, device=device)
    fixed = wp.quat(*(rotation if rotation is not None else (0.0, 0.0, 0.0, 1.0)))
    edges = [round(i * total / bands) for i in range(bands + 1)]

    def launch(band: int) -> None:
        crystal_args = [float(half_length_ratio), index_wp, max_interactions, int(rotation is None), fixed]
        inputs = [seed, photons, *crystal_args, band, histogram, tallies, edges[band]]
        wp.launch(kernels.trace_prisms_kernel, dim=edges[band + 1] - edges[band], inputs=inputs, device=device)

    wp.load_module(kernels, device=device)  # compile or load once, not in racing threads
    if bands == 1:
        launch(0)
    else:
        with ThreadPoolExecutor(max_workers=bands) as pool:
            list(pool.map(launch, range(bands)))
    counts = tallies.numpy().sum(axis=0)
    bound = 1.0 + half_length_ratio**2
    return PrismTrace(
        nodes=np.radians(np.arange(kernels.NODE_COUNT) * kernels.BIN_DEG),
        histogram=histogram.numpy().sum(axis=0),
        hits=counts[:, kernels.TALLY_HITS],
        misses=counts[:, kernels.TALLY_MISSES],
        trapped=counts[:, kernels.TALLY_TRAPPED],
        square_area=4.0 * bound,
    )


def bessel_j1(z) -> np.ndarray:
    """Bessel function J1(z), real z >= 0, by the trapezoid rule on Bessel's integral (error ~1e-11 for z <= 500).

    J1(z) = 1/(2 pi) integral over [0, 2 pi] of cos(t - z sin t) dt; the integrand is periodic and smooth, so
    K equally spaced points err by about J_K(z), negligible once K exceeds z by a few dozen.
    """
    z = np.asarray(z, dtype=np.float64)
    nodes = int(np.max(z, initial=0.0)) + 64
    t = (np.arange(nodes) + 0.5) * (2.0 * np.pi / nodes)
    flat = z.reshape(-1)
    out = np.empty_like(flat)
    for start in range(0, len(flat), 512):
        chunk = flat[start : start + 512, None]
        out[start : start + 512] = np.cos(t - chunk * np.sin(t)).mean(axis=1)
    return out.reshape(z.shape)


def diffraction_phase(equal_area_radius: float, wavelengths, theta: np.ndarray | None = None) -> np.ndarray:
    """Fraunhofer-Kirchhoff diffraction by a disk of radius ``equal_area_radius`` [m], normalised [1/sr].

    Args:
        equal_area_radius: Disk radius [m].
        wavelengths: Wavelengths [m] averaged with equal weights (each normalised first).
        theta: Scattering angles [rad]; the shared grid when None.
    """
    theta = angle_grid() if theta is None else theta
    sin_t = np.sin(theta)
    obliquity = (0.5 * (1.0 + np.cos(theta))) ** 2
    total = np.zeros_like(theta)
    for wavelength in np.atleast_1d(wavelengths):
        z = 2.0 * np.pi * equal_area_radius / wavelength * sin_t
        small = z < 1e-6
        airy = np.where(small, 1.0, 2.0 * bessel_j1(z) / np.where(small, 1.0, z)) ** 2
        total += normalise(obliquity * airy, theta)
    return total / len(np.atleast_1d(wavelengths))


def _phase_result(habit: str, phase: np.ndarray, **extra) -> IceOptics:
    phase = normalise(np.maximum(phase, 0.0))
    asymmetry = sphere_integral(phase * np.cos(angle_grid()))
    return IceOptics(habit=habit, phase=phase, asymmetry=asymmetry, **extra)


def ice_optics(
    habit: str = "column", *, seed: int = 0, photons: int | None = None, device: str | None = None
) -> IceOptics:
    """Phase function of randomly oriented hexagonal ice prisms: ray tracing plus diffraction.

    Args:
        habit: ``column`` (length / diameter 2, default) or ``plate`` (0.2); sizes in :data:`HABITS`.
        seed: Random seed; the same seed gives the same table on a given device.
        photons: Photons per channel; :data:`DEFAULT_PHOTONS` when None.
        device: Warp device for the Monte Carlo (``auto`` when None).

    Returns:
        IceOptics with the (3, M) phase on the shared grid, normalised per channel.
    """
    if habit not in HABITS:
        raise SceneError(f"unknown ice habit {habit!r}; known: {', '.join(HABITS)}")
    crystal = HABITS[habit]
    photons = DEFAULT_PHOTONS if photons is None else int(photons)
    trace = trace_prisms(crystal.half_length_ratio, photons, seed=seed, device=device)
    theta = angle_grid()
    # every histogram node is a grid node, so linear interpolation keeps the density (and its integral) exact
    density = trace.density()
    geometric = normalise(np.stack([np.interp(theta, trace.nodes, row) for row in density]))
    diffraction = np.stack([diffraction_phase(crystal.equal_area_radius, band_samples(c)[0], theta) for c in range(3)])
    side = 0.5 * crystal.diameter
    return _phase_result(
        habit,
        DIFFRACTED_SHARE * diffraction + (1.0 - DIFFRACTED_SHARE) * geometric,
        photons=photons,
        geometric=geometric,
        trapped_fraction=trace.trapped / np.maximum(trace.hits, 1),
        projected_area=trace.hits / photons * trace.square_area * side * side,
        crystal=crystal,
    )


def snow_optics() -> IceOptics:
    """Smooth phase function of snow aggregates (two-term Henyey-Greenstein, g = 0.75, no halos)."""
    mu = np.cos(angle_grid())
    (w_peak, g_peak), (w_rays, g_rays) = SNOW_PEAK, SNOW_RAYS
    row = normalise(w_peak * henyey_greenstein(mu, g_peak) + w_rays * henyey_greenstein(mu, g_rays))
    return _phase_result("snow", np.tile(row, (3, 1)))


__all__ = [
    "HABITS",
    "ICE_INDEX_TABLE",
    "MAX_INTERACTIONS",
    "Crystal",
    "IceOptics",
    "PrismTrace",
    "diffraction_phase",
    "ice_optics",
    "ice_refractive_index",
    "snow_optics",
    "trace_prisms",
]
