"""Bouthors, Neyret & Lefebvre 2006, Appendix A: the 1D reflectance/transmittance model of a stratiform slab, with
Appendix B's fitted parameters (host side, float64 numpy; the kernels in :mod:`.kernels` mirror it in float32).

Thickness is measured in *reference metres*: the geometric thickness of a slab of Bouthors' droplets
(N0 = 300 cm^-3, γ = 2, r_e = 7 µm, κ = 0.0462 /m) with the same optical depth. A layer with other droplets maps its
thickness by ``H_ref = H κ / κ_ref`` (:func:`reference_thickness`), so the fits keep their meaning.

Quantities, all energies per unit incident flux (the sun's irradiance times μ_l):

============ ======================================================================================================
T_ms(H)      (b + (1 - b) e^{-cH}) β / (H - (H - 1) β), β = 0.9961; clamped to [0, 1] (b > 1 at small θ_l lifts
             the fit above 1 by < 3e-3 below a few metres); R_ms = 1 - T_ms (albedo 1: nothing is absorbed)
T_0(H)       τ_S(H_l) = exp(-κ_S H / μ_l): light that met no S event (the direct beam and its F* aureole)
T_1, R_1     t H s_c(H) and r (1 - τ_c(2H)) / 2 with τ_c(x) = e^{-κ_c x}, s_c = κ_c τ_c
T_2, R_2     T_2a + T_2b = (κ_c t H)^2 τ_c(H) / 2 + r^2 (1 + (2Hκ_c - 1) τ_c(2H)) τ_c(3H) / 4 and
             r t (1 - (2Hκ_c + 1) τ_c(2H)) / 2
T_3+, R_3+   T_ms - T_0 - T_1 - T_2 and R_ms - R_1 - R_2, where the fitted low orders would exceed the total
             (thin slabs, grazing sun) they are scaled down to it: no order adds energy and R + T = 1 exactly
============ ======================================================================================================

b, c, κ_c, t, r depend on θ_l (Appendix B, every 10°) and are interpolated linearly in θ_l [deg].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: β = T_ms(1 m) (Appendix B).
BETA = 0.9961
#: Extinction coefficient of Bouthors' droplets, N0 σ with σ = π r_e² [1/m] (r_e = 7 µm, N0 = 3e8 m^-3).
KAPPA_REFERENCE = 3.0e8 * np.pi * (7.0e-6) ** 2
#: Appendix B, one row per θ_l = 0, 10, ..., 90 deg: b, c [1/m], κ_c [1/m], t, r.
APPENDIX_B = np.array([
    [1.1796, 0.0138, 0.0265, 0.8389, 0.0547],
    [1.1293, 0.0154, 0.0262, 0.8412, 0.0547],
    [1.1382, 0.0131, 0.0272, 0.8334, 0.0552],
    [1.0953, 0.0049, 0.0294, 0.8208, 0.0564],
    [0.9808, 0.0012, 0.0326, 0.8010, 0.0603],
    [0.9077, 0.0047, 0.0379, 0.7774, 0.0705],
    [0.7987, 0.0207, 0.0471, 0.7506, 0.0984],
    [0.6629, 0.0133, 0.0616, 0.7165, 0.1700],
    [0.5043, 0.0280, 0.0700, 0.7149, 0.3554],
    [0.3021, 0.0783, 0.0700, 0.1000, 0.9500],
])
APPENDIX_B_ANGLES_DEG = np.arange(0.0, 91.0, 10.0)


@dataclass(frozen=True)
class SlabParameters:
    """Appendix B's θ_l-dependent fits at one or more sun angles (arrays broadcast with θ_l)."""

    b: np.ndarray
    c: np.ndarray
    kappa_c: np.ndarray
    t: np.ndarray
    r: np.ndarray


