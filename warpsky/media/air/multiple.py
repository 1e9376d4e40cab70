"""The table of the air's multiple scattering, built on the host in float64 (see
:mod:`warpsky.media.air.multiple_kernels`
for what it holds and how the sky uses it): the single-scattering field on 48 altitudes x 2 x 96 directions, its
isotropic mean and the Rayleigh quadrupole of the second order, then the isotropic orders >= 2 over altitude as one
linear system per channel, for Riley's Rayleigh gas alone or with aerosols and ozone
(:mod:`~warpsky.media.air.mixture`)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from warpsky.media.air.mixture import (
    constituents,
    depth_parts,
    hg,
    points_along,
    scatter_parts,
    sun_transmittance,
)
from warpsky.media.air.mixture import transmittance as air_transmittance

#: Table nodes over altitude: h = floor + TOP_SCALE_HEIGHTS H u^2, u uniform in [0, 1].
NODES = 48
#: The table reaches this many scale heights above the floor (air density e^-12 of the floor's); above, Psi is the
#: top node's.
TOP_SCALE_HEIGHTS = 12.0
#: Gauss-Legendre nodes per half sphere (in u = sqrt(|mu|)) of the sphere integrals.
DIRECTIONS = 96
#: Gauss-Legendre nodes of the integral along a view ray (per channel, in s = 1 - T).
RAY_NODES = 8
#: The same for the rays of the table's own build.
BUILD_RAY_NODES = 16


@dataclass(frozen=True)
class MultipleTable:
    """Psi at the table's altitude nodes, per unit sun irradiance, RGB [1/sr].

    Attributes:
        values: (NODES, 3) Psi at h = floor + height u^2, u = linspace(0, 1, NODES).
        quadrupole: (NODES, 3, 3) what Rayleigh's phase adds to the second order (:func:`second_order_quadrupole`):
            node, term q_0..q_2, channel.
        aerosol: (NODES, 5, 3) what the aerosols' phase adds to the second order (:func:`aerosol_terms`): the
            coefficients of the quadrupole weights (3) and the dipole weights (2, :func:`dipole_weights`).
        floor: Altitude [m above sea level] of the floor (the ground plane, else sea level).
        height: Altitude span [m] of the nodes above the floor.
        seconds: Build time.
    """

    values: np.ndarray
    quadrupole: np.ndarray
    floor: float
    height: float
    seconds: float
    aerosol: np.ndarray | None = None

    def at(self, altitude, angular=None, *, aerosol: bool = False) -> np.ndarray:
        """Psi at ``altitude`` (array, m above sea level), linear in u, plus with ``angular`` (broadcasting
        (..., 5): :func:`quadrupole_weights` then :func:`dipole_weights`) the second order's anisotropic part
        towards that view, the Rayleigh gas's or with ``aerosol`` the aerosols'; (..., 3)."""
        i, f = _interpolation(np.asarray(altitude, dtype=np.float64), self.floor, self.height)
        w = f[..., None]
        out = self.values[i] * (1.0 - w) + self.values[i + 1] * w
        if angular is not None:
            angular = np.asarray(angular, dtype=np.float64)
            terms = self.quadrupole if not aerosol else self.aerosol
            weights = angular[..., :3] if not aerosol else angular
            if terms is not None:
                q = terms[i] * (1.0 - w[..., None]) + terms[i + 1] * w[..., None]
                out = out + np.einsum("...mc,...m->...c", q, weights)
        return out


def _half_sphere(count: int) -> tuple[np.ndarray, np.ndarray]:
    """(mu, weight) on (0, 1] for int_0^1 f(mu) dmu by Gauss-Legendre in u = sqrt(mu)."""
    x, w = np.polynomial.legendre.leggauss(count)
    u = 0.5 * (x + 1.0)
    return u * u, w * u  # dmu = 2 u du, du = dx / 2


def azimuthal_rayleigh(mu, sun_y: float) -> np.ndarray:
    """Rayleigh's phase averaged over the azimuth of a direction of elevation sine ``mu`` about the vertical, for
    the sun at elevation sine ``sun_y`` [1/sr]: 3 / (16 pi) (1 + mu^2 l^2 + (1 - mu^2)(1 - l^2) / 2)."""
    mu = np.asarray(mu, dtype=np.float64)
    return 3.0 / (16.0 * math.pi) * (1.0 + mu * mu * sun_y * sun_y + 0.5 * (1.0 - mu * mu) * (1.0 - sun_y * sun_y))


def azimuthal_hg(mu, sun_y: float, g: float, order: int = 0, count: int = 96) -> np.ndarray:
    """The Henyey-Greenstein phase's azimuthal Fourier coefficient of ``order`` about the vertical for a direction
    of elevation sine ``mu`` and the sun at elevation sine ``sun_y``: the mean over the azimuth (order 0), else
    (1 / pi) int_0^{2 pi} p cos(order phi) dphi, so p = sum_m p^(m) cos(m phi); Gauss-Legendre over phi in [0, pi]."""
    mu = np.asarray(mu, dtype=np.float64)
    x, w = np.polynomial.legendre.leggauss(count)
    phi = 0.5 * math.pi * (x + 1.0)
    b = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))[..., None] * math.sqrt(max(1.0 - sun_y * sun_y, 0.0))
    values = hg(mu[..., None] * sun_y + b * np.cos(phi), g) * np.cos(order * phi)
    mean = 0.5 * (values * w).sum(axis=-1)  # (1 / pi) int_0^pi
    return mean if order == 0 else 2.0 * mean


def _single_field(atm, h, view, air_sine: float, distance, sun_y: float):
    """(I_R, I_M or None, L_1 without the floor) on the build's rays, (NODES, D, 3) each."""
    parts = scatter_parts(atm, h, view, air_sine, distance)
    field = azimuthal_rayleigh(view, sun_y)[..., None] * parts[0]
    mie = parts[1] if len(parts) > 1 else None
    if mie is not None:
        field = field + azimuthal_hg(view, sun_y, atm.mie_g)[..., None] * mie
    return parts[0], mie, field


