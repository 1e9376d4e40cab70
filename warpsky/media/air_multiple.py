"""The light the air scatters more than once, as a table, for Riley's flat-earth Rayleigh air over a Lambertian
floor: Hillaire's (2020, "A scalable and production ready sky and atmosphere rendering technique", §5.5)
construction with two of its approximations removed.

The analytic sky (:mod:`~warpsky.media.air_analytic`) is the air's single scattering. What it leaves out, light
scattered two or more times, is added per point y of a view ray as sigma_s(y) E Psi(h(y), v), E the sun's
irradiance at the top of the air and Psi a function of altitude (the earth is flat: the sun's elevation is the same
everywhere) and, through its second order, of the view v:

* the single-scattering field L_1(h, w): the exact sky along w (Riley's closed form, Rayleigh phase,
  :func:`~warpsky.media.air_analytic.inscatter`) plus, looking down, the sunlit floor (albedo rho,
  rho / pi E mu_s T_sun) through the air between;
* the orders >= 2 with isotropic scattering, solved over altitude (:func:`transport`): the second order's source
  J_2(h) = (1 / 4 pi) int L_1 dw and the floor lit by the single-scattering sky, R_2 = rho E_1 / pi, then each
  order's source carried along every direction by the exact transmittance to the next (and to and from the floor),
  x_{n+1} = M x_n, so Psi = sum_n J_n = (I - M)^{-1} x_2, one linear system per channel. Hillaire instead takes
  Psi = J_2 / (1 - f) with f the local return fraction (a geometric series with every order at the point's own
  strength), which at a low sun is 6 % low in blue: the light scattered high up, where the sun is still bright,
  is what reaches the ground's air;
* the second order with Rayleigh's phase: its quadrupole (:func:`second_order_quadrupole`), three azimuthal terms
  about the sun, added per view with its P2 weights (:func:`quadrupole_weights`); orders >= 3 stay isotropic.

Rayleigh's azimuthal mean is closed form, so each sphere integral is a quadrature over mu = w_y alone (Gauss-
Legendre on [-1, 0] and [0, 1] in u = sqrt(|mu|), dense at the horizon where the flat earth's sky has its cusp),
in float64 on the host: 48 altitudes x 2 x 96 directions, about 40 ms, cached per air, floor and sun.

Along a view ray the integral int sigma_s T Psi dt is taken in s = 1 - T (ds = sigma_s T dt, the air's extinction
being its scattering): int_0^{1 - T(K)} Psi(h(s)) ds with 8 Gauss-Legendre nodes per channel, h(s) in closed
form (Riley Eq. 11 inverted); for a pinhole camera a per-frame view table holds the whole ray's integrals."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky import device_buffers
from warpsky.media.air_analytic import INFINITE, air_depth, inscatter, rayleigh, transmittance
from warpsky.numerics import one_minus_exp

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
        floor: Altitude [m above sea level] of the floor (the ground plane, else sea level).
        height: Altitude span [m] of the nodes above the floor.
        seconds: Build time.
    """

    values: np.ndarray
    quadrupole: np.ndarray
    floor: float
    height: float
    seconds: float

    def at(self, altitude, angular=None) -> np.ndarray:
        """Psi at ``altitude`` (array, m above sea level), linear in u, plus with ``angular`` (broadcasting
        :func:`quadrupole_weights`, (..., 3)) the second order's Rayleigh part towards that view; (..., 3)."""
        i, f = _interpolation(np.asarray(altitude, dtype=np.float64), self.floor, self.height)
        w = f[..., None]
        out = self.values[i] * (1.0 - w) + self.values[i + 1] * w
        if angular is not None:
            q = self.quadrupole[i] * (1.0 - w[..., None]) + self.quadrupole[i + 1] * w[..., None]
            out = out + np.einsum("...mc,...m->...c", q, np.asarray(angular, dtype=np.float64))
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


