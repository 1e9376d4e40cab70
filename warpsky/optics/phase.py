"""Analytic phase functions, normalised over the sphere (integral of p dOmega = 1).

``cos_theta`` is the cosine of the scattering angle between the incoming and outgoing propagation directions:
1 is forward scattering, -1 is back scattering. Each model keeps its evaluation, its sampling (cos θ from a uniform
number) and that sampling's density together, as ``@wp.func`` for kernels; :func:`phase_numpy` evaluates the same
closed forms on the host for host code and tests.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.model.scene import PhaseKind

INV_FOUR_PI = 1.0 / (4.0 * math.pi)
RAYLEIGH_NORM = 3.0 / (16.0 * math.pi)
#: Phase-model codes as kernels see them (a medium's ``phase_kind``; codes from ``TABLE_KIND`` up select a table).
PHASE_ISOTROPIC = wp.constant(int(PhaseKind.ISOTROPIC))
PHASE_HG = wp.constant(int(PhaseKind.HG))
PHASE_RAYLEIGH = wp.constant(int(PhaseKind.RAYLEIGH))


# Isotropic: p = 1 / (4 pi), sampled exactly by cos θ uniform in [-1, 1].


@wp.func
def isotropic_sample_cos(u: float) -> float:
    """cos θ of an isotropic sample from the uniform number ``u`` in [0, 1)."""
    return 1.0 - 2.0 * u


@wp.func
def isotropic_pdf(cos_theta: float) -> float:
    """Density [1/sr] of :func:`isotropic_sample_cos`: 1 / (4 pi) whatever ``cos_theta``."""
    return INV_FOUR_PI


# Henyey–Greenstein: sampled exactly by inverting its cumulative distribution in cos θ.


@wp.func
def phase_hg(cos_theta: float, g: float) -> float:
    """Henyey-Greenstein phase function [1/sr]."""
    denom = 1.0 + g * g - 2.0 * g * cos_theta
    denom = wp.max(denom, 1.0e-12)
    return INV_FOUR_PI * (1.0 - g * g) / (denom * wp.sqrt(denom))


@wp.func
def hg_sample_cos(g: float, u: float) -> float:
    """cos θ of a Henyey–Greenstein sample (exact inversion; isotropic for |g| < 1e-4)."""
    if wp.abs(g) < 1.0e-4:
        return isotropic_sample_cos(u)
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return wp.clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


@wp.func
def hg_pdf(cos_theta: float, g: float) -> float:
    """Density [1/sr] of :func:`hg_sample_cos`: the phase itself (the inversion is exact)."""
    return phase_hg(cos_theta, g)


# Rayleigh: sampled like the isotropic phase; the sample's weight p / pdf carries its shape.


@wp.func
def phase_rayleigh(cos_theta: float) -> float:
    """Rayleigh phase function 3/(16 pi) (1 + cos^2) [1/sr]."""
    return RAYLEIGH_NORM * (1.0 + cos_theta * cos_theta)


@wp.func
def rayleigh_sample_cos(u: float) -> float:
    """cos θ of a Rayleigh sample: uniform over the sphere."""
    return isotropic_sample_cos(u)


@wp.func
def rayleigh_pdf(cos_theta: float) -> float:
    """Density [1/sr] of :func:`rayleigh_sample_cos`: 1 / (4 pi)."""
    return isotropic_pdf(cos_theta)


# Any analytic model by its code.


@wp.func
def phase_eval(kind: int, g: float, cos_theta: float) -> float:
    """Evaluate the phase model with code ``kind`` (a :class:`PhaseKind`) [1/sr]."""
    if kind == PHASE_HG:
        return phase_hg(cos_theta, g)
    if kind == PHASE_RAYLEIGH:
        return phase_rayleigh(cos_theta)
    return INV_FOUR_PI


@wp.func
def phase_sample_cos(kind: int, g: float, u: float) -> float:
    """cos θ of a sample of the phase model with code ``kind`` from the uniform number ``u``."""
    if kind == PHASE_HG:
        return hg_sample_cos(g, u)
    if kind == PHASE_RAYLEIGH:
        return rayleigh_sample_cos(u)
    return isotropic_sample_cos(u)


@wp.func
def phase_pdf(kind: int, g: float, cos_theta: float) -> float:
    """Density [1/sr] with which :func:`phase_sample_cos` returns ``cos_theta`` for the model with code ``kind``."""
    if kind == PHASE_HG:
        return hg_pdf(cos_theta, g)
    if kind == PHASE_RAYLEIGH:
        return rayleigh_pdf(cos_theta)
    return isotropic_pdf(cos_theta)


def phase_numpy(kind: PhaseKind, g: float, cos_theta) -> np.ndarray:
    """Host (float64) evaluation of the same phase models."""
    mu = np.asarray(cos_theta, dtype=np.float64)
    if kind == PhaseKind.HG:
        return INV_FOUR_PI * (1.0 - g * g) / (1.0 + g * g - 2.0 * g * mu) ** 1.5
    if kind == PhaseKind.RAYLEIGH:
        return RAYLEIGH_NORM * (1.0 + mu * mu)
    return np.full_like(mu, INV_FOUR_PI)