def build(atm, floor: float, albedo, sun_y: float, air_sine: float) -> MultipleTable:
    """The table for the air ``atm`` (:class:`~warpsky.model.scene.Atmosphere`) over a Lambertian floor of
    ``albedo`` (RGB) at ``floor`` [m above sea level], lit by a sun of elevation sine ``sun_y`` (its direction) and
    ``air_sine`` (its air mass, :func:`~warpsky.media.air.analytic.air_sine`)."""
    import time

    started = time.perf_counter()
    albedo = np.asarray(albedo, dtype=np.float64)[None, None, :]
    height = TOP_SCALE_HEIGHTS * atm.scale_height
    h = node_heights(floor, height)[:, None]
    mu, weight = _half_sphere(DIRECTIONS)
    up, down = np.broadcast_to(mu[None, :], (NODES, len(mu))), np.broadcast_to(-mu[None, :], (NODES, len(mu)))
    w = weight[None, :, None]
    # up: the air to infinity; down: the air to the floor, then the floor
    i_up, mie_up, l1_up = _single_field(atm, h, up, air_sine, np.inf, sun_y)
    distance = (h - floor) / mu[None, :]
    t_down = air_transmittance(atm, h, down, distance)
    i_down, mie_down, l1_down = _single_field(atm, h, down, air_sine, distance, sun_y)
    quadrupole = second_order_quadrupole((i_up, mie_up, l1_up), (i_down, mie_down, l1_down), mu, weight, sun_y,
                                         atm.mie_g)
    t_sun_floor = sun_transmittance(atm, np.asarray(floor), air_sine)[None, None, :]
    l1_down = l1_down + t_down * albedo / math.pi * max(sun_y, 0.0) * t_sun_floor
    aerosol = (aerosol_terms((i_up, mie_up, l1_up), (i_down, mie_down, l1_down), mu, weight, sun_y, atm.mie_g)
               if mie_up is not None else None)
    # orders >= 2 (isotropic in-scattering): J_2 is the mean of the single-scattering field L_1 (sunlit floor
    # included), R_2 the floor lit by the single-scattering sky; then x_{n+1} = M x_n, Psi = sum_n J_n
    a1 = 0.5 * ((l1_up * w).sum(axis=1) + (l1_down * w).sum(axis=1))
    e1 = 2.0 * math.pi * (l1_up[0] * (mu * weight)[:, None]).sum(axis=0)
    values = np.zeros((NODES, 3))
    for c in range(3):
        m = transport(atm, c, float(floor), height, float(albedo[0, 0, c]), mu, weight)
        x2 = np.append(a1[:, c], albedo[0, 0, c] * e1[c] / math.pi)
        values[:, c] = np.linalg.solve(np.eye(NODES + 1) - m, x2)[:NODES]
    return MultipleTable(values, quadrupole, float(floor), float(height), time.perf_counter() - started, aerosol)