def parameters(theta_l_deg) -> SlabParameters:
    """Appendix B interpolated linearly at ``theta_l_deg`` (clamped to [0, 90])."""
    theta = np.clip(np.asarray(theta_l_deg, dtype=np.float64), 0.0, 90.0)
    cols = [np.interp(theta, APPENDIX_B_ANGLES_DEG, APPENDIX_B[:, k]) for k in range(5)]
    return SlabParameters(*cols)


def reference_thickness(thickness, extinction) -> np.ndarray:
    """Thickness [m] of a slab of extinction ``extinction`` [1/m] in reference metres (same optical depth)."""
    return np.asarray(thickness, dtype=np.float64) * (np.asarray(extinction, dtype=np.float64) / KAPPA_REFERENCE)


def transmittance_ms(h, theta_l_deg) -> np.ndarray:
    """T_ms(H): total (all orders) transmitted energy of a slab of ``h`` reference metres."""
    h = np.maximum(np.asarray(h, dtype=np.float64), 0.0)
    p = parameters(theta_l_deg)
    isotropic = BETA / (BETA + h * (1.0 - BETA))  # = β / (H - (H - 1) β), no cancellation
    return np.clip((p.b + (1.0 - p.b) * np.exp(-p.c * h)) * isotropic, 0.0, 1.0)


def reflectance_ms(h, theta_l_deg) -> np.ndarray:
    """R_ms(H) = 1 - T_ms(H)."""
    return 1.0 - transmittance_ms(h, theta_l_deg)


@dataclass(frozen=True)
class OrderEnergies:
    """Transmitted and reflected energy per scattering order of the modified-Mie model (Appendix A).

    ``t0..t3p`` sum to ``t_ms`` and ``r1..r3p`` to ``r_ms``; every entry is >= 0.
    """

    t0: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    t3p: np.ndarray
    r1: np.ndarray
    r2: np.ndarray
    r3p: np.ndarray
    t_ms: np.ndarray
    r_ms: np.ndarray


def _split(total, parts):
    """Scale ``parts`` down where their sum exceeds ``total``; return (parts, total - sum >= 0)."""
    low = sum(parts)
    scale = np.where(low > total, total / np.where(low > 0.0, low, 1.0), 1.0)
    parts = [p * scale for p in parts]
    return parts, np.maximum(total - sum(parts), 0.0)


def order_energies(h, theta_l_deg, kappa_s: float) -> OrderEnergies:
    """Appendix A per order for ``h`` reference metres at sun zenith ``theta_l_deg``.

    ``kappa_s`` is the modified-Mie extinction κ_S = (1 - P_f) κ in reference units [1/reference m] (used by T_0).
    """
    h = np.maximum(np.asarray(h, dtype=np.float64), 0.0)
    theta = np.asarray(theta_l_deg, dtype=np.float64)
    p = parameters(theta)
    mu_l = np.maximum(np.cos(np.radians(np.clip(theta, 0.0, 90.0))), 1e-9)
    k = p.kappa_c
    tau1, tau2, tau3 = np.exp(-k * h), np.exp(-2.0 * k * h), np.exp(-3.0 * k * h)
    t0 = np.exp(-kappa_s * h / mu_l)
    t1 = p.t * h * k * tau1
    t2 = 0.5 * (k * p.t * h) ** 2 * tau1 + 0.25 * p.r**2 * (1.0 + (2.0 * h * k - 1.0) * tau2) * tau3
    r1 = 0.5 * p.r * -np.expm1(-2.0 * k * h)
    # 1 - (1 + x) e^-x without cancellation for small x = 2Hκ_c
    x = 2.0 * k * h
    one_minus = np.where(x < 1e-3, x * x * (0.5 - x / 3.0), 1.0 - (1.0 + x) * tau2)
    r2 = 0.5 * p.r * p.t * one_minus
    t_ms = transmittance_ms(h, theta)
    r_ms = 1.0 - t_ms
    (t0, t1, t2), t3p = _split(t_ms, [t0, t1, t2])
    (r1, r2), r3p = _split(r_ms, [r1, r2])
    return OrderEnergies(t0, t1, t2, t3p, r1, r2, r3p, t_ms, r_ms)
