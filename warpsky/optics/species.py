"""The particle species warpsky knows, with their sources.

================ ============================== =============================================================
species          extinction cross section [m^2] phase function
================ ============================== =============================================================
air              R 2.28e-31, G 5.33e-31,        Rayleigh, Riley Eq. 1 (cross sections: Riley Table 2 at 650,
                 B 1.30e-30                     515 and 440 nm, our R, G, B)
cloud            6.28e-10 (0.01 mm sphere)      Mie, lognormal droplets around r = 10 um (warpsky.optics.mie)
rain             6.28e-6 (1 mm sphere)          Mie, lognormal drops around r = 1 mm
ice              1.82e-6                        geometric optics Monte Carlo of random hexagonal columns
                                                plus diffraction (warpsky.optics.ice)
snow             1.41e-5                        smooth aggregate model, no halo peaks (warpsky.optics.ice)
stratus          1.54e-10 (π r_e², r_e = 7 µm)  Mie, Bouthors 2006 modified Gamma (N0 300 cm^-3, γ 2, r_e 7 µm)
================ ============================== =============================================================

Cross sections are Riley et al. 2004, Table 2; all albedos default to 1 (Riley §3.1). A field's number
concentration [1/m^3] times the cross section is its extinction coefficient (Riley Eq. 2).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.scene import FIELD_SPECIES, SPECIES_NAMES
from warpsky.optics import mie
from warpsky.optics.analytic import rayleigh
from warpsky.optics.grid import SEGMENTS_DEG, angle_grid, normalise

__all__ = ["FIELD_SPECIES", "SPECIES", "SPECIES_NAMES", "Species", "get_species"]


@dataclass(frozen=True)
class Species:
    """A particle species: where its optics come from.

    Attributes:
        name: One of :data:`SPECIES_NAMES`.
        extinction_cross_section: Per RGB channel [m^2].
        albedo: Single-scattering albedo per channel.
        model: How the phase table is built (``rayleigh``, ``mie``, ``ice``, ``snow``).
        params: Model parameters; part of the cache key.
        source: Where the numbers come from.
    """

    name: str
    extinction_cross_section: tuple[float, float, float]
    model: str
    params: dict = field(default_factory=dict)
    albedo: tuple[float, float, float] = (1.0, 1.0, 1.0)
    source: str = ""

    def cache_key(self) -> str:
        """Hash of everything that determines this species' tables."""
        details = dict(self.params)
        if self.model == "mie":
            details["distribution_values"] = repr(getattr(mie, self.params["distribution"]))
        blob = json.dumps(
            {"name": self.name, "model": self.model, "params": details, "grid": SEGMENTS_DEG}, sort_keys=True
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def build_phase(self) -> np.ndarray:
        """Compute the (3, M) phase table on the shared grid (slow for Mie and ice: use the cache)."""
        if self.model == "rayleigh":
            return normalise(np.tile(rayleigh(np.cos(angle_grid())), (3, 1)))
        if self.model == "mie":
            distribution = getattr(mie, self.params["distribution"])
            return np.asarray(mie.mie_optics(distribution).phase, dtype=np.float64)
        from warpsky.optics.ice import ice_optics, snow_optics  # Warp kernels: loaded for a build only

        if self.model == "ice":
            return np.asarray(ice_optics(self.params["habit"], seed=self.params["seed"]).phase, dtype=np.float64)
        if self.model == "snow":
            return np.asarray(snow_optics().phase, dtype=np.float64)
        raise SceneError(f"species {self.name}: unknown optics model {self.model!r}")


SPECIES: dict[str, Species] = {
    "air": Species("air", (2.28e-31, 5.33e-31, 1.30e-30), "rayleigh", source="Riley 2004 Eq. 1, Table 2"),
    "cloud": Species("cloud", (6.28e-10,) * 3, "mie", {"distribution": "CLOUD"},
                     source="Riley 2004 Table 2; Mie (miepython) over a lognormal, r = 10 um"),
    "rain": Species("rain", (6.28e-6,) * 3, "mie", {"distribution": "RAIN"},
                    source="Riley 2004 Table 2; Mie (miepython) over a lognormal, r = 1 mm"),
    "ice": Species("ice", (1.82e-6,) * 3, "ice", {"habit": "column", "seed": 0},
                   source="Riley 2004 Table 2; ray-traced random hexagonal columns + diffraction"),
    "snow": Species("snow", (1.41e-5,) * 3, "snow", source="Riley 2004 Table 2; smooth aggregate model"),
    "stratus": Species("stratus", (1.54e-10,) * 3, "mie", {"distribution": "BOUTHORS_STRATUS"},
                       source="Bouthors 2006 §3.1: modified Gamma N0 = 300 cm^-3, gamma = 2, r_e = 7 um; "
                       "sigma = pi r_e^2"),
}


def get_species(name: str) -> Species:
    try:
        return SPECIES[name]
    except KeyError:
        raise SceneError(f"unknown species {name!r}; known: {', '.join(SPECIES_NAMES)}") from None
