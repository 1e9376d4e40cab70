"""Oriented ice crystals: a phase table over the sky around the sun, per sun elevation (parhelia, arcs).

Randomly oriented prisms (:mod:`warpsky.optics.ice`) scatter by the scattering angle alone. Falling plates keep
their c-axis nearly vertical and columns theirs nearly horizontal, so what they scatter depends on where the sun
is: plates give the parhelia (sundogs) and the circumzenithal arc, horizontal columns the tangent arcs, Parry
columns the Parry arcs (Riley et al. 2004 leave parhelia to future work, §8). The table here holds, for each sun
elevation e, the phase function over look directions in the sun's azimuthal frame.

Table layout (:class:`OrientedIceTable`)
    ``phase[s, i, j, c]`` [1/sr], float32: sun elevation ``sun_elevations_deg[s]`` (0-90°), look-direction
    elevation bin i (centre -90° + i step, up positive), azimuth bin j (centre j step from the sun's azimuth,
    0-180°, folded: the laws are mirror-symmetric about the sun's vertical plane), channel c (R, G, B). The look
    direction is where the observer sees the light (minus the scattered light's direction of travel); the sun is
    at (e, 0°). Values are bin averages: sum over bins of phase x :meth:`SkyBins.solid_angles` is 1 per (s, c).
    A negative sun elevation is served by mirroring (every law is symmetric under up-down reflection too).

Parts (as in :mod:`warpsky.optics.ice`: extinction efficiency 2, half diffracted, half ray optics)
    * Ray optics: the Monte Carlo of :mod:`warpsky.optics.oriented_ice_kernels`, hits weighted by the crystal's
      projected area along the sunlight in its sampled orientation.
    * Diffraction: Fraunhofer-Kirchhoff by a disk with the mean projected area the Monte Carlo measured at that
      sun elevation (an approximation: a plate seen edge-on really diffracts into a vertically elongated pattern),
      averaged over each bin by a 16 x 16 sub-sampling within 9° of the sun, then normalised on the grid.

Closed forms (asserted by the tests)
    * Parhelion of plates (vertical 60° prism edges): the azimuthal projection of a ray through a prism with a
      vertical edge obeys Snell's law with Bravais' index n' = sqrt(n^2 - sin^2 e) / cos e, and elevation is
      kept, so the parhelion sits at elevation e and azimuth offset da = 2 asin(n' sin 30°) - 60°; its angular
      distance d from the sun follows from sin(d/2) = cos e sin(da/2). None once n' >= 2 (e >= 60.75°).
    * Circumzenithal arc (in through the top basal face, out through a side face, 90° prism): horizontal
      components scale by 1/n at the horizontal face and the vertical one by n at the vertical face, so the arc's
      elevation is h = asin(sqrt(n^2 - cos^2 e)); it exists only while n^2 - cos^2 e < 1 (e < 32.2°).
    * Upper tangent arc of horizontal columns: rays perpendicular to the c-axis see the 60° prism's minimum
      deviation 2 asin(n / 2) - 60° directly above the sun.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpsky.core.device import cpu_thread_count, resolve_device
from warpsky.core.errors import SceneError
from warpsky.core.files import atomic_write, cache_dir
from warpsky.core.progress import announced
from warpsky.optics import oriented_ice_kernels as kernels
from warpsky.optics.grid import angle_grid
from warpsky.optics.ice import (
    DIFFRACTED_SHARE,
    HABITS,
    ICE_INDEX_TABLE,
    MAX_INTERACTIONS,
    Crystal,
    diffraction_phase,
    ice_refractive_index,
)
from warpsky.optics.spectrum import band_samples

#: Orientation laws and their kernel codes.
KINDS = {"random": kernels.KIND_RANDOM, "plate": kernels.KIND_PLATE, "column": kernels.KIND_COLUMN,
         "parry": kernels.KIND_PARRY}
#: The habit each law is meant for: plates fall with the c-axis vertical, columns with it horizontal.
KIND_HABITS = {"random": ("column", "plate"), "plate": ("plate",), "column": ("column",), "parry": ("column",)}
#: Default sun elevations [deg] of a table: 0-90° every 2°.
DEFAULT_SUN_ELEVATIONS = tuple(float(e) for e in range(0, 91, 2))
#: Photons per channel and sun elevation by default: ~1 % noise in a 1° x 0.5° bin of a parhelion's peak.
DEFAULT_PHOTONS = 4_000_000
#: Photons per second of the CPU kernel on two busy cores (plates, measured), and seconds of diffraction binning
#: per sun elevation, for the progress line's estimate.
CPU_PHOTONS_PER_SECOND = 5.0e6
DIFFRACTION_SECONDS = 1.0
#: Bump when a change to the builder changes table contents.
CACHE_VERSION = 1
#: Diffraction: bins whose centre lies within this angle [deg] of the sun are sub-sampled 16 x 16.
_NEAR_SUN_DEG = 9.0
_SUBSAMPLES = 16


@dataclass(frozen=True)
class IceOrientation:
    """How the crystals of an ice field are oriented.

    ========= ====== ======= ========= ===============================================================
    name      unit   default range     meaning
    ========= ====== ======= ========= ===============================================================
    kind      -      random  see below orientation law
    tilt_deg  deg    0       0 - 90    standard deviation of the Gaussian flutter (0: perfect alignment)
    habit     -      (kind)  column,   crystal shape from :data:`warpsky.optics.ice.HABITS`; empty: plate
                             plate     for ``plate``, column otherwise
    ========= ====== ======= ========= ===============================================================

    Laws: ``random`` (uniform, as :mod:`warpsky.optics.ice`); ``plate`` (c-axis vertical, uniform spin about it,
    tilted by a normal deviate of ``tilt_deg`` about a horizontal axis of uniform azimuth); ``column`` (c-axis
    horizontal with uniform azimuth and uniform spin, tilted out of the horizontal by the flutter); ``parry``
    (as column, but two prism faces horizontal: the spin about the c-axis is the flutter alone).
    USD: ``warpsky:ice:orientation``, ``warpsky:ice:tilt``, ``warpsky:ice:habit`` (see :func:`parse_orientation`).
    """

    kind: str = "random"
    tilt_deg: float = 0.0
    habit: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SceneError(f"ice orientation must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if not (math.isfinite(self.tilt_deg) and 0.0 <= self.tilt_deg <= 90.0):
            raise SceneError(f"ice tilt must be a finite angle in [0, 90] degrees, got {self.tilt_deg!r}")
        if not self.habit:
            object.__setattr__(self, "habit", KIND_HABITS[self.kind][0])
        if self.habit not in KIND_HABITS[self.kind]:
            raise SceneError(f"ice orientation {self.kind!r} needs habit {' or '.join(KIND_HABITS[self.kind])}, "
                             f"got {self.habit!r}")

    @property
    def crystal(self) -> Crystal:
        return HABITS[self.habit]


def parse_orientation(habit: str, orientation: str, tilt_deg: float, prim: str) -> IceOrientation:
    """Validate the USD attributes of an ice field's crystals.

    Args:
        habit: ``warpsky:ice:habit`` token, ``column`` or ``plate``.
        orientation: ``warpsky:ice:orientation`` token, ``random``, ``plate``, ``column`` or ``parry``.
        tilt_deg: ``warpsky:ice:tilt`` [deg], flutter standard deviation, 0-90.
        prim: Prim path, for the message.

    Raises:
        SceneError: naming the prim and attribute and what was expected.
    """
    if habit not in HABITS:
        raise SceneError(f"{prim}.warpsky:ice:habit must be one of {', '.join(HABITS)}, got {habit!r}")
    if orientation not in KINDS:
        raise SceneError(f"{prim}.warpsky:ice:orientation must be one of {', '.join(KINDS)}, got {orientation!r}")
    try:
        tilt = float(tilt_deg)
    except (TypeError, ValueError):
        tilt = math.nan
    if not (math.isfinite(tilt) and 0.0 <= tilt <= 90.0):
        raise SceneError(f"{prim}.warpsky:ice:tilt must be a finite angle in [0, 90] degrees, got {tilt_deg!r}")
    if habit not in KIND_HABITS[orientation]:
        raise SceneError(f"{prim}.warpsky:ice:orientation {orientation!r} needs warpsky:ice:habit "
                         f"{' or '.join(KIND_HABITS[orientation])} (how such crystals fall), got {habit!r}")
    return IceOrientation(orientation, tilt, habit)


@dataclass(frozen=True)
class SkyBins:
    """Sky bins around the sun: elevation bins centred on -90° + i step, azimuth bins on j step (end bins half).

    Attributes:
        elevation_step_deg: Elevation bin width [deg]; 180 / it must be whole.
        azimuth_step_deg: Azimuth bin width [deg]; 180 / it must be whole. Default 0.5°: a parhelion's inner
            edge is placed to a quarter degree.
    """

    elevation_step_deg: float = 1.0
    azimuth_step_deg: float = 0.5

    def __post_init__(self) -> None:
        for name in ("elevation_step_deg", "azimuth_step_deg"):
            count = 180.0 / getattr(self, name)
            if not (count >= 1.0 and abs(count - round(count)) < 1e-9):
                raise SceneError(f"sky bin {name} must divide 180 degrees, got {getattr(self, name)!r}")

    @property
    def elevation_bins(self) -> int:
        return int(round(180.0 / self.elevation_step_deg)) + 1

    @property
    def azimuth_bins(self) -> int:
        return int(round(180.0 / self.azimuth_step_deg)) + 1

    def elevation_centres_deg(self) -> np.ndarray:
        return -90.0 + self.elevation_step_deg * np.arange(self.elevation_bins)

    def azimuth_centres_deg(self) -> np.ndarray:
        return self.azimuth_step_deg * np.arange(self.azimuth_bins)

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(elevation edges, azimuth edges) [rad], clipped to [-pi/2, pi/2] and [0, pi]."""
        de, da = self.elevation_step_deg / 2.0, self.azimuth_step_deg / 2.0
        elev = np.clip(np.append(self.elevation_centres_deg() - de, 90.0), -90.0, 90.0)
        azim = np.clip(np.append(self.azimuth_centres_deg() - da, 180.0), 0.0, 180.0)
        return np.radians(elev), np.radians(azim)

    def solid_angles(self) -> np.ndarray:
        """(E, A) solid angle [sr] of each bin, both azimuth signs together (sums to 4 pi)."""
        elev, azim = self.edges()
        return 2.0 * np.diff(np.sin(elev))[:, None] * np.diff(azim)[None, :]

    def bins_of(self, look: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(elevation bins, azimuth bins) of (N, 3) look directions in the sun frame (the kernels' ``sky_bin``)."""
        look = np.asarray(look, dtype=np.float64)
        elevation = np.arctan2(look[:, 1], np.hypot(look[:, 0], look[:, 2]))
        azimuth = np.arctan2(np.abs(look[:, 2]), look[:, 0])
        row = np.floor((elevation + 0.5 * np.pi) / math.radians(self.elevation_step_deg) + 0.5).astype(int)
        column = np.floor(azimuth / math.radians(self.azimuth_step_deg) + 0.5).astype(int)
        return np.clip(row, 0, self.elevation_bins - 1), np.clip(column, 0, self.azimuth_bins - 1)

    def struct(self) -> kernels.SkyGrid:
        grid = kernels.SkyGrid()
        grid.elevation_step = math.radians(self.elevation_step_deg)
        grid.azimuth_step = math.radians(self.azimuth_step_deg)
        grid.elevation_bins = self.elevation_bins
        grid.azimuth_bins = self.azimuth_bins
        return grid


@dataclass(frozen=True)
class SkyTrace:
    """Raw Monte Carlo result for one sun elevation.

    Attributes:
        histogram: (3, E, A) photons leaving per sky bin and channel.
        hits, misses, trapped: (3,) photon tallies per channel.
        square_area: Launch square's area [circumradius^2].
    """

    histogram: np.ndarray
    hits: np.ndarray
    misses: np.ndarray
    trapped: np.ndarray
    square_area: float


def default_index() -> np.ndarray:
    """(3, 5) ice index at each channel's sample wavelengths (Warren & Brandt 2008)."""
    return np.stack([ice_refractive_index(band_samples(c)[0]) for c in range(3)])


def trace_oriented(
    orientation: IceOrientation,
    sun_elevation_deg: float,
    photons: int,
    *,
    grid: SkyBins | None = None,
    seed: int = 0,
    device: str | None = None,
    refractive_index: np.ndarray | None = None,
    max_interactions: int = MAX_INTERACTIONS,
) -> SkyTrace:
    """Trace ``photons`` photons per channel from a sun at ``sun_elevation_deg`` (0-90°) through oriented prisms."""
    if photons <= 0 or 3 * photons >= 2**31:
        raise SceneError(f"photons per channel must lie in 1..{(2**31 - 1) // 3}, got {photons}")
    if not 0.0 <= sun_elevation_deg <= 90.0:
        raise SceneError(f"sun elevation must lie in [0, 90] degrees, got {sun_elevation_deg}")
    grid = grid or SkyBins()
    device = resolve_device(device or "auto")
    index = default_index() if refractive_index is None else np.asarray(refractive_index, dtype=np.float32)
    crystal = orientation.crystal
    trace = kernels.OrientedTrace()
    trace.seed = int(seed)
    trace.photons_per_channel = int(photons)
    trace.half_length = float(crystal.half_length_ratio)
    trace.refractive_index = wp.array(np.asarray(index, dtype=np.float32), dtype=float, device=device)
    trace.max_interactions = int(max_interactions)
    trace.kind = KINDS[orientation.kind]
    trace.tilt = math.radians(orientation.tilt_deg)
    trace.sun_elevation = math.radians(sun_elevation_deg)
    trace.grid = grid.struct()
    total = 3 * photons
    # CPU: concurrent single-threaded launches from a pool, each into its own band; CUDA: one launch
    bands = max(1, min(cpu_thread_count() if device == "cpu" else 1, total))
    shape = (bands, 3, grid.elevation_bins, grid.azimuth_bins)
    histogram = wp.zeros(shape, dtype=wp.float64, device=device)
    tallies = wp.zeros((bands, 3, kernels.TALLY_COUNT), dtype=wp.int32, device=device)
    edges = [round(i * total / bands) for i in range(bands + 1)]

    def launch(band: int) -> None:
        wp.launch(kernels.trace_oriented_kernel, dim=edges[band + 1] - edges[band],
                  inputs=[trace, band, edges[band], histogram, tallies], device=device)

    wp.load_module(kernels, device=device)  # compile or load once, not in racing threads
    with ThreadPoolExecutor(max_workers=bands) as pool:
        list(pool.map(launch, range(bands)))
    counts = tallies.numpy().sum(axis=0)
    return SkyTrace(
        histogram=histogram.numpy().sum(axis=0),
        hits=counts[:, kernels.TALLY_HITS],
        misses=counts[:, kernels.TALLY_MISSES],
        trapped=counts[:, kernels.TALLY_TRAPPED],
        square_area=4.0 * (1.0 + crystal.half_length_ratio**2),
    )


def _scattering_angle(sun_elevation: float, elevation: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Angle [rad] between the sun and look directions at (elevation, azimuth) [rad] (haversine, exact near 0)."""
    half_chord = (np.sin(0.5 * (elevation - sun_elevation)) ** 2
                  + np.cos(elevation) * math.cos(sun_elevation) * np.sin(0.5 * azimuth) ** 2)
    return 2.0 * np.arcsin(np.sqrt(np.clip(half_chord, 0.0, 1.0)))


def diffraction_bins(equal_area_radius: float, wavelengths, sun_elevation_deg: float, grid: SkyBins) -> np.ndarray:
    """(E, A) Fraunhofer-Kirchhoff diffraction of a disk of ``equal_area_radius`` [m] around the sun, as bin
    averages [1/sr] normalised on ``grid`` (see the module docstring)."""
    return profile_bins(diffraction_phase(equal_area_radius, wavelengths, angle_grid()), sun_elevation_deg, grid)


def profile_bins(profile: np.ndarray, sun_elevation_deg: float, grid: SkyBins) -> np.ndarray:
    """(E, A) bin averages [1/sr], normalised on ``grid``, of a phase ``profile`` given on the shared scattering
    angle grid (:func:`~warpsky.optics.grid.angle_grid`) for a sun at ``sun_elevation_deg``: bins within
    9° of the sun are averaged over 16 x 16 sub-samples (a forward peak narrower than a bin), the others take
    their centre's value."""
    theta = angle_grid()
    sun = math.radians(sun_elevation_deg)
    elev = np.radians(grid.elevation_centres_deg())[:, None]
    azim = np.radians(grid.azimuth_centres_deg())[None, :]
    centre = _scattering_angle(sun, elev, azim)
    values = np.interp(centre, theta, profile)
    rows, cols = np.nonzero(centre < math.radians(_NEAR_SUN_DEG))
    elev_edges, azim_edges = grid.edges()
    u = (np.arange(_SUBSAMPLES) + 0.5) / _SUBSAMPLES
    sub_elev = elev_edges[rows, None] + np.outer(elev_edges[rows + 1] - elev_edges[rows], u)  # (K, S)
    sub_azim = azim_edges[cols, None] + np.outer(azim_edges[cols + 1] - azim_edges[cols], u)
    angles = _scattering_angle(sun, sub_elev[:, :, None], sub_azim[:, None, :])
    weight = np.broadcast_to(np.cos(sub_elev)[:, :, None], angles.shape)  # solid angle ~ cos(elevation)
    samples = np.interp(angles, theta, profile)
    values[rows, cols] = (samples * weight).sum(axis=(1, 2)) / weight.sum(axis=(1, 2))
    return values / np.sum(values * grid.solid_angles())


@dataclass(frozen=True)
class OrientedIceTable:
    """Phase of oriented ice per sun elevation over the sky bins (layout in the module docstring).

    Attributes:
        orientation: The crystals' orientation law.
        sun_elevations_deg: (S,) ascending sun elevations [deg] in [0, 90].
        grid: The sky bins.
        phase: (S, E, A, 3) float32 bin-averaged phase [1/sr], normalised per (sun elevation, channel).
        projected_area: (S,) mean projected area along the sunlight [m^2] (Monte Carlo hit rate).
        trapped_fraction: (S, 3) share of the hitting photons still inside after the interaction cap.
        photons: Photons per channel and sun elevation.
        seconds: Build time [s] (0 when loaded from the cache).
    """

    orientation: IceOrientation
    sun_elevations_deg: np.ndarray
    grid: SkyBins
    phase: np.ndarray
    projected_area: np.ndarray
    trapped_fraction: np.ndarray
    photons: int
    seconds: float = field(default=0.0, compare=False)


def build_oriented_table(
    orientation: IceOrientation,
    *,
    sun_elevations_deg=DEFAULT_SUN_ELEVATIONS,
    grid: SkyBins | None = None,
    photons: int = DEFAULT_PHOTONS,
    seed: int = 0,
    device: str | None = None,
) -> OrientedIceTable:
    """Compute the table (no cache; see :func:`oriented_ice_table`). Sun elevation s uses seed ``seed + s``."""
    grid = grid or SkyBins()
    suns = np.asarray(sun_elevations_deg, dtype=np.float64).reshape(-1)
    if suns.size == 0 or np.any(np.diff(suns) <= 0.0) or suns[0] < 0.0 or suns[-1] > 90.0:
        raise SceneError(f"sun elevations must ascend within [0, 90] degrees, got {suns.tolist()}")
    started = time.perf_counter()
    crystal = orientation.crystal
    solid = grid.solid_angles()
    side = 0.5 * crystal.diameter
    phase = np.empty((len(suns), grid.elevation_bins, grid.azimuth_bins, 3), dtype=np.float32)
    area = np.empty(len(suns))
    trapped = np.empty((len(suns), 3))
    for s, sun in enumerate(suns):
        trace = trace_oriented(orientation, float(sun), photons, grid=grid, seed=seed + s, device=device)
        area[s] = trace.hits.sum() / (3.0 * photons) * trace.square_area * side * side
        trapped[s] = trace.trapped / np.maximum(trace.hits, 1)
        radius = math.sqrt(area[s] / math.pi)
        for c in range(3):
            geometric = trace.histogram[c] / (trace.histogram[c].sum() * solid)
            diffraction = diffraction_bins(radius, band_samples(c)[0], float(sun), grid)
            phase[s, :, :, c] = DIFFRACTED_SHARE * diffraction + (1.0 - DIFFRACTED_SHARE) * geometric
    return OrientedIceTable(orientation, suns, grid, phase, area, trapped, int(photons),
                            time.perf_counter() - started)


def table_key(orientation: IceOrientation, suns, grid: SkyBins, photons: int, seed: int) -> str:
    """Hash of everything that determines a table's contents."""
    crystal = orientation.crystal
    blob = json.dumps({
        "kind": orientation.kind, "tilt": orientation.tilt_deg, "habit": orientation.habit,
        "crystal": [crystal.diameter, crystal.length], "suns": [float(e) for e in suns],
        "grid": [grid.elevation_step_deg, grid.azimuth_step_deg], "photons": int(photons), "seed": int(seed),
        "index": ICE_INDEX_TABLE, "interactions": MAX_INTERACTIONS, "diffracted": DIFFRACTED_SHARE,
        "version": CACHE_VERSION,
    }, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def oriented_ice_table(
    orientation: IceOrientation,
    *,
    sun_elevations_deg=DEFAULT_SUN_ELEVATIONS,
    grid: SkyBins | None = None,
    photons: int = DEFAULT_PHOTONS,
    seed: int = 0,
    device: str | None = None,
) -> OrientedIceTable:
    """The table from ``$WARPSKY_CACHE/optics/ice-oriented-<kind>-<habit>-v<version>-<hash>.npz``, built (with a
    progress line on stderr, and an entry in :data:`warpsky.optics.tables.BUILD_LOG`) when absent. A renderer with
    one sun elevation per frame can ask for exactly that one (``sun_elevations_deg=(e,)``)."""
    from warpsky.optics.tables import BUILD_LOG

    grid = grid or SkyBins()
    suns = np.asarray(sun_elevations_deg, dtype=np.float64).reshape(-1)
    key = table_key(orientation, suns, grid, photons, seed)
    path = cache_dir() / "optics" / f"ice-oriented-{orientation.kind}-{orientation.habit}-v{CACHE_VERSION}-{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as data:
                return OrientedIceTable(orientation, data["suns"], grid, data["phase"], data["area"],
                                        data["trapped"], int(photons))
        except (OSError, ValueError, EOFError, KeyError):
            pass  # unreadable cache entry: rebuild and overwrite it
    seconds = len(suns) * (3.0 * photons / CPU_PHOTONS_PER_SECOND + DIFFRACTION_SECONDS)
    with announced("optics", f"oriented ice table ({orientation.kind} {orientation.habit}s)",
                   f"building oriented ice table ({orientation.kind} {orientation.habit}s, tilt "
                   f"{orientation.tilt_deg:g}°, {len(suns)} sun elevations; ≈ {seconds:.0f} s on two CPU cores, "
                   f"seconds on a GPU; once, then loaded from {path.parent})"):
        table = build_oriented_table(orientation, sun_elevations_deg=suns, grid=grid, photons=photons, seed=seed,
                                     device=device)
    BUILD_LOG.append(("ice", f"oriented-{orientation.kind}", table.seconds))
    atomic_write(path, lambda tmp: np.savez_compressed(tmp, suns=suns, phase=table.phase,
                                                       area=table.projected_area, trapped=table.trapped_fraction))
    return table


def oriented_slice(table: OrientedIceTable, sun_elevation_deg: float) -> tuple[np.ndarray, SkyBins]:
    """((E, A, 3) float32 phase [1/sr] for one sun elevation, the grid), linear between the table's elevations.

    A negative elevation mirrors the table's ``-sun_elevation_deg`` slice top to bottom. Elevations outside the
    table's range raise a :class:`SceneError`. Between two table elevations a sharp arc shows twice at partial
    strength (a parhelion moves ~2.5° in azimuth per degree of sun elevation near e = 50°): where that matters,
    build the table at the frame's own sun elevation."""
    mirrored = sun_elevation_deg < 0.0
    e = abs(float(sun_elevation_deg))
    suns = table.sun_elevations_deg
    if not (suns[0] - 1e-9 <= e <= suns[-1] + 1e-9):
        raise SceneError(f"sun elevation {sun_elevation_deg:g}° lies outside the oriented ice table's "
                         f"{suns[0]:g}-{suns[-1]:g}° (in magnitude)")
    upper = int(np.clip(np.searchsorted(suns, e), 1, max(len(suns) - 1, 1)))
    if len(suns) == 1:
        out = table.phase[0].copy()
    else:
        w = float(np.clip((e - suns[upper - 1]) / (suns[upper] - suns[upper - 1]), 0.0, 1.0))
        out = ((1.0 - w) * table.phase[upper - 1] + w * table.phase[upper]).astype(np.float32)
    return (out[::-1].copy() if mirrored else out), table.grid


def sun_frame(sun_direction) -> np.ndarray:
    """(3, 3) rotation whose rows are the sun frame's X (horizontal towards the sun), Y (up), Z axes in world
    coordinates (Y up): ``frame @ world_vector`` is the vector in the sun frame. A sun at the zenith uses world X."""
    s = np.asarray(sun_direction, dtype=np.float64)
    horizontal = np.array([s[0], 0.0, s[2]])
    norm = np.linalg.norm(horizontal)
    x = horizontal / norm if norm > 1e-12 else np.array([1.0, 0.0, 0.0])
    y = np.array([0.0, 1.0, 0.0])
    return np.stack([x, y, np.cross(x, y)])


def oriented_phase(table: OrientedIceTable, sun_elevation_deg: float, look_dirs) -> np.ndarray:
    """(N, 3) phase [1/sr] seen along (N, 3) unit look directions in the sun frame (:func:`sun_frame`).

    Look directions point from the observer into the sky (minus the scattered light's travel direction). Linear
    in the sun elevation, constant within a bin (so integrals over the sphere stay exact)."""
    values, grid = oriented_slice(table, sun_elevation_deg)
    rows, cols = grid.bins_of(np.atleast_2d(look_dirs))
    return values[rows, cols].astype(np.float64)


def slice_cdf(values: np.ndarray, grid: SkyBins) -> tuple[np.ndarray, np.ndarray]:
    """Sampling tables of one (E, A, 3) slice: (marginal CDF over elevation bins (E + 1, 3), conditional CDFs
    over azimuth bins per elevation bin (E, A + 1, 3)); pick a bin by the two, then a uniform point in it and a
    random azimuth sign. Rows without energy get a uniform CDF."""
    energy = values.astype(np.float64) * grid.solid_angles()[:, :, None]
    row_energy = energy.sum(axis=1)
    marginal = np.concatenate([np.zeros((1, 3)), np.cumsum(row_energy, axis=0)])
    marginal /= np.maximum(marginal[-1:], 1e-300)
    columns = np.concatenate([np.zeros((energy.shape[0], 1, 3)), np.cumsum(energy, axis=1)], axis=1)
    uniform = np.linspace(0.0, 1.0, energy.shape[1] + 1)[None, :, None]
    total = columns[:, -1:, :]
    conditional = np.where(total > 0.0, columns / np.where(total > 0.0, total, 1.0), uniform)
    return marginal, conditional


__all__ = ["DEFAULT_PHOTONS", "DEFAULT_SUN_ELEVATIONS", "KINDS", "IceOrientation", "OrientedIceTable", "SkyBins",
           "SkyTrace", "build_oriented_table", "diffraction_bins", "oriented_ice_table", "oriented_phase",
           "oriented_slice", "parse_orientation", "slice_cdf", "sun_frame", "trace_oriented"]
