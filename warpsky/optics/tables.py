"""Optics tables for exactly the species a scene contains, built lazily and cached on disk.

Each table is stored as ``$WARPSKY_CACHE/optics/<species>-<kind>-<hash>.npz`` (default cache ``~/.cache/warpsky``),
where the hash covers the species' parameters, the angular grid and :data:`CACHE_VERSION`. Files are written to a
temporary name and renamed, so concurrent farm workers never read half a table. :data:`BUILD_LOG` records what this
process computed (as opposed to loaded), so tests and ``warpsky optics build`` can tell a build from a load.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpsky.files import atomic_write, cache_dir
from warpsky.optics.multiple import ams_tables, forward_fractions, modified_mie
from warpsky.optics.species import get_species

#: Bump when a change to the builders changes table contents.
CACHE_VERSION = 1
#: Default highest multiple-scattering order. Riley stopped at n = 26; with g ~ 0.87 the deviation from isotropy
#: falls like 3 g^n, so Ams_60 of every warpsky species is isotropic to ~3e-3 (measured in the optics tests).
DEFAULT_ORDERS = 60
#: (species, kind, seconds) of every table computed (not loaded) in this process.
BUILD_LOG: list[tuple[str, str, float]] = []


def _path(species: str, kind: str, extra: str = "") -> Path:
    key = get_species(species).cache_key()
    return cache_dir() / "optics" / f"{species}-{kind}{extra}-v{CACHE_VERSION}-{key}.npz"


def _cached(species: str, kind: str, build, extra: str = "") -> dict[str, np.ndarray]:
    path = _path(species, kind, extra)
    if path.is_file():
        try:
            with np.load(path) as data:
                return {k: data[k] for k in data.files}
        except (OSError, ValueError, EOFError):
            pass  # unreadable cache entry: rebuild and overwrite it
    started = time.perf_counter()
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

    data = _cached(species, "ams", build, extra=f"{orders}")
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
