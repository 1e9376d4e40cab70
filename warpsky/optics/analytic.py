"""Closed-form phase functions (float64, numpy) for fast paths and for comparison with tabulated Mie.

Every function takes ``mu = cos(theta)`` (theta the scattering angle, 0 forward) and returns p [1/sr] with
integral over the sphere equal to 1.

=================== ====================================================================================
model               formula
=================== ====================================================================================
Rayleigh            3/(16 pi) (1 + mu^2)                                     (Riley 2004, Eq. 1)
Henyey-Greenstein   (1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^(3/2))
two-term HG         w HG(g1) + (1 - w) HG(g2)
Draine              HG(g) (1 + a mu^2) / (1 + a (1 + 2 g^2) / 3)             (Draine 2003)
HG + Draine         (1 - w_D) HG(g_HG) + w_D Draine(g_D, a)                  (Jendersie & d'Eon 2023)
=================== ====================================================================================

Jendersie & d'Eon's fit of Mie scattering by water droplets of diameter d [um], valid for 5 <= d <= 50:
g_HG = exp(-0.0990567 / (d - 1.67154)), g_D = exp(-2.20679 / (d + 3.91029) - 0.428934),
a = exp(3.62489 - 8.29288 / (d + 5.52825)), w_D = exp(-0.599085 / (d - 0.641583) - 0.665888).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError

INV_FOUR_PI = 1.0 / (4.0 * math.pi)


def _check_g(g: float) -> None:
    if not (-1.0 < g < 1.0):
        raise SceneError(f"asymmetry g must lie in (-1, 1), got {g}")


def rayleigh(mu) -> np.ndarray:
    mu = np.asarray(mu, dtype=np.float64)
    return 3.0 / (16.0 * math.pi) * (1.0 + mu * mu)


def henyey_greenstein(mu, g: float) -> np.ndarray:
    _check_g(g)
    mu = np.asarray(mu, dtype=np.float64)
    return INV_FOUR_PI * (1.0 - g * g) / (1.0 + g * g - 2.0 * g * mu) ** 1.5


def two_term_hg(mu, g1: float, g2: float, weight: float) -> np.ndarray:
    """``weight`` x HG(g1) + (1 - weight) x HG(g2); weight in [0, 1]."""
    if not (0.0 <= weight <= 1.0):
        raise SceneError(f"two-term HG weight must lie in [0, 1], got {weight}")
    return weight * henyey_greenstein(mu, g1) + (1.0 - weight) * henyey_greenstein(mu, g2)


def draine(mu, g: float, alpha: float) -> np.ndarray:
    _check_g(g)
    if alpha < 0.0:
        raise SceneError(f"Draine alpha must be >= 0, got {alpha}")
    mu = np.asarray(mu, dtype=np.float64)
    return henyey_greenstein(mu, g) * (1.0 + alpha * mu * mu) / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0)


@dataclass(frozen=True)
class HgDraineParams:
    """Parameters of the HG + Draine mixture."""

    g_hg: float
    g_draine: float
    alpha: float
    w_draine: float


def jendersie_deon_params(diameter_um: float) -> HgDraineParams:
    """Jendersie & d'Eon 2023 fit for water droplets of ``diameter_um`` micrometres (5 to 50)."""
    d = float(diameter_um)
    if not (5.0 <= d <= 50.0):
        raise SceneError(f"the HG+Draine fit covers droplet diameters 5-50 um, got {d:g} um")
    return HgDraineParams(
        g_hg=math.exp(-0.0990567 / (d - 1.67154)),
        g_draine=math.exp(-2.20679 / (d + 3.91029) - 0.428934),
        alpha=math.exp(3.62489 - 8.29288 / (d + 5.52825)),
        w_draine=math.exp(-0.599085 / (d - 0.641583) - 0.665888),
    )


def hg_draine(mu, diameter_um: float) -> np.ndarray:
    """Approximate Mie phase function of water droplets (Jendersie & d'Eon 2023)."""
    params = jendersie_deon_params(diameter_um)
    return (1.0 - params.w_draine) * henyey_greenstein(mu, params.g_hg) + params.w_draine * draine(
        mu, params.g_draine, params.alpha
    )