def build(beta_sea_level, scale_height: float, floor: float, albedo, sun_y: float, air_sine: float) -> MultipleTable:
    """The table for air of sea-level scattering ``beta_sea_level`` [1/m, RGB] and ``scale_height`` [m] over a
    Lambertian floor of ``albedo`` (RGB) at ``floor`` [m above sea level], lit by a sun of elevation sine ``sun_y``
    (its direction) and ``air_sine`` (its air mass, :func:`~warpsky.media.air_analytic.air_sine`)."""
    import time

    started = time.perf_counter()
    beta = np.asarray(beta_sea_level, dtype=np.float64)[None, None, :]
    albedo = np.asarray(albedo, dtype=np.float64)[None, None, :]
    gamma = 1.0 / scale_height
    height = TOP_SCALE_HEIGHTS * scale_height
    h = node_heights(floor, height)[:, None, None]
    mu, weight = _half_sphere(DIRECTIONS)
    up, down = mu[None, :, None], -mu[None, :, None]
    w = weight[None, :, None]
    # up: the air to infinity
    i_up = inscatter(beta, gamma, h, up, air_sine, np.inf)
    l1_up = azimuthal_rayleigh(up, sun_y) * i_up
    # down: the air to the floor, then the floor
    distance = (h - floor) / mu[None, :, None]
    t_down = transmittance(beta, gamma, h, down, distance)
    i_down = inscatter(beta, gamma, h, down, air_sine, distance)
    l1_down = azimuthal_rayleigh(down, sun_y) * i_down
    quadrupole = second_order_quadrupole(i_up, i_down, l1_up, l1_down, mu, weight, sun_y)
    t_sun_floor = np.exp(-beta * np.exp(-gamma * floor) / (gamma * air_sine))
    l1_down = l1_down + t_down * albedo / math.pi * max(sun_y, 0.0) * t_sun_floor
    # orders >= 2 (isotropic in-scattering): J_2 is the mean of the single-scattering field L_1 (sunlit floor
    # included), R_2 the floor lit by the single-scattering sky; then x_{n+1} = M x_n, Psi = sum_n J_n
    a1 = 0.5 * ((l1_up * w).sum(axis=1) + (l1_down * w).sum(axis=1))
    e1 = 2.0 * math.pi * (l1_up[0] * (mu * weight)[:, None]).sum(axis=0)
    values = np.zeros((NODES, 3))
    for c in range(3):
        m = transport(float(beta[0, 0, c]), gamma, float(floor), height, float(albedo[0, 0, c]), mu, weight)
        x2 = np.append(a1[:, c], albedo[0, 0, c] * e1[c] / math.pi)
        values[:, c] = np.linalg.solve(np.eye(NODES + 1) - m, x2)[:NODES]
    return MultipleTable(values, quadrupole, float(floor), float(height), time.perf_counter() - started)


def second_order_quadrupole(i_up, i_down, l1_up, l1_down, mu, weight, sun_y: float) -> np.ndarray:
    """(NODES, 3 terms, 3 channels): the part of the second order's in-scattering that Rayleigh's phase adds to
    the isotropic one, as coefficients q_m of q_0 P2(mu_v) + q_1 P2^1(mu_v) cos(dphi) + q_2 P2^2(mu_v) cos(2 dphi)
    for a view of elevation sine mu_v at azimuth dphi from the sun.

    P_R(cos t) = (1 + P2(cos t) / 2) / 4 pi, so the second order's in-scattering towards v is the isotropic
    (1 / 4 pi) int L_1 plus (1 / 8 pi) int L_1(w) P2(w . v) dw. The single-scattering field L_1 has exactly three
    azimuthal terms about the sun, L_1 = I(mu) 3 / (16 pi) [(1 + a^2 + b^2 / 2) + 2 a b cos + (b^2 / 2) cos 2], a =
    mu mu_s, b = sqrt(1 - mu^2) sqrt(1 - mu_s^2), plus the floor's isotropic term in the first; Legendre's
    addition theorem then leaves one integral over mu per term: q_m = (c_m / 4) int L_1^(m) P2^m dmu, c = (1, 1/6,
    1/24)."""
    ups, downs = mu[None, :, None], -mu[None, :, None]
    w = weight[None, :, None]
    k = 3.0 / (16.0 * math.pi)
    ls = math.sqrt(max(1.0 - sun_y * sun_y, 0.0))
    out = np.zeros((i_up.shape[0], 3, i_up.shape[2]))
    for m, c in ((0, 1.0), (1, 1.0 / 6.0), (2, 1.0 / 24.0)):
        total = 0.0
        for x, intensity, field in ((ups, i_up, l1_up), (downs, i_down, l1_down)):
            b = np.sqrt(np.maximum(1.0 - x * x, 0.0)) * ls
            if m == 0:
                term, legendre = field, 0.5 * (3.0 * x * x - 1.0)
            elif m == 1:
                term, legendre = intensity * k * 2.0 * x * sun_y * b, 3.0 * x * np.sqrt(np.maximum(1.0 - x * x, 0.0))
            else:
                term, legendre = intensity * k * 0.5 * b * b, 3.0 * (1.0 - x * x)
            total = total + (term * legendre * w).sum(axis=1)
        out[:, m, :] = 0.25 * c * total
    return out


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