def second_order_quadrupole(up, down, mu, weight, sun_y: float, g: float) -> np.ndarray:
    """(NODES, 3 terms, 3 channels): the part of the second order's in-scattering that Rayleigh's phase adds to
    the isotropic one, as coefficients q_m of q_0 P2(mu_v) + q_1 P2^1(mu_v) cos(dphi) + q_2 P2^2(mu_v) cos(2 dphi)
    for a view of elevation sine mu_v at azimuth dphi from the sun; ``up`` and ``down`` are (I_R, I_M or None,
    L_1) on the build's rays (:func:`_single_field`).

    P_R(cos t) = (1 + P2(cos t) / 2) / 4 pi, so the second order's in-scattering towards v is the isotropic
    (1 / 4 pi) int L_1 plus (1 / 8 pi) int L_1(w) P2(w . v) dw. The Rayleigh part of the single-scattering field
    has exactly three azimuthal terms about the sun, I_R(mu) 3 / (16 pi) [(1 + a^2 + b^2 / 2) + 2 a b cos +
    (b^2 / 2) cos 2], a = mu mu_s, b = sqrt(1 - mu^2) sqrt(1 - mu_s^2), the aerosols' part the Henyey-Greenstein
    phase's first three (:func:`azimuthal_hg`), the floor's is isotropic; Legendre's addition theorem then leaves
    one integral over mu per term: q_m = (c_m / 4) int L_1^(m) P2^m dmu, c = (1, 1/6, 1/24)."""
    w = weight[None, :, None]
    k = 3.0 / (16.0 * math.pi)
    ls = math.sqrt(max(1.0 - sun_y * sun_y, 0.0))
    out = np.zeros((up[0].shape[0], 3, up[0].shape[2]))
    for m, c in ((0, 1.0), (1, 1.0 / 6.0), (2, 1.0 / 24.0)):
        total = 0.0
        for sign, (intensity, mie, field) in ((1.0, up), (-1.0, down)):
            x = sign * mu[None, :, None]
            b = np.sqrt(np.maximum(1.0 - x * x, 0.0)) * ls
            if m == 0:
                term, legendre = field, 0.5 * (3.0 * x * x - 1.0)
            elif m == 1:
                term, legendre = intensity * k * 2.0 * x * sun_y * b, 3.0 * x * np.sqrt(np.maximum(1.0 - x * x, 0.0))
            else:
                term, legendre = intensity * k * 0.5 * b * b, 3.0 * (1.0 - x * x)
            if m > 0 and mie is not None:
                term = term + mie * azimuthal_hg(sign * mu, sun_y, g, m)[None, :, None]
            total = total + (term * legendre * w).sum(axis=1)
        out[:, m, :] = 0.25 * c * total
    return out

def aerosol_terms(up, down, mu, weight, sun_y: float, g: float) -> np.ndarray:
    """(NODES, 5 terms, 3 channels): what the aerosols' Henyey-Greenstein phase adds to the second order's isotropic
    in-scattering, as coefficients of the quadrupole weights (:func:`quadrupole_weights`) and the dipole weights
    (:func:`dipole_weights`); ``down`` holds the sunlit floor in its field.

    HG's phase is (1 + 3 g P1 + 5 g^2 P2 + ...) / 4 pi, so towards a view v the second order gains
    (3 g / 4 pi) F . v + 10 g^2 times the quadrupole Rayleigh's phase adds (:func:`second_order_quadrupole`, here
    with the floor's light), F = int L_1 w dw the single-scattering field's first moment: its vertical part
    2 pi int L_1^(0) mu dmu and its part towards the sun's azimuth pi int L_1^(1) sqrt(1 - mu^2) dmu. A strongly
    forward phase (Earth's aerosols: g = 0.8) sends little of a bright floor's upward light back down, and much of
    the bright horizon's light along a horizontal view: the isotropic table is 5 % too bright overhead above snow
    and 2-4 % too dark at the horizon without these terms."""
    quadrupole = 10.0 * g * g * second_order_quadrupole(up, down, mu, weight, sun_y, g)
    w = weight[None, :, None]
    k = 3.0 / (16.0 * math.pi)
    ls = math.sqrt(max(1.0 - sun_y * sun_y, 0.0))
    vertical, towards = 0.0, 0.0
    for sign, (intensity, mie, field) in ((1.0, up), (-1.0, down)):
        x = sign * mu[None, :, None]
        across = np.sqrt(np.maximum(1.0 - x * x, 0.0))
        first = (intensity * k * 2.0 * x * sun_y * across * ls
                 + mie * azimuthal_hg(sign * mu, sun_y, g, 1)[None, :, None])
        vertical = vertical + 2.0 * math.pi * (field * x * w).sum(axis=1)
        towards = towards + math.pi * (first * across * w).sum(axis=1)
    dipole = 3.0 * g / (4.0 * math.pi) * np.stack([vertical, towards], axis=1)
    return np.concatenate([quadrupole, dipole], axis=1)


