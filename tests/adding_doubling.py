"""An independent plane-parallel reference: the adding-doubling method (van de Hulst 1980; Prahl 1995) for a
homogeneous slab lit by a collimated beam, azimuthally symmetric (normal incidence), in numpy float64.

Radiance vectors live on Gauss-Legendre nodes in mu (0, 1]; the collimated direction and the directions where
radiance is wanted are added as nodes of vanishing weight (1e-9), which leaves the angular integrals unchanged and
lets the beam enter as radiance E / (2 pi w). A layer of optical thickness tau / 2^k is taken to first order in
single scattering (error O(tau / 2^k)), then doubled k times:

    T2 = T (1 - R R)^-1 T,    R2 = R + T (1 - R R)^-1 R T.
"""

from __future__ import annotations

import numpy as np


def azimuth_kernel(phase, mu_out: np.ndarray, mu_in: np.ndarray, same_hemisphere: bool, count: int = 720):
    """h(mu_out, mu_in) = integral over azimuth of p(cos Theta): scattering from a direction of cosine mu_in
    into mu_out, both measured from the layer normal in their own hemispheres."""
    phi = (np.arange(count) + 0.5) * 2 * np.pi / count
    a = mu_out[:, None, None] * mu_in[None, :, None] * (1.0 if same_hemisphere else -1.0)
    b = np.sqrt(1 - mu_out**2)[:, None, None] * np.sqrt(1 - mu_in**2)[None, :, None] * np.cos(phi)[None, None, :]
    return phase(np.clip(a + b, -1.0, 1.0)).sum(axis=-1) * (2 * np.pi / count)


def slab_radiance(phase, tau: float, albedo: float, view_mu, *, nodes: int = 64, doublings: int = 24):
    """(reflected, diffusely transmitted) radiance per unit beam irradiance at the view cosines, for a beam at
    normal incidence."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    extra = np.concatenate([[1.0], np.atleast_1d(np.asarray(view_mu, dtype=np.float64))])
    mu = np.concatenate([0.5 * (x + 1.0), extra])
    weight = np.concatenate([0.5 * w, np.full(len(extra), 1e-9)])
    delta = tau / 2.0**doublings
    back = azimuth_kernel(phase, mu, mu, same_hemisphere=False)
    forward = azimuth_kernel(phase, mu, mu, same_hemisphere=True)
    r = albedo * delta / mu[:, None] * back * weight[None, :]
    t = np.diag(np.exp(-delta / mu)) + albedo * delta / mu[:, None] * forward * weight[None, :]
    eye = np.eye(len(mu))
    for _ in range(doublings):
        inverse = np.linalg.solve(eye - r @ r, t)
        r, t = r + t @ r @ inverse, t @ inverse
    beam = np.zeros(len(mu))
    beam[nodes] = 1.0 / (2 * np.pi * weight[nodes])  # E = 1 along mu = 1
    reflected, transmitted = r @ beam, t @ beam
    return reflected[nodes + 1 :], transmitted[nodes + 1 :]


def _layer(phase, tau: float, albedo: float, mu: np.ndarray, weight: np.ndarray, doublings: int):
    """(R, T) of one homogeneous layer on the nodes ``mu`` (see :func:`slab_radiance`)."""
    doublings = max(int(np.ceil(np.log2(max(tau, 1e-30) / 1e-7))), 1) if doublings is None else doublings
    delta = tau / 2.0**doublings
    back = azimuth_kernel(phase, mu, mu, same_hemisphere=False)
    forward = azimuth_kernel(phase, mu, mu, same_hemisphere=True)
    r = albedo * delta / mu[:, None] * back * weight[None, :]
    t = np.diag(np.exp(-delta / mu)) + albedo * delta / mu[:, None] * forward * weight[None, :]
    eye = np.eye(len(mu))
    for _ in range(doublings):
        inverse = np.linalg.solve(eye - r @ r, t)
        r, t = r + t @ r @ inverse, t @ inverse
    return r, t


def stack_radiance(layers, view_mu, *, nodes: int = 64, doublings=None):
    """Diffusely transmitted radiance at the bottom of a stack of homogeneous layers (top first), each
    ``(phase, tau, albedo)``, per unit beam irradiance at normal incidence, at the view cosines: each layer's R and
    T by doubling, then added top down, R = R1 + T1 R2 (1 - R1 R2)^-1 T1, T = T2 (1 - R1 R2)^-1 T1 (homogeneous
    layers reflect alike from both sides)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    extra = np.concatenate([[1.0], np.atleast_1d(np.asarray(view_mu, dtype=np.float64))])
    mu = np.concatenate([0.5 * (x + 1.0), extra])
    weight = np.concatenate([0.5 * w, np.full(len(extra), 1e-9)])
    eye = np.eye(len(mu))
    r_total, t_total = None, None
    for phase, tau, albedo in layers:
        r, t = _layer(phase, tau, albedo, mu, weight, doublings)
        if r_total is None:
            r_total, t_total = r, t
            continue
        inverse = np.linalg.solve(eye - r_total @ r, t_total)
        # seen from above the new layer's top: the stack so far on top of it
        r_total, t_total = r_total + t_total @ r @ inverse, t @ inverse
    beam = np.zeros(len(mu))
    beam[nodes] = 1.0 / (2 * np.pi * weight[nodes])
    return (t_total @ beam)[nodes + 1 :]


def ground_reflected_radiance(phase, tau: float, albedo: float, ground_albedo: float, view_mu: float) -> float:
    """Radiance leaving the top of a homogeneous slab over a Lambertian ground, per unit beam irradiance at normal
    incidence, by adding-doubling: the slab's R and T on Gauss nodes, the ground as the
    operator L_i = 2 a sum_j w_j mu_j L_j, added: R + T G (1 - R G)^-1 T."""
    x, w = np.polynomial.legendre.leggauss(64)
    mu = np.concatenate([0.5 * (x + 1.0), [1.0, view_mu]])
    weight = np.concatenate([0.5 * w, [1e-9, 1e-9]])
    r, t = _layer(phase, tau, albedo, mu, weight, None)
    ground = 2.0 * ground_albedo * np.tile(weight * mu, (len(mu), 1))
    beam = np.zeros(len(mu))
    beam[64] = 1.0 / (2 * np.pi * weight[64])
    down = t @ beam
    up = np.linalg.solve(np.eye(len(mu)) - ground @ r, ground @ down)
    return float((r @ beam + t @ up)[65])