def transport(beta: float, gamma: float, floor: float, height: float, albedo: float, mu: np.ndarray,
              weight: np.ndarray) -> np.ndarray:
    """The map M of one channel from an order's isotropic source J_n at the table's nodes and floor radiance R_n
    (the state [J_n, R_n], NODES + 1 values) to the next order's, in float64:

        J_{n+1}(h) = (1 / 4 pi) int [ int_ray sigma_s T J_n dt + (looking down) T(h -> floor) R_n ] dw,
        R_{n+1} = albedo / pi * E_n,  E_n = int_up (int_ray sigma_s T J_n dt) mu dw  at the floor,

    each ray integral taken in s = 1 - T with :data:`BUILD_RAY_NODES` Gauss-Legendre nodes and J interpolated
    linearly between the nodes; ``mu``, ``weight`` are the half-sphere quadrature (:func:`_half_sphere`)."""
    h = node_heights(floor, height)
    s, wk = ray_nodes(BUILD_RAY_NODES)
    out = np.zeros((NODES + 1, NODES + 1))
    for sign in (1.0, -1.0):
        view = sign * mu[None, :, None]
        distance = np.inf if sign > 0 else (h[:, None, None] - floor) / mu[None, :, None]
        t = transmittance(beta, gamma, h[:, None, None], view, distance)  # (NODES, D, 1)
        span = 1.0 - t
        altitude = node_altitudes(beta, gamma, h[:, None, None], view, -np.log1p(-s[None, None, :] * span))
        i, f = _interpolation(altitude, floor, height)  # (NODES, D, K)
        ray = span * wk[None, None, :]  # each node's weight in its ray's integral
        rows = np.broadcast_to(np.arange(NODES)[:, None, None], i.shape)
        mean = 0.5 * ray * weight[None, :, None]
        np.add.at(out, (rows, i), mean * (1.0 - f))
        np.add.at(out, (rows, i + 1), mean * f)
        if sign > 0:  # the floor's irradiance from the air above it (row 0 is the floor's altitude)
            flux = albedo / math.pi * 2.0 * math.pi * ray[0] * (mu * weight)[:, None]
            np.add.at(out[NODES], i[0], flux * (1.0 - f[0]))
            np.add.at(out[NODES], i[0] + 1, flux * f[0])
        else:  # the floor seen through the air below each node
            out[:NODES, NODES] = 0.5 * (t[:, :, 0] * weight[None, :]).sum(axis=1)
    return out


@functools.lru_cache(maxsize=64)
def _cached(beta: tuple, scale_height: float, floor: float, albedo: tuple, sun_y: float, air_sine: float):
    return build(np.array(beta), scale_height, floor, np.array(albedo), sun_y, air_sine)


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
    return _cached(tuple(float(b) for b in atmosphere.beta_sea_level), float(atmosphere.scale_height), floor,
                   tuple(float(a) for a in albedo), float(light.direction[1]), float(light.air_sine))


