"""Analytic phase functions, normalised over the sphere (integral of p dOmega = 1).

``cos_theta`` is the cosine of the scattering angle between the incoming and outgoing propagation directions:
1 is forward scattering, -1 is back scattering. Each model exists as a ``@wp.func`` for kernels and as a numpy
function for host code and tests; both evaluate the same closed form.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.scene.model import PhaseKind

INV_FOUR_PI = 1.0 / (4.0 * math.pi)
RAYLEIGH_NORM = 3.0 / (16.0 * math.pi)
#: Phase-model codes as kernels see them (a medium's ``phase_kind``; codes from ``TABLE_KIND`` up select a table).
PHASE_ISOTROPIC = wp.constant(int(PhaseKind.ISOTROPIC))
PHASE_HG = wp.constant(int(PhaseKind.HG))
PHASE_RAYLEIGH = wp.constant(int(PhaseKind.RAYLEIGH))


@wp.func
def phase_hg(cos_theta: float, g: float) -> float:
    """Henyey-Greenstein phase function [1/sr]."""
    denom = 1.0 + g * g - 2.0 * g * cos_theta
    denom = wp.max(denom, 1.0e-12)
    return INV_FOUR_PI * (1.0 - g * g) / (denom * wp.sqrt(denom))


@wp.func
def phase_rayleigh(cos_theta: float) -> float:
    """Rayleigh phase function 3/(16 pi) (1 + cos^2) [1/sr]."""
    return RAYLEIGH_NORM * (1.0 + cos_theta * cos_theta)


@wp.func
def phase_eval(kind: int, g: float, cos_theta: float) -> float:
    """Evaluate the phase model with code ``kind`` (a :class:`PhaseKind`)."""
    if kind == PHASE_HG:
        return phase_hg(cos_theta, g)
    if kind == PHASE_RAYLEIGH:
        return phase_rayleigh(cos_theta)
    return INV_FOUR_PI


def phase_numpy(kind: PhaseKind, g: float, cos_theta) -> np.ndarray:
    """Host (float64) evaluation of the same phase models."""
    mu = np.asarray(cos_theta, dtype=np.float64)
    if kind == PhaseKind.HG:
        return INV_FOUR_PI * (1.0 - g * g) / (1.0 + g * g - 2.0 * g * mu) ** 1.5
    if kind == PhaseKind.RAYLEIGH:
        return RAYLEIGH_NORM * (1.0 + mu * mu)
    return np.full_like(mu, INV_FOUR_PI)
