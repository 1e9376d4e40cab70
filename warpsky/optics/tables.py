"""Optics tables for exactly the species a scene contains, built lazily and cached on disk.

Each table is stored as ``$WARPSKY_CACHE/optics/<species>-<kind>-<hash>.npz`` (default cache ``~/.cache/warpsky``),
where the hash covers the species' parameters, the angular grid and :data:`CACHE_VERSION`. Files are written to a
temporary name and renamed, so concurrent farm workers never read half a table. :data:`BUILD_LOG` records what this
process computed (as opposed to loaded), so tests and ``warpsky optics build`` can tell a build from a load. A table
being built prints a line to stderr first (:func:`build_progress`, then one every 10 s while it runs,
:func:`warpsky.core.progress.announced`): a build takes seconds to minutes, once.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpsky.core.files import atomic_write, cache_dir
from warpsky.core.progress import announced
from warpsky.model.scene import PhaseKind
from warpsky.optics.grid import angle_grid, sphere_integral
from warpsky.optics.multiple import ams_tables, forward_fractions, modified_mie
from warpsky.optics.species import get_species

#: Bump when a change to the builders changes table contents.
CACHE_VERSION = 1
#: Default highest multiple-scattering order. Riley stopped at n = 26; with g ~ 0.87 the deviation from isotropy
#: falls like 3 g^n, so Ams_60 of every warpsky species is isotropic to ~3e-3 (measured in the optics tests).
DEFAULT_ORDERS = 60
#: (species, kind, seconds) of every table computed (not loaded) in this process.
BUILD_LOG: list[tuple[str, str, float]] = []
#: Seconds each table took to build into an empty cache on a 2-core machine shared with other work (load average
#: 3-6), one table after another, for the progress line; Ams tables at 60 orders, after their phase table (the
#: time grows with the orders; rain's and ice's took 28-65 s and 41-53 s as the load varied, here their means).
#: The storm's four species for slicing: about 3 minutes; phase tables only (the other techniques): about 70 s.
#: ``evaluation/benchmarks/bench_optics.py`` measured them on an idle machine: rain's phase 36 s, the four Ams tables 16
#: s.
BUILD_SECONDS = {
    ("cloud", "phase"): 8, ("cloud", "ams"): 2, ("rain", "phase"): 51, ("rain", "ams"): 45,
    ("ice", "phase"): 11, ("ice", "ams"): 45, ("snow", "phase"): 0.1, ("snow", "ams"): 3,
    ("stratus", "phase"): 4, ("stratus", "bouthors"): 21,
}
#: How the progress line names each kind of table.
KIND_NAMES = {"phase": "phase", "ams": "multiple-scattering (Ams)", "bouthors": "modified Mie"}


def build_progress(species: str, kind: str, orders: int | None = None) -> str:
    """The line printed before a table is built: ``building rain phase table (≈ 51 s, once)``."""
    seconds = BUILD_SECONDS.get((species, kind))
    if seconds is not None and orders is not None:
        seconds *= orders / DEFAULT_ORDERS
    estimate = "" if seconds is None else (f"≈ {seconds:.0f} s, " if seconds >= 1.5 else "about a second, ")
    return (f"building {species} {KIND_NAMES.get(kind, kind)} table ({estimate}once; then loaded from "
            f"{cache_dir() / 'optics'})")


def _path(species: str, kind: str, extra: str = "") -> Path:
    key = get_species(species).cache_key()
    return cache_dir() / "optics" / f"{species}-{kind}{extra}-v{CACHE_VERSION}-{key}.npz"


def _cached(species: str, kind: str, build, extra: str = "", *, orders: int | None = None) -> dict[str, np.ndarray]:
    path = _path(species, kind, extra)
    if path.is_file():
        try:
            with np.load(path) as data:
                return {k: data[k] for k in data.files}
        except (OSError, ValueError, EOFError):
            pass  # unreadable cache entry: rebuild and overwrite it
    started = time.perf_counter()
    with announced("optics", f"{species} {KIND_NAMES.get(kind, kind)} table",
                   build_progress(species, kind, orders)):
        arrays = build()
    BUILD_LOG.append((species, kind, time.perf_counter() - started))
    atomic_write(path, lambda tmp: np.savez(tmp, **arrays))
    return arrays


def is_cached(species: str, kind: str = "phase", extra: str = "") -> bool:
    """Whether a table is on disk already (a render would load rather than build it)."""
    return _path(species, kind, extra).is_file()


def phase_table(species: str) -> np.ndarray:
    """(3, M) phase function of ``species`` on the shared grid [1/sr], normalised per channel."""
    return _cached(species, "phase", lambda: {"phase": get_species(species).build_phase()})["phase"]


def ams_table(species: str, orders: int = DEFAULT_ORDERS) -> tuple[np.ndarray, np.ndarray]:
    """(Ams_n for n = 0..orders as (orders+1, 3, M), forward fractions F_n as (orders+1, 3)) (Riley Eqs. 20, 23)."""
    def build():
        ams = ams_tables(phase_table(species), orders)
        return {"ams": ams, "forward": forward_fractions(ams)}

    data = _cached(species, "ams", build, extra=f"{orders}", orders=orders)
    return data["ams"], data["forward"]


def modified_mie_table(species: str, theta_f_deg: float = 5.0) -> dict[str, np.ndarray]:
    """Bouthors 2006 §4.1: forward weight P_f, P_S, P_F and P2 = P_S * P_S for forward cut ``theta_f_deg``."""
    def build():
        result = modified_mie(phase_table(species), np.radians(theta_f_deg))
        return {"forward_weight": result.forward_weight, "p_s": result.p_s, "p_f": result.p_f, "p2": result.p2}

    return _cached(species, "bouthors", build, extra=f"{theta_f_deg:g}")


@dataclass
class OpticsTables:
    """Host tables for a list of species, in that order (row i of each array is species i)."""

    species: tuple[str, ...]
    phase: np.ndarray  # (S, 3, M)
    extinction_cross_section: np.ndarray  # (S, 3) [m^2]
    albedo: np.ndarray  # (S, 3)
    ams: np.ndarray | None = None  # (S, N+1, 3, M)
    forward: np.ndarray | None = None  # (S, N+1, 3)
    seconds: float = 0.0
    built: list = field(default_factory=list)

    def index(self, name: str) -> int:
        return self.species.index(name)


def build_tables(species: list[str] | tuple[str, ...], *, orders: int | None = None) -> OpticsTables:
    """Tables for ``species`` only (cached); with ``orders``, also Ams_0..orders and F_n."""
    names = tuple(dict.fromkeys(species))
    started = time.perf_counter()
    before = len(BUILD_LOG)
    phase = np.stack([phase_table(n) for n in names]) if names else np.zeros((0, 3, 0))
    sigma = np.array([get_species(n).extinction_cross_section for n in names]).reshape(-1, 3)
    albedo = np.array([get_species(n).albedo for n in names]).reshape(-1, 3)
    ams = forward = None
    if orders is not None and names:
        pairs = [ams_table(n, orders) for n in names]
        ams = np.stack([a for a, _ in pairs])
        forward = np.stack([f for _, f in pairs])
    return OpticsTables(names, phase, sigma, albedo, ams, forward, time.perf_counter() - started,
                        BUILD_LOG[before:])


def mean_cosine(medium) -> np.ndarray:
    """Asymmetry g per channel of a medium's phase: the mean cosine of its species' table, else its HG g (0 for
    isotropic and Rayleigh scattering)."""
    if medium.species is not None:
        return species_mean_cosine(medium.species).copy()
    if medium.phase.kind == PhaseKind.HG:
        return np.full(3, float(medium.phase.g))
    return np.zeros(3)


@functools.lru_cache(maxsize=32)
def species_mean_cosine(species: str) -> np.ndarray:
    """Mean cosine g per channel of a species' phase table (kept per process; do not write into it)."""
    return sphere_integral(phase_table(species) * np.cos(angle_grid()))