def ray_nodes(count: int = RAY_NODES) -> tuple[np.ndarray, np.ndarray]:
    """(s, weight) of ``count``-point Gauss-Legendre on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(count)
    return 0.5 * (x + 1.0), 0.5 * w


def node_altitudes(beta_sea_level, gamma: float, h0, view_y, depth) -> np.ndarray:
    """Altitude [m] where the optical depth from ``h0`` along elevation sine ``view_y`` reaches ``depth`` (per
    channel), Riley's Eq. 11 inverted: h = h0 - log(1 - depth gamma v_y / B(h0)) / gamma."""
    b0 = np.asarray(beta_sea_level, dtype=np.float64) * np.exp(-gamma * np.asarray(h0, dtype=np.float64))
    x = np.asarray(depth, dtype=np.float64) * gamma * np.asarray(view_y, dtype=np.float64) / b0
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(h0, dtype=np.float64) - np.log1p(-np.minimum(x, 1.0 - 1e-15)) / gamma


def multiple_inscatter(table: MultipleTable, beta_sea_level, gamma: float, h0, view_y, distance,
                       angular=None) -> np.ndarray:
    """int_0^K sigma_s T Psi dt per channel (multiply by E): the multiple-scattering radiance along a view ray of
    elevation sine ``view_y`` from ``h0`` over ``distance`` (inf: to the end of the air, upward), with the second
    order's Rayleigh part for the views' ``angular`` weights (:func:`quadrupole_weights`, (..., 3); None: the
    isotropic part alone); (..., 3) float64 for arrays broadcasting to (...)."""
    h0 = np.asarray(h0, dtype=np.float64)[..., None]
    view_y = np.asarray(view_y, dtype=np.float64)[..., None]
    beta = np.asarray(beta_sea_level, dtype=np.float64)
    span = 1.0 - transmittance(beta, gamma, h0, view_y, np.asarray(distance, dtype=np.float64)[..., None])
    out = np.zeros(np.broadcast_shapes(span.shape, h0.shape, view_y.shape))
    for sk, wk in zip(*ray_nodes(), strict=True):
        altitude = node_altitudes(beta, gamma, h0, view_y, -np.log1p(-sk * span))
        for c in range(3):
            out[..., c] += wk * table.at(altitude[..., c], angular)[..., c]
    return span * out


def air_radiance(scene, light, altitude: float, directions: np.ndarray, distance=np.inf) -> np.ndarray:
    """(N, 3) radiance of ``scene``'s air seen from ``altitude`` [m above sea level] along unit ``directions``
    (N, 3) over ``distance`` [m] (scalar or (N,); inf: to the end of the air, upward) for the sunlight ``light``
    (above the air): Riley's single scattering E P_R inscatter plus, unless the atmosphere turns it off, the
    table's multiple scattering. The same light the sky pass draws."""
    atmosphere = scene.atmosphere
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    distance = np.broadcast_to(np.asarray(distance, dtype=np.float64).reshape(-1) if np.ndim(distance)
                               else np.asarray(distance, dtype=np.float64), (len(directions),))
    beta = atmosphere.beta_sea_level
    view_y = directions[:, 1]
    single = inscatter(beta[None, :], atmosphere.gamma, altitude, view_y[:, None], light.air_sine, distance[:, None])
    out = single * rayleigh(directions @ np.asarray(light.direction, dtype=np.float64))[:, None]
    table = scene_table(scene, light)
    if table is not None:
        angular = quadrupole_weights(directions, light.direction)
        out = out + multiple_inscatter(table, beta, atmosphere.gamma, altitude, view_y, distance, angular)
    return np.asarray(light.irradiance, dtype=np.float64)[None, :] * out


# ---- on the device ----------------------------------------------------------------------------------------------

_S, _W = ray_nodes()
vec_nodes = wp.types.vector(length=RAY_NODES, dtype=float)
RAY_S = wp.constant(vec_nodes(*_S.tolist()))
RAY_W = wp.constant(vec_nodes(*_W.tolist()))
TABLE_NODES = wp.constant(NODES)


@wp.struct
class AirMultiple:
    """:class:`MultipleTable` as kernels see it (``enabled`` 0: single scattering only), with the frame's view
    table: the ray integrals of the four terms from the eye's altitude to the end of the air, against the view's
    elevation sine (``view_nodes`` > 0 where every camera ray starts at the eye)."""

    enabled: int
    values: wp.array2d(dtype=wp.vec3)  # (NODES, 4): Psi, then the quadrupole's q_0, q_1, q_2, RGB each
    floor: float  # [m above sea level]
    height: float  # [m]
    view_nodes: int  # entries of ``views`` (0: none; integrate each ray)
    views: wp.array2d(dtype=wp.vec3)  # (view_nodes, 4): per term, int sigma_s T term dt over the whole ray


