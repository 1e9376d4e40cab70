"""Water content to extinction: a cloud model's mixing ratios as the extinction coefficients warpsky renders.

Cloud models (CM1, WRF) carry each hydrometeor as a mixing ratio q [kg of water per kg of dry air]. Rendering
needs the extinction coefficient β [1/m] of each species warpsky has optics for (``cloud``, ``rain``, ``ice``,
``snow``: :data:`~warpsky.model.scene.FIELD_SPECIES`, whose phase functions and cross sections are Riley et al.
2004 §3.1, Table 2). The conversion, per grid cell:

1. Temperature from the potential temperature θ [K] and pressure p [Pa] (Poisson's equation):
   T = θ (p / p0)^(R_d / c_p), p0 = 1e5 Pa.
2. Dry-air density from the ideal gas law, the water vapour's share of the pressure taken out when the file
   gives the vapour mixing ratio q_v: ρ_d = p / (R_d T (1 + q_v / ε)), ε = R_d / R_v = 0.622 (the ideal gas law
   for the mixture, p = ρ_d R_d T + ρ_v R_v T with ρ_v = q_v ρ_d). Without q_v, ρ_d = p / (R_d T), about 1 %
   high in moist low levels.
3. Water content W = q ρ_d [kg/m³].
4. Extinction from the hydrometeor's size distribution, in the geometric-optics limit: every particle removes
   twice its projected area (Q_ext = 2, the extinction paradox; Riley §3.1 uses σ_ex = 2πr² for all water and ice
   particles), which holds to a few per cent for particles much larger than the wavelength (size parameter
   2πr/λ > 100: r > 9 µm at 550 nm).

   * **Monodisperse / effective radius** (cloud droplets, cloud ice): for spheres of density ρ_p and effective
     radius r_e = <r³>/<r²>, β = 3 W / (2 ρ_p r_e) (Stephens 1978; for ice, the same form with an ice effective
     radius is Fu 1996's leading term β ≈ IWC · a1 / D_ge). Droplets: ρ_w = 1000 kg/m³, r_e = 10 µm (the
     ``cloud`` species' lognormal, Riley Table 2's 0.01 mm sphere). Ice: ρ_i = 917 kg/m³, r_e = 25 µm (mid-range
     of the effective sizes of cirrus and anvil ice, D_ge 10-130 µm in Fu 1996).
   * **Exponential (inverse-exponential) distributions** (rain, snow, graupel), N(D) = N0 exp(-Λ D) [1/m⁴] of
     spheres of bulk density ρ_p: W = π ρ_p N0 / Λ⁴ fixes Λ = (π ρ_p N0 / W)^(1/4), and
     β = Q_ext (π/4) ∫ D² N(D) dD = π N0 / Λ³. Rain: Marshall and Palmer (1948), N0 = 8e6 m⁻⁴, ρ_w = 1000;
     snow: N0 = 3e6 m⁻⁴, ρ_s = 100 kg/m³; graupel: N0 = 4e4 m⁻⁴, ρ_g = 400 kg/m³ (Lin, Farley and Orville
     1983, the bulk scheme CM1 and WRF's Lin option use; Morrison's and Thompson's schemes diagnose their own
     N0, which a file does not carry). β is not linear in W: it grows as W^(3/4).

Two-moment schemes (Morrison's, Thompson's rain and ice; CM1's ``ncr ncs ncg nci``, WRF's ``QNRAIN QNSNOW
QNGRAUPEL QNICE``, per kg of dry air) also carry each category's number concentration N [1/m³ after × ρ_d]; where
it is given it replaces the fixed intercept or radius: an exponential's slope follows from W and N,
Λ = (π ρ_p N / W)^(1/3) and β = π N / Λ² = (π N)^(1/3) (W / ρ_p)^(2/3); droplets and ice then all take the mean
particle mass (r = (3 W / (4 π ρ_p N))^(1/3), β = 2 π r² N).

Graupel has no optics of its own in warpsky (Riley §3.1 leaves it out too); it renders with the ``snow``
species' phase function (large, irregular ice without halo peaks), its extinction added to the snow's: for two
fields with the same phase function, Riley's Eq. 3 and 6 make their sum the same medium.

Typical values (W = 1 g/m³): cloud 0.15 1/m (a 1 km thick cloud has τ = 150), rain 2.2e-3, ice 0.065, snow 0.010,
graupel 1.2e-3.

References: Marshall, J. S. and Palmer, W. M. K. (1948), J. Meteor. 5, 165-166. Stephens, G. L. (1978), J. Atmos.
Sci. 35, 2123-2132. Lin, Y.-L., Farley, R. D. and Orville, H. D. (1983), J. Clim. Appl. Meteor. 22, 1065-1092.
Fu, Q. (1996), J. Climate 9, 2058-2082. Riley, K. et al. (2004), Efficient Rendering of Atmospheric Phenomena.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError

__all__ = ["CP_DRY", "EPSILON", "HYDROMETEORS", "P0", "R_DRY", "Hydrometeor", "dry_air_density", "extinction",
           "species_extinction", "temperature_from_theta", "water_content"]

#: Gas constant of dry air [J/(kg K)] and its heat capacity at constant pressure [J/(kg K)] (CM1's and WRF's
#: values: CM1 constants.F rd = 287.04, cp = 1005.7; WRF r_d = 287, cp = 7 r_d / 2 = 1004.5).
R_DRY = 287.04
CP_DRY = 1005.7
#: Reference pressure of the potential temperature [Pa].
P0 = 1.0e5
#: R_d / R_v, the ratio of the gas constants of dry air and water vapour.
EPSILON = 0.622


@dataclass(frozen=True)
class Hydrometeor:
    """One of a cloud model's water categories and how its water content becomes extinction.

    ==================== ======= ============================================================================
    attribute            unit    meaning
    ==================== ======= ============================================================================
    name                 –       ``cloud``, ``rain``, ``ice``, ``snow``, ``graupel``
    species              –       the warpsky species it renders as (its phase function and cross section)
    particle_density     kg/m³   density of the particles' (bulk) material
    effective_radius     m       r_e of the monodisperse model; 0 for an exponential distribution
    intercept            1/m⁴    N0 of the exponential distribution; 0 for the effective-radius model
    source               –       where the numbers come from
    ==================== ======= ============================================================================
    """

    name: str
    species: str
    particle_density: float
    effective_radius: float = 0.0
    intercept: float = 0.0
    source: str = ""

    def __post_init__(self):
        if not (self.particle_density > 0.0):
            raise SceneError(f"hydrometeor {self.name}: particle density must be > 0 kg/m^3, "
                             f"got {self.particle_density!r}")
        if (self.effective_radius > 0.0) == (self.intercept > 0.0):
            raise SceneError(f"hydrometeor {self.name}: give an effective radius [m] or an exponential intercept "
                             f"N0 [1/m^4], exactly one, got {self.effective_radius!r} and {self.intercept!r}")

    @property
    def exponential(self) -> bool:
        """Whether the size distribution is exponential (else monodisperse at the effective radius)."""
        return self.intercept > 0.0

    def __repr__(self) -> str:
        size = (f"N0={self.intercept:g} 1/m^4" if self.exponential else f"r_e={self.effective_radius * 1e6:g} um")
        return f"Hydrometeor({self.name} -> {self.species}, rho={self.particle_density:g} kg/m^3, {size})"


HYDROMETEORS: dict[str, Hydrometeor] = {
    "cloud": Hydrometeor("cloud", "cloud", 1000.0, effective_radius=10e-6,
                         source="droplets, r_e = 10 um (Riley 2004 Table 2); beta = 3W / (2 rho_w r_e)"),
    "rain": Hydrometeor("rain", "rain", 1000.0, intercept=8.0e6,
                        source="Marshall-Palmer 1948, N0 = 8e6 m^-4; Q_ext = 2"),
    "ice": Hydrometeor("ice", "ice", 917.0, effective_radius=25e-6,
                       source="ice, r_e = 25 um (Fu 1996 range); beta = 3W / (2 rho_i r_e)"),
    "snow": Hydrometeor("snow", "snow", 100.0, intercept=3.0e6,
                        source="Lin, Farley and Orville 1983: N0 = 3e6 m^-4, rho_s = 100 kg/m^3; Q_ext = 2"),
    "graupel": Hydrometeor("graupel", "snow", 400.0, intercept=4.0e4,
                           source="Lin, Farley and Orville 1983: N0 = 4e4 m^-4, rho_g = 400 kg/m^3; Q_ext = 2"),
}


def temperature_from_theta(theta: np.ndarray, pressure: np.ndarray) -> np.ndarray:
    """Temperature [K] from potential temperature ``theta`` [K] and ``pressure`` [Pa]: T = θ (p / p0)^(R_d/c_p)."""
    return np.asarray(theta, dtype=np.float64) * (np.asarray(pressure, dtype=np.float64) / P0) ** (R_DRY / CP_DRY)


def dry_air_density(pressure: np.ndarray, temperature: np.ndarray, vapour: np.ndarray | None = None) -> np.ndarray:
    """Dry-air density [kg/m³] from ``pressure`` [Pa], ``temperature`` [K] and, when given, the water-vapour
    mixing ratio ``vapour`` [kg/kg]: ρ_d = p / (R_d T (1 + q_v / ε))."""
    p = np.asarray(pressure, dtype=np.float64)
    t = np.asarray(temperature, dtype=np.float64)
    if np.any(~np.isfinite(p)) or np.any(p <= 0.0):
        raise SceneError("air pressure must be finite and > 0 Pa everywhere")
    if np.any(~np.isfinite(t)) or np.any(t <= 0.0):
        raise SceneError("air temperature must be finite and > 0 K everywhere")
    moist = 1.0 if vapour is None else 1.0 + np.clip(np.asarray(vapour, dtype=np.float64), 0.0, None) / EPSILON
    return p / (R_DRY * t * moist)


def water_content(mixing_ratio: np.ndarray, air_density: np.ndarray) -> np.ndarray:
    """Water content [kg/m³] of a hydrometeor: its mixing ratio [kg per kg of dry air] times the dry-air density
    [kg/m³]. Negative mixing ratios (the small undershoots of a model's advection) count as none."""
    return np.clip(np.asarray(mixing_ratio, dtype=np.float64), 0.0, None) * np.asarray(air_density, np.float64)


def extinction(hydrometeor: Hydrometeor, content: np.ndarray, effective_radius: np.ndarray | None = None,
               number: np.ndarray | None = None) -> np.ndarray:
    """Extinction coefficient [1/m] of ``content`` [kg/m³] of ``hydrometeor``.

    Args:
        hydrometeor: The category and its size distribution.
        content: Water content W [kg/m³] (≥ 0).
        effective_radius: Per-cell effective radius [m] for the effective-radius model (a file's ``RE_CLOUD``,
            say); cells where it is not > 0 take the hydrometeor's own. Ignored for exponential distributions.
        number: Per-cell number concentration N [1/m³] from a two-moment scheme, or None. Where it is > 0 it
            replaces the fixed size: an exponential distribution's slope follows from W and N,
            Λ = (π ρ_p N / W)^(1/3), so β = π N / Λ² = (π N)^(1/3) (W / ρ_p)^(2/3); the effective-radius model's
            particles all take the mean mass, r = (3 W / (4 π ρ_p N))^(1/3), so β = 2 π r² N.

    Returns:
        β [1/m], float64, the shape of ``content``: 3W / (2 ρ_p r_e), or π N0 Λ⁻³ with Λ = (π ρ_p N0 / W)^(1/4),
        or the two-moment forms above where ``number`` is given.
    """
    w = np.clip(np.asarray(content, dtype=np.float64), 0.0, None)
    rho = hydrometeor.particle_density
    if hydrometeor.exponential:
        n0 = hydrometeor.intercept
        # π N0 Λ⁻³ with Λ⁴ = π ρ N0 / W, written in W so that W = 0 gives 0 without a division
        beta = math.pi * n0 * (w / (math.pi * rho * n0)) ** 0.75
    else:
        radius = np.full(w.shape, hydrometeor.effective_radius)
        if effective_radius is not None:
            given = np.broadcast_to(np.asarray(effective_radius, dtype=np.float64), w.shape)
            radius = np.where(np.isfinite(given) & (given > 0.0), given, radius)
        beta = 3.0 * w / (2.0 * rho * radius)
    if number is None:
        return beta
    n = np.broadcast_to(np.nan_to_num(np.asarray(number, dtype=np.float64), nan=0.0), w.shape)
    counted = np.clip(n, 0.0, None)
    if hydrometeor.exponential:
        two_moment = np.cbrt(math.pi * counted) * (w / rho) ** (2.0 / 3.0)
    else:
        two_moment = 2.0 * math.pi * counted ** (1.0 / 3.0) * (3.0 * w / (4.0 * math.pi * rho)) ** (2.0 / 3.0)
    return np.where(n > 0.0, two_moment, beta)


def _hydrometeor(table: dict[str, Hydrometeor], name: str) -> Hydrometeor:
    """``table``'s category ``name``, or a SceneError naming the known ones."""
    if name not in table:
        raise SceneError(f"unknown hydrometeor {name!r}; known: {', '.join(table)}")
    return table[name]


def species_extinction(contents: dict[str, np.ndarray], radii: dict[str, np.ndarray] | None = None,
                       hydrometeors: dict[str, Hydrometeor] | None = None,
                       numbers: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Extinction [1/m] per warpsky species from water contents [kg/m³] per hydrometeor name.

    Hydrometeors rendered as the same species (graupel and snow) add (Riley Eq. 3). Species without any water
    are left out.

    Args:
        contents: Hydrometeor name (a key of ``hydrometeors``) -> water content [kg/m³].
        radii: Hydrometeor name -> per-cell effective radius [m], where the file gives one.
        hydrometeors: The categories (default :data:`HYDROMETEORS`).
        numbers: Hydrometeor name -> per-cell number concentration [1/m³], where a two-moment scheme gives one.
    """
    table = HYDROMETEORS if hydrometeors is None else hydrometeors
    radii, numbers = radii or {}, numbers or {}
    out: dict[str, np.ndarray] = {}
    for name, content in contents.items():
        kind = _hydrometeor(table, name)
        beta = extinction(kind, content, radii.get(name), numbers.get(name))
        out[kind.species] = out[kind.species] + beta if kind.species in out else beta
    return out


def species_water(contents: dict[str, np.ndarray], cell_volume: float,
                  hydrometeors: dict[str, Hydrometeor] | None = None) -> dict[str, tuple[float, float]]:
    """(peak water content [kg/m³], total water [kg]) per warpsky species, from water contents [kg/m³] per
    hydrometeor name on cells of ``cell_volume`` [m³]; hydrometeors rendered as the same species (graupel and snow)
    add, as their extinctions do in :func:`species_extinction`."""
    table = HYDROMETEORS if hydrometeors is None else hydrometeors
    summed: dict[str, np.ndarray] = {}
    for name, content in contents.items():
        species = _hydrometeor(table, name).species
        content = np.asarray(content, dtype=np.float64)
        summed[species] = summed[species] + content if species in summed else content
    return {species: (float(grid.max(initial=0.0)), float(grid.sum() * cell_volume))
            for species, grid in summed.items()}