def dipole_weights(view: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(..., 2): mu_v and sqrt(1 - mu_v^2) cos(dphi) for unit views (..., 3) and the sun's unit direction (3,): the
    view's components up and towards the sun's azimuth."""
    view = np.asarray(view, dtype=np.float64)
    sun = np.asarray(sun, dtype=np.float64)
    sun_h = math.hypot(sun[0], sun[2])
    towards = (view[..., 0] * sun[0] + view[..., 2] * sun[2]) / sun_h if sun_h > 1e-9 else np.zeros(view.shape[:-1])
    return np.stack([view[..., 1], towards], axis=-1)


def quadrupole_weights(view: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(..., 3): P2(mu_v), P2^1(mu_v) cos(dphi), P2^2(mu_v) cos(2 dphi) for unit views (..., 3) and the sun's unit
    direction (3,) (dphi their azimuth difference; 0 when either is vertical)."""
    view = np.asarray(view, dtype=np.float64)
    sun = np.asarray(sun, dtype=np.float64)
    mu = view[..., 1]
    horizontal = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    sun_h = math.hypot(sun[0], sun[2])
    with np.errstate(invalid="ignore", divide="ignore"):
        cos1 = np.where((horizontal > 1e-9) & (sun_h > 1e-9),
                        (view[..., 0] * sun[0] + view[..., 2] * sun[2]) / np.maximum(horizontal * sun_h, 1e-300), 0.0)
    cos1 = np.clip(cos1, -1.0, 1.0)
    return np.stack([0.5 * (3.0 * mu * mu - 1.0), 3.0 * mu * horizontal * cos1,
                     3.0 * horizontal * horizontal * (2.0 * cos1 * cos1 - 1.0)], axis=-1)


def node_heights(floor: float, height: float) -> np.ndarray:
    """The table's node altitudes [m above sea level]: floor + height u^2, u = linspace(0, 1, NODES)."""
    return floor + height * np.linspace(0.0, 1.0, NODES) ** 2


def _interpolation(altitude: np.ndarray, floor: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """(node index i, weight of node i + 1) of linear interpolation in u at ``altitude`` (clamped to the nodes)."""
    u = np.sqrt(np.clip((altitude - floor) / height, 0.0, 1.0))
    x = u * (NODES - 1)
    i = np.minimum(np.floor(x).astype(int), NODES - 2)
    return i, x - i


def transport(atm, channel: int, floor: float, height: float, albedo: float, mu: np.ndarray,
              weight: np.ndarray) -> np.ndarray:
    """The map M of one ``channel`` from an order's isotropic source J_n at the table's nodes and floor radiance
    R_n (the state [J_n, R_n], NODES + 1 values) to the next order's, in float64:

        J_{n+1}(h) = (1 / 4 pi) int [ int_ray sigma_s T J_n dt + (looking down) T(h -> floor) R_n ] dw,
        R_{n+1} = albedo / pi * E_n,  E_n = int_up (int_ray sigma_s T J_n dt) mu dw  at the floor,

    each ray integral taken per scattering constituent c in s_c = 1 - T_c (its single-scattering albedo times
    the others' transmittance at each node) with :data:`BUILD_RAY_NODES` Gauss-Legendre nodes and J interpolated
    linearly between the nodes; ``mu``, ``weight`` are the half-sphere quadrature (:func:`_half_sphere`)."""
    h = node_heights(floor, height)
    s, wk = ray_nodes(BUILD_RAY_NODES)
    out = np.zeros((NODES + 1, NODES + 1))
    for sign in (1.0, -1.0):
        view = sign * mu[None, :, None]
        distance = np.inf if sign > 0 else (h[:, None, None] - floor) / mu[None, :, None]
        parts = [p[..., channel] for p in depth_parts(atm, h[:, None, None], view, distance)]  # (NODES, D, 1)
        for index, (beta, gamma, omega) in enumerate(constituents(atm)):
            span = -np.expm1(-parts[index])
            tau = -np.log1p(-s[None, None, :] * span)
            altitude, along = points_along(beta[channel], gamma, h[:, None, None], view, tau)
            at = [p[..., channel] for p in depth_parts(atm, h[:, None, None], view, along)]
            others = sum(p for i, p in enumerate(at) if i != index)
            i, f = _interpolation(altitude, floor, height)  # (NODES, D, K)
            ray = omega[channel] * span * wk[None, None, :] * np.exp(-others)  # each node's weight in its ray
            rows = np.broadcast_to(np.arange(NODES)[:, None, None], i.shape)
            mean = 0.5 * ray * weight[None, :, None]
            np.add.at(out, (rows, i), mean * (1.0 - f))
            np.add.at(out, (rows, i + 1), mean * f)
            if sign > 0:  # the floor's irradiance from the air above it (row 0 is the floor's altitude)
                flux = albedo / math.pi * 2.0 * math.pi * ray[0] * (mu * weight)[:, None]
                np.add.at(out[NODES], i[0], flux * (1.0 - f[0]))
                np.add.at(out[NODES], i[0] + 1, flux * f[0])
        if sign < 0:  # the floor seen through the air below each node
            t = np.exp(-sum(parts))
            out[:NODES, NODES] = 0.5 * (t[:, :, 0] * weight[None, :]).sum(axis=1)
    return out


def _key(atm) -> tuple:
    """What of ``atm`` the table depends on, hashable."""
    colours = (atm.beta_sea_level, atm.mie_scattering, atm.mie_absorption, atm.ozone_absorption)
    return (tuple(float(v) for c in colours for v in c), float(atm.scale_height), float(atm.mie_scale_height),
            float(atm.mie_g), float(atm.ozone_altitude), float(atm.ozone_width))


@functools.lru_cache(maxsize=64)
def _cached(key: tuple, floor: float, albedo: tuple, sun_y: float, air_sine: float):
    return build(_KEYED[key], floor, np.array(albedo), sun_y, air_sine)


#: The atmosphere each cache key stands for.
_KEYED: dict = {}


def floor_of(scene) -> tuple[float, np.ndarray]:
    """(altitude above sea level [m], albedo RGB) of what ends the air below, as the path tracer's air ends: the
    ground plane where it lies at or above sea level, else a black sea level."""
    atmosphere = scene.atmosphere
    if scene.ground is not None and scene.ground.height + atmosphere.altitude >= 0.0:
        return float(scene.ground.height + atmosphere.altitude), np.asarray(scene.ground.albedo, dtype=np.float64)
    return 0.0, np.zeros(3)


def scene_table(scene, light) -> MultipleTable | None:
    """The table of ``scene``'s air for the sunlight ``light`` (:class:`~warpsky.light.sun.Sunlight`, the sun above
    the air); None without an atmosphere, with multiple scattering off, or without sunlight."""
    atmosphere = scene.atmosphere
    if atmosphere is None or not atmosphere.multiple_scattering or light is None or not light.lit \
            or light.air_sine <= 0.0:
        return None
    floor, albedo = floor_of(scene)
    key = _key(atmosphere)
    _KEYED.setdefault(key, atmosphere)
    return _cached(key, floor, tuple(float(a) for a in albedo), float(light.direction[1]), float(light.air_sine))


def ray_nodes(count: int = RAY_NODES) -> tuple[np.ndarray, np.ndarray]:
    """(s, weight) of ``count``-point Gauss-Legendre on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(count)
    return 0.5 * (x + 1.0), 0.5 * w