@wp.func
def quadrupole_angular(view: wp.vec3, sun: wp.vec3) -> wp.vec3:
    """P2(mu_v), P2^1(mu_v) cos(dphi), P2^2(mu_v) cos(2 dphi) of the unit ``view`` and the sun's unit direction
    (dphi their azimuth difference; 0 where either is vertical), as :func:`quadrupole_weights`."""
    mu = view[1]
    horizontal = wp.sqrt(wp.max(1.0 - mu * mu, 0.0))
    sun_h = wp.sqrt(sun[0] * sun[0] + sun[2] * sun[2])
    cos1 = float(0.0)
    if horizontal > 1.0e-9 and sun_h > 1.0e-9:
        cos1 = wp.clamp((view[0] * sun[0] + view[2] * sun[2]) / (horizontal * sun_h), -1.0, 1.0)
    return wp.vec3(0.5 * (3.0 * mu * mu - 1.0), 3.0 * mu * horizontal * cos1,
                   3.0 * horizontal * horizontal * (2.0 * cos1 * cos1 - 1.0))


@wp.struct
class MultipleTerms:
    """Ray integrals of the table's four terms (Psi, q_0, q_1, q_2), RGB each."""

    psi: wp.vec3
    q0: wp.vec3
    q1: wp.vec3
    q2: wp.vec3


@wp.func
def combine(terms: MultipleTerms, angular: wp.vec3) -> wp.vec3:
    """The multiple-scattering integral towards a view of ``angular`` weights: Psi's plus the quadrupole's."""
    return terms.psi + terms.q0 * angular[0] + terms.q1 * angular[1] + terms.q2 * angular[2]


@wp.func
def multiple_terms(ms: AirMultiple, beta_sl: wp.vec3, gamma: float, h0: float, view_y: float,
                   depth: wp.vec3) -> MultipleTerms:
    """int sigma_s T term dt of each table term over a view ray from ``h0`` of elevation sine ``view_y`` whose
    optical depth is ``depth`` (per channel; multiply by E): in s = 1 - T, :data:`RAY_NODES` Gauss-Legendre nodes,
    the altitude at each in closed form (Riley Eq. 11 inverted), the table linear in u."""
    out = MultipleTerms()
    b0 = beta_sl * wp.exp(-gamma * h0)
    for c in range(3):
        span = one_minus_exp(depth[c])
        slope = gamma * view_y / b0[c]
        for k in range(RAY_NODES):
            q = RAY_S[k] * span
            tau = -wp.log(1.0 - q)
            if q < 1.0e-3:
                tau = q * (1.0 + 0.5 * q)
            x = wp.min(tau * slope, 1.0 - 1.0e-7)
            h = h0 - wp.log(1.0 - x) / gamma
            if wp.abs(x) < 1.0e-3:
                h = h0 + x * (1.0 + x * (0.5 + x / 3.0)) / gamma
            u = wp.sqrt(wp.clamp((h - ms.floor) / ms.height, 0.0, 1.0))
            xi = u * float(TABLE_NODES - 1)
            i = wp.min(int(xi), TABLE_NODES - 2)
            w = xi - float(i)
            a = RAY_W[k] * span * (1.0 - w)
            b = RAY_W[k] * span * w
            out.psi[c] += a * ms.values[i, 0][c] + b * ms.values[i + 1, 0][c]
            out.q0[c] += a * ms.values[i, 1][c] + b * ms.values[i + 1, 1][c]
            out.q1[c] += a * ms.values[i, 2][c] + b * ms.values[i + 1, 2][c]
            out.q2[c] += a * ms.values[i, 3][c] + b * ms.values[i + 1, 3][c]
    return out


