"""The storm's environment: a sounding in CM1's ``input_sounding`` format, the Weisman & Klemp (1982) analytic
sounding written by code, and the hydrostatic base state the solver perturbs.

``input_sounding`` (CM1, Bryan & Fritsch 2002): line 1 holds the surface pressure [mb], surface potential
temperature [K] and surface water-vapour mixing ratio [g/kg]; every further line one level: height above ground [m],
potential temperature [K], vapour mixing ratio [g/kg], wind u and v [m/s]. The solver's world is warpsky's: +y up,
the sounding's u blows along +x and its v along +z.

Weisman & Klemp (1982, Mon. Wea. Rev. 110, 504), their eqs. (1)-(3):

- θ(z) = θ0 + (θ_tr - θ0) (z / z_tr)^(5/4) below the tropopause z_tr = 12 km, θ_tr exp(g (z - z_tr) / (c_p T_tr))
  above it; θ0 = 300 K, θ_tr = 343 K, T_tr = 213 K;
- relative humidity 1 - 0.75 (z / z_tr)^(5/4) below z_tr, 0.25 above, the vapour capped at 14 g/kg (their moist
  boundary layer);
- u(z) = U_s tanh(z / z_s), z_s = 3 km (their unidirectional shear; U_s = 15 m/s here).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.core.files import atomic_write

GRAVITY = 9.81  # [m/s^2]
R_DRY = 287.04  # [J/(kg K)] gas constant of dry air
R_VAPOUR = 461.5  # [J/(kg K)]
CP_DRY = 1005.7  # [J/(kg K)] isobaric heat capacity of dry air
LATENT_VAPOURISATION = 2.501e6  # [J/kg] at 0 C
P_REFERENCE = 1.0e5  # [Pa] of the Exner function and potential temperature
EPSILON = R_DRY / R_VAPOUR  # ratio of the gas constants (0.622)
KAPPA = R_DRY / CP_DRY


def saturation_pressure(temperature):
    """Saturation vapour pressure over liquid water [Pa] at ``temperature`` [K] (Bolton 1980, eq. 10)."""
    celsius = np.asarray(temperature, dtype=np.float64) - 273.15
    return 611.2 * np.exp(17.67 * celsius / (celsius + 243.5))


def saturation_mixing_ratio(temperature, pressure):
    """Saturation vapour mixing ratio [kg/kg] over liquid water at ``temperature`` [K] and ``pressure`` [Pa]."""
    es = saturation_pressure(temperature)
    return EPSILON * es / np.maximum(np.asarray(pressure, dtype=np.float64) - es, 1.0)


def virtual_factor(vapour):
    """θ_v / θ of moist air with ``vapour`` mixing ratio [kg/kg]: (1 + q_v / ε) / (1 + q_v)."""
    return (1.0 + np.asarray(vapour) / EPSILON) / (1.0 + np.asarray(vapour))


@dataclass(frozen=True)
class Sounding:
    """A column of the environment, as ``input_sounding`` holds it (SI units here).

    ========================= ====== ====================================================
    name                      unit   meaning
    ========================= ====== ====================================================
    surface_pressure          Pa     pressure at z = 0
    surface_theta             K      potential temperature at z = 0
    surface_vapour            kg/kg  vapour mixing ratio at z = 0
    height                    m      levels above ground, increasing
    theta, vapour             K, -   potential temperature and vapour mixing ratio there
    wind_u, wind_v            m/s    wind along +x and +z (warpsky's horizontal axes)
    ========================= ====== ====================================================
    """

    surface_pressure: float
    surface_theta: float
    surface_vapour: float
    height: np.ndarray
    theta: np.ndarray
    vapour: np.ndarray
    wind_u: np.ndarray
    wind_v: np.ndarray

    def at(self, height) -> dict[str, np.ndarray]:
        """θ, q_v, u, v linearly interpolated to ``height`` [m] (the surface values below the first level, the top
        level's above the last)."""
        z = np.concatenate([[0.0], self.height]) if self.height[0] > 0.0 else self.height
        surface = self.height[0] > 0.0

        def column(values, at_surface):
            values = np.concatenate([[at_surface], values]) if surface else values
            return np.interp(height, z, values)

        return {"theta": column(self.theta, self.surface_theta),
                "vapour": column(self.vapour, self.surface_vapour),
                "wind_u": column(self.wind_u, self.wind_u[0]), "wind_v": column(self.wind_v, self.wind_v[0])}


def weisman_klemp(*, shear: float = 15.0, shear_depth: float = 3000.0, top: float = 20000.0,
                  spacing: float = 100.0) -> Sounding:
    """The Weisman & Klemp (1982) sounding (module docstring) from 0 to ``top`` [m] every ``spacing`` [m], with
    wind u = ``shear`` tanh(z / ``shear_depth``) [m/s]."""
    z_tr, theta_0, theta_tr, t_tr = 12000.0, 300.0, 343.0, 213.0
    z = np.arange(0.0, top + 0.5 * spacing, spacing)
    below = z <= z_tr
    theta = np.where(below, theta_0 + (theta_tr - theta_0) * (np.minimum(z, z_tr) / z_tr) ** 1.25,
                     theta_tr * np.exp(GRAVITY * (z - z_tr) / (CP_DRY * t_tr)))
    humidity = np.where(below, 1.0 - 0.75 * (np.minimum(z, z_tr) / z_tr) ** 1.25, 0.25)
    vapour = np.zeros_like(z)
    for _ in range(4):  # the vapour changes the pressure profile a little: iterate to a fixed point
        exner = hydrostatic_exner(z, theta, vapour, P_REFERENCE)
        pressure = P_REFERENCE * exner ** (1.0 / KAPPA)
        vapour = np.minimum(humidity * saturation_mixing_ratio(theta * exner, pressure), 0.014)
    wind = shear * np.tanh(z / shear_depth)
    return Sounding(P_REFERENCE, theta[0], vapour[0], z[1:], theta[1:], vapour[1:], wind[1:], np.zeros_like(z[1:]))


def hydrostatic_exner(height: np.ndarray, theta: np.ndarray, vapour: np.ndarray, surface_pressure: float,
                      *, substeps: int = 8) -> np.ndarray:
    """Exner function (p / p0)^(R/c_p) at ``height`` [m] (increasing, from the surface) of the column in
    hydrostatic balance dπ/dz = -g / (c_p θ_v), θ and q_v linear between the levels (midpoint rule on ``substeps``
    pieces of each interval)."""
    exner = np.empty_like(height, dtype=np.float64)
    exner[0] = (surface_pressure / P_REFERENCE) ** KAPPA
    theta_v = theta * virtual_factor(vapour)
    for n in range(1, len(height)):
        s = (np.arange(substeps) + 0.5) / substeps
        tv = theta_v[n - 1] + (theta_v[n] - theta_v[n - 1]) * s
        exner[n] = exner[n - 1] - GRAVITY / CP_DRY * np.sum(1.0 / tv) * (height[n] - height[n - 1]) / substeps
    if np.any(exner <= 0.0):
        raise UsageError("the sounding reaches zero pressure below its top (is θ in K and z in m?)")
    return exner


def write_sounding(path: str | Path, sounding: Sounding) -> Path:
    """Write ``sounding`` as CM1's ``input_sounding`` text file at ``path`` (atomically)."""
    lines = [f"{sounding.surface_pressure / 100.0:10.3f} {sounding.surface_theta:10.4f} "
             f"{sounding.surface_vapour * 1000.0:10.5f}"]
    for z, th, qv, u, v in zip(sounding.height, sounding.theta, sounding.vapour, sounding.wind_u, sounding.wind_v,
                               strict=True):
        lines.append(f"{z:10.2f} {th:10.4f} {qv * 1000.0:10.5f} {u:9.4f} {v:9.4f}")
    text = "\n".join(lines) + "\n"
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def read_sounding(path: str | Path) -> Sounding:
    """Read a CM1 ``input_sounding`` file (module docstring); a ``UsageError`` names the file, line and problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise UsageError(f"--sounding {path}: cannot read it ({exc.strerror or exc})") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            raise UsageError(f"{path}:{number}: expected numbers, got {line.strip()!r}") from None
        expected = 3 if not rows else 5
        if len(values) != expected:
            raise UsageError(f"{path}:{number}: expected {expected} numbers ("
                             + ("surface pressure [mb], θ [K], q_v [g/kg]" if not rows else
                                "z [m], θ [K], q_v [g/kg], u [m/s], v [m/s]") + f"), got {len(values)}")
        rows.append((number, values))
    if len(rows) < 3:
        raise UsageError(f"{path}: a sounding needs its surface line and at least two levels")
    (_, (p_mb, theta_s, qv_s)), levels = rows[0], np.array([v for _, v in rows[1:]], dtype=np.float64)
    if not 100.0 <= p_mb <= 1100.0:
        raise UsageError(f"{path}:{rows[0][0]}: surface pressure must be in mb (100-1100), got {p_mb:g}")
    if not 150.0 <= theta_s <= 600.0 or np.any(levels[:, 1] < 150.0):
        raise UsageError(f"{path}: potential temperatures must be in K (150-600 at the surface and above 150)")
    if np.any(np.diff(levels[:, 0]) <= 0.0) or levels[0, 0] < 0.0:
        bad = rows[1 + int(np.argmax(np.diff(levels[:, 0]) <= 0.0)) + 1][0] if levels[0, 0] >= 0.0 else rows[1][0]
        raise UsageError(f"{path}:{bad}: heights must increase from the ground up")
    if qv_s < 0.0 or np.any(levels[:, 2] < 0.0):
        raise UsageError(f"{path}: vapour mixing ratios must be >= 0 g/kg")
    return Sounding(p_mb * 100.0, theta_s, qv_s / 1000.0, levels[:, 0], levels[:, 1], levels[:, 2] / 1000.0,
                    levels[:, 3], levels[:, 4])


@dataclass(frozen=True)
class BaseState:
    """The hydrostatic environment on the solver's levels (cell centres, and the ``face`` arrays at the levels'
    boundaries, one more): θ [K], q_v [kg/kg], Exner π, pressure [Pa], density ρ [kg/m^3], wind [m/s]."""

    theta: np.ndarray
    vapour: np.ndarray
    exner: np.ndarray
    pressure: np.ndarray
    density: np.ndarray
    density_face: np.ndarray
    wind_u: np.ndarray
    wind_v: np.ndarray

    @property
    def temperature(self) -> np.ndarray:
        return self.theta * self.exner


def base_state(sounding: Sounding, levels: int, spacing: float) -> BaseState:
    """The sounding on ``levels`` cells of ``spacing`` [m] from the ground: centres at (j + ½) spacing."""
    fine = np.linspace(0.0, levels * spacing, 8 * levels + 1)  # faces every 8th point, centres every 8th + 4
    column = sounding.at(fine)
    exner = hydrostatic_exner(fine, column["theta"], column["vapour"], sounding.surface_pressure)
    pressure = P_REFERENCE * exner ** (1.0 / KAPPA)
    density = pressure / (R_DRY * column["theta"] * exner * virtual_factor(column["vapour"]))
    centres = slice(4, None, 8)
    return BaseState(column["theta"][centres], column["vapour"][centres], exner[centres], pressure[centres],
                     density[centres], density[::8], column["wind_u"][centres], column["wind_v"][centres])