@wp.func
def multiple_along(ms: AirMultiple, beta_sl: wp.vec3, gamma: float, h0: float, view_y: float, angular: wp.vec3,
                   depth: wp.vec3) -> wp.vec3:
    """int sigma_s T Psi dt over a view ray (see :func:`multiple_terms`) towards a view of ``angular`` weights
    (:func:`quadrupole_angular`); 0 when the table is off."""
    out = wp.vec3(0.0)
    if ms.enabled != 0:
        out = combine(multiple_terms(ms, beta_sl, gamma, h0, view_y, depth), angular)
    return out


@wp.func
def view_index(view_y: float, count: int) -> float:
    """Fractional entry of elevation sine ``view_y`` in a view table of ``count`` entries: uniform in
    sign(mu) sqrt(|mu|), dense at the horizon."""
    v = wp.sign(view_y) * wp.sqrt(wp.abs(view_y))
    return wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(count - 1)


@wp.func
def whole_ray(ms: AirMultiple, view_y: float, angular: wp.vec3) -> wp.vec3:
    """The view table's multiple-scattering integral over a whole camera ray of elevation sine ``view_y``."""
    x = view_index(view_y, ms.view_nodes)
    i = wp.min(int(x), ms.view_nodes - 2)
    w = x - float(i)
    out = wp.vec3(0.0)
    for term in range(4):
        weight = float(1.0)
        if term > 0:
            weight = angular[term - 1]
        out += (ms.views[i, term] * (1.0 - w) + ms.views[i + 1, term] * w) * weight
    return out


#: Entries of the frame's view table.
VIEW_NODES = 1024


@wp.kernel
def view_table_kernel(ms: AirMultiple, beta_sl: wp.vec3, gamma: float, altitude: float, floor: float,
                      out: wp.array2d(dtype=wp.vec3)):
    """Entry i of the view table: the ray from ``altitude`` to the end of the air (``floor`` below, space above)
    at the elevation sine whose :func:`view_index` is i."""
    i = wp.tid()
    n = out.shape[0]
    v = 2.0 * float(i) / float(n - 1) - 1.0
    view_y = wp.sign(v) * v * v
    distance = float(INFINITE)
    if view_y < 0.0:
        distance = wp.max(altitude - floor, 0.0) / (-view_y)
    terms = multiple_terms(ms, beta_sl, gamma, altitude, view_y, air_depth(beta_sl, gamma, altitude, view_y,
                                                                            distance))
    out[i, 0] = terms.psi
    out[i, 1] = terms.q0
    out[i, 2] = terms.q1
    out[i, 3] = terms.q2


def multiple_struct(table: MultipleTable | None, device, name: str = "air_multiple", *, views=None) -> AirMultiple:
    """Kernel view of ``table`` (None: off, a zero table); ``views`` = (atmosphere, eye altitude [m above sea
    level], floor altitude [m]) also builds the frame's view table (for cameras whose rays all start at the
    eye)."""
    out = AirMultiple()
    out.enabled = int(table is not None)
    values = np.zeros((NODES, 4, 3))
    if table is not None:
        values[:, 0], values[:, 1:] = table.values, table.quadrupole
    out.values = device_buffers.upload(f"{name}:values", values.astype(np.float32), wp.vec3, device)
    out.floor = float(table.floor) if table is not None else 0.0
    out.height = float(table.height) if table is not None else 1.0
    out.view_nodes = 0
    if table is None or views is None:
        out.views = device_buffers.reusable(f"{name}:no views", (2, 4), wp.vec3, device)
    else:
        atmosphere, altitude, floor = views
        out.views = device_buffers.reusable(f"{name}:views", (VIEW_NODES, 4), wp.vec3, device)
        beta = wp.vec3(*np.asarray(atmosphere.beta_sea_level, dtype=np.float64).tolist())
        wp.launch(view_table_kernel, dim=VIEW_NODES, inputs=[out, beta, float(atmosphere.gamma), float(altitude),
                                                             float(floor), out.views], device=device)
        out.view_nodes = VIEW_NODES
    return out


__all__ = ["AirMultiple", "MultipleTable", "air_radiance", "build", "multiple_along", "multiple_inscatter",
           "multiple_struct", "quadrupole_angular", "scene_table", "whole_ray"]
