"""The light the air scatters more than once, as a table, for Riley's flat-earth Rayleigh air over a Lambertian
floor: Hillaire's (2020, "A scalable and production ready sky and atmosphere rendering technique", §5.5)
construction with two of its approximations removed.

The analytic sky (:mod:`~warpsky.media.air.analytic`) is the air's single scattering. What it leaves out, light
scattered two or more times, is added per point y of a view ray as sigma_s(y) E Psi(h(y), v), E the sun's
irradiance at the top of the air and Psi a function of altitude (the earth is flat: the sun's elevation is the same
everywhere) and, through its second order, of the view v:

* the single-scattering field L_1(h, w): the exact sky along w (Riley's closed form, Rayleigh phase,
  :func:`~warpsky.media.air.analytic.inscatter`) plus, looking down, the sunlit floor (albedo rho,
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

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.numerics import one_minus_exp
from warpsky.media.air.analytic import INFINITE, AnalyticAir, air_depth, analytic_air, rayleigh
from warpsky.media.air.mixture import constituents, depth_parts, hg, points_along, scatter_parts
from warpsky.media.air.mixture_kernels import (
    AirDepths,
    AirScatter,
    air_depths,
    air_scatter,
    distance_at_depth,
    ozone_depth,
    scalar_depth,
)
from warpsky.media.air.multiple import (  # noqa: F401 (the table's build, kept importable from here)
    BUILD_RAY_NODES,
    DIRECTIONS,
    NODES,
    RAY_NODES,
    TOP_SCALE_HEIGHTS,
    MultipleTable,
    _half_sphere,
    _interpolation,
    build,
    dipole_weights,
    floor_of,
    node_heights,
    quadrupole_weights,
    ray_nodes,
    scene_table,
)


def multiple_inscatter(table: MultipleTable, atm, h0, view_y, distance, angular=None) -> np.ndarray:
    """int_0^K sigma_s T Psi dt per channel (multiply by E): the multiple-scattering radiance of the air ``atm``
    along a view ray of elevation sine ``view_y`` from ``h0`` over ``distance`` (inf: to the end of the air,
    upward), with the second order's anisotropic parts for the views' ``angular`` weights
    (:func:`quadrupole_weights` then :func:`dipole_weights`, (..., 5); None: the isotropic part alone); (..., 3)
    float64 for arrays broadcasting to (...). Each scattering constituent's part is taken in its own s = 1 - T
    (:data:`RAY_NODES` Gauss-Legendre nodes), times its albedo and the other constituents' transmittance."""
    h0 = np.asarray(h0, dtype=np.float64)[..., None]
    view_y = np.asarray(view_y, dtype=np.float64)[..., None]
    distance = np.asarray(distance, dtype=np.float64)[..., None]
    parts = depth_parts(atm, h0[..., 0], view_y[..., 0], distance[..., 0])
    out = 0.0
    for index, (beta, gamma, omega) in enumerate(constituents(atm)):
        span = -np.expm1(-parts[index])
        total = np.zeros(np.broadcast_shapes(span.shape, h0.shape, view_y.shape))
        for sk, wk in zip(*ray_nodes(), strict=True):
            tau = -np.log1p(-sk * span)
            altitude, along = points_along(beta, gamma, h0, view_y, tau)
            weight = wk
            if atm.mixed:
                at = depth_parts(atm, h0, view_y, along)
                others = sum(p for i, p in enumerate(at) if i != index)
                weight = wk * np.exp(-np.diagonal(others, axis1=-2, axis2=-1))
            for c in range(3):
                psi = table.at(altitude[..., c], angular, aerosol=index == 1)[..., c]
                total[..., c] += (weight[..., c] if np.ndim(weight) else weight) * psi
        out = out + omega * span * total
    return out


def air_radiance(scene, light, altitude: float, directions: np.ndarray, distance=np.inf) -> np.ndarray:
    """(N, 3) radiance of ``scene``'s air seen from ``altitude`` [m above sea level] along unit ``directions``
    (N, 3) over ``distance`` [m] (scalar or (N,); inf: to the end of the air, upward) for the sunlight ``light``
    (above the air): the single scattering E (P_R I_R + P_M I_M) (:func:`~warpsky.media.air.mixture.scatter_parts`)
    plus, unless the atmosphere turns it off, the table's multiple scattering. The same light the sky pass draws."""
    atmosphere = scene.atmosphere
    if atmosphere.round:
        from warpsky.media.air import round_earth as air_round_host

        return air_round_host.radiance(scene, light, altitude, directions, distance)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    distance = np.broadcast_to(np.asarray(distance, dtype=np.float64).reshape(-1) if np.ndim(distance)
                               else np.asarray(distance, dtype=np.float64), (len(directions),))
    view_y = directions[:, 1]
    cos_theta = directions @ np.asarray(light.direction, dtype=np.float64)
    parts = scatter_parts(atmosphere, altitude, view_y, light.air_sine, distance)
    out = parts[0] * rayleigh(cos_theta)[:, None]
    if len(parts) > 1:
        out = out + parts[1] * hg(cos_theta, atmosphere.mie_g)[:, None]
    table = scene_table(scene, light)
    if table is not None:
        angular = np.concatenate([quadrupole_weights(directions, light.direction),
                                  dipole_weights(directions, light.direction)], axis=-1)
        out = out + np.maximum(multiple_inscatter(table, atmosphere, altitude, view_y, distance, angular), 0.0)
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
    values: wp.array2d(dtype=wp.vec3)  # (NODES, 9): Psi, the Rayleigh quadrupole's q_0..q_2, the aerosols' 5 terms
    floor: float  # [m above sea level]
    height: float  # [m]
    view_nodes: int  # entries of ``views`` (0: none; integrate each ray)
    views: wp.array2d(dtype=wp.vec3)  # (view_nodes, 11): int sigma_s T term dt over the whole ray of Psi, q_0..q_2,
    # then (air with aerosols or ozone) the single-scattering integrals of the Rayleigh gas and the aerosols, then
    # the aerosols' five terms


#: A view's weights of the second order's anisotropic terms: P2(mu_v), P2^1(mu_v) cos(dphi), P2^2(mu_v) cos(2 dphi),
#: then mu_v and sqrt(1 - mu_v^2) cos(dphi).
vec5 = wp.types.vector(length=5, dtype=float)


@wp.func
def quadrupole_angular(view: wp.vec3, sun: wp.vec3) -> vec5:
    """The weights of the unit ``view`` and the sun's unit direction (dphi their azimuth difference; 0 where either
    is vertical), as :func:`quadrupole_weights` and :func:`dipole_weights`."""
    mu = view[1]
    horizontal = wp.sqrt(wp.max(1.0 - mu * mu, 0.0))
    sun_h = wp.sqrt(sun[0] * sun[0] + sun[2] * sun[2])
    cos1 = float(0.0)
    if horizontal > 1.0e-9 and sun_h > 1.0e-9:
        cos1 = wp.clamp((view[0] * sun[0] + view[2] * sun[2]) / (horizontal * sun_h), -1.0, 1.0)
    return vec5(0.5 * (3.0 * mu * mu - 1.0), 3.0 * mu * horizontal * cos1,
                3.0 * horizontal * horizontal * (2.0 * cos1 * cos1 - 1.0), mu, horizontal * cos1)


@wp.struct
class MultipleTerms:
    """Ray integrals of the table's terms (Psi, the Rayleigh gas's q_0..q_2, the aerosols' five), RGB each."""

    psi: wp.vec3
    q0: wp.vec3
    q1: wp.vec3
    q2: wp.vec3
    a0: wp.vec3
    a1: wp.vec3
    a2: wp.vec3
    a3: wp.vec3
    a4: wp.vec3


@wp.func
def combine(terms: MultipleTerms, angular: vec5) -> wp.vec3:
    """The multiple-scattering integral towards a view of ``angular`` weights: Psi's plus the second order's
    anisotropic parts (not below 0)."""
    out = (terms.psi + terms.q0 * angular[0] + terms.q1 * angular[1] + terms.q2 * angular[2]
           + terms.a0 * angular[0] + terms.a1 * angular[1] + terms.a2 * angular[2] + terms.a3 * angular[3]
           + terms.a4 * angular[4])
    return wp.vec3(wp.max(out[0], 0.0), wp.max(out[1], 0.0), wp.max(out[2], 0.0))


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
def multiple_along(ms: AirMultiple, beta_sl: wp.vec3, gamma: float, h0: float, view_y: float, angular: vec5,
                   depth: wp.vec3) -> wp.vec3:
    """int sigma_s T Psi dt over a view ray (see :func:`multiple_terms`) towards a view of ``angular`` weights
    (:func:`quadrupole_angular`); 0 when the table is off."""
    out = wp.vec3(0.0)
    if ms.enabled != 0:
        out = combine(multiple_terms(ms, beta_sl, gamma, h0, view_y, depth), angular)
    return out


@wp.func
def add_terms(out: MultipleTerms, ms: AirMultiple, c: int, h: float, a: float, rayleigh: int) -> MultipleTerms:
    """``out`` plus weight ``a`` of the table's terms at altitude ``h`` in channel ``c`` (the quadrupole only for
    the Rayleigh gas's part, ``rayleigh`` 1)."""
    u = wp.sqrt(wp.clamp((h - ms.floor) / ms.height, 0.0, 1.0))
    xi = u * float(TABLE_NODES - 1)
    i = wp.min(int(xi), TABLE_NODES - 2)
    w = xi - float(i)
    r = out
    r.psi[c] += a * ((1.0 - w) * ms.values[i, 0][c] + w * ms.values[i + 1, 0][c])
    if rayleigh != 0:
        r.q0[c] += a * ((1.0 - w) * ms.values[i, 1][c] + w * ms.values[i + 1, 1][c])
        r.q1[c] += a * ((1.0 - w) * ms.values[i, 2][c] + w * ms.values[i + 1, 2][c])
        r.q2[c] += a * ((1.0 - w) * ms.values[i, 3][c] + w * ms.values[i + 1, 3][c])
    else:
        r.a0[c] += a * ((1.0 - w) * ms.values[i, 4][c] + w * ms.values[i + 1, 4][c])
        r.a1[c] += a * ((1.0 - w) * ms.values[i, 5][c] + w * ms.values[i + 1, 5][c])
        r.a2[c] += a * ((1.0 - w) * ms.values[i, 6][c] + w * ms.values[i + 1, 6][c])
        r.a3[c] += a * ((1.0 - w) * ms.values[i, 7][c] + w * ms.values[i + 1, 7][c])
        r.a4[c] += a * ((1.0 - w) * ms.values[i, 8][c] + w * ms.values[i + 1, 8][c])
    return r


@wp.func
def mixed_terms(ms: AirMultiple, air: AnalyticAir, h0: float, view_y: float, d: AirDepths) -> MultipleTerms:
    """:func:`multiple_terms` for air with aerosols or ozone: each scattering constituent in its own s = 1 - T,
    times its albedo and the other constituents' transmittance at each node."""
    out = MultipleTerms()
    for which in range(2):
        for c in range(3):
            beta = air.beta_sea_level[c]
            gamma = air.gamma
            own = d.rayleigh[c]
            albedo = float(1.0)
            if which == 1:
                beta = air.mie_extinction[c]
                gamma = air.mie_gamma
                own = d.mie[c]
                albedo = air.mie_albedo[c]
            if beta > 0.0:
                span = one_minus_exp(own)
                for k in range(RAY_NODES):
                    q = RAY_S[k] * span
                    t = distance_at_depth(beta, gamma, h0, view_y, -wp.log(1.0 - q))
                    others = air.ozone[c] * ozone_depth(air, h0, view_y, t)
                    if which == 0:
                        others += scalar_depth(air.mie_extinction[c], air.mie_gamma, h0, view_y, t)
                    else:
                        others += scalar_depth(air.beta_sea_level[c], air.gamma, h0, view_y, t)
                    a = RAY_W[k] * span * albedo * wp.exp(-others)
                    out = add_terms(out, ms, c, h0 + view_y * t, a, 1 - which)
    return out


@wp.func
def multiple_along_air(ms: AirMultiple, air: AnalyticAir, h0: float, view_y: float, angular: vec5,
                       distance: float) -> wp.vec3:
    """int sigma_s T Psi dt from ``h0`` over ``distance`` towards a view of ``angular`` weights, for any air; 0
    when the table is off."""
    out = wp.vec3(0.0)
    if ms.enabled != 0:
        if air.mixed == 0:
            out = combine(multiple_terms(ms, air.beta_sea_level, air.gamma, h0, view_y,
                                         air_depth(air.beta_sea_level, air.gamma, h0, view_y, distance)), angular)
        else:
            out = combine(mixed_terms(ms, air, h0, view_y, air_depths(air, h0, view_y, distance)), angular)
    return out


@wp.func
def view_index(view_y: float, count: int) -> float:
    """Fractional entry of elevation sine ``view_y`` in a view table of ``count`` entries: uniform in
    sign(mu) sqrt(|mu|), dense at the horizon."""
    v = wp.sign(view_y) * wp.sqrt(wp.abs(view_y))
    return wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(count - 1)


@wp.func
def whole_ray(ms: AirMultiple, view_y: float, angular: vec5) -> wp.vec3:
    """The view table's multiple-scattering integral over a whole camera ray of elevation sine ``view_y``."""
    x = view_index(view_y, ms.view_nodes)
    i = wp.min(int(x), ms.view_nodes - 2)
    w = x - float(i)
    terms = MultipleTerms()
    terms.psi = ms.views[i, 0] * (1.0 - w) + ms.views[i + 1, 0] * w
    terms.q0 = ms.views[i, 1] * (1.0 - w) + ms.views[i + 1, 1] * w
    terms.q1 = ms.views[i, 2] * (1.0 - w) + ms.views[i + 1, 2] * w
    terms.q2 = ms.views[i, 3] * (1.0 - w) + ms.views[i + 1, 3] * w
    terms.a0 = ms.views[i, 6] * (1.0 - w) + ms.views[i + 1, 6] * w
    terms.a1 = ms.views[i, 7] * (1.0 - w) + ms.views[i + 1, 7] * w
    terms.a2 = ms.views[i, 8] * (1.0 - w) + ms.views[i + 1, 8] * w
    terms.a3 = ms.views[i, 9] * (1.0 - w) + ms.views[i + 1, 9] * w
    terms.a4 = ms.views[i, 10] * (1.0 - w) + ms.views[i + 1, 10] * w
    return combine(terms, angular)


@wp.func
def whole_single(ms: AirMultiple, view_y: float) -> AirScatter:
    """The view table's single-scattering integrals over a whole camera ray (air with aerosols or ozone)."""
    x = view_index(view_y, ms.view_nodes)
    i = wp.min(int(x), ms.view_nodes - 2)
    w = x - float(i)
    out = AirScatter()
    out.rayleigh = ms.views[i, 4] * (1.0 - w) + ms.views[i + 1, 4] * w
    out.mie = ms.views[i, 5] * (1.0 - w) + ms.views[i + 1, 5] * w
    return out


#: Entries of the frame's view table.
VIEW_NODES = 1024


@wp.kernel
def view_table_kernel(ms: AirMultiple, air: AnalyticAir, sun_y: float, altitude: float, floor: float,
                      out: wp.array2d(dtype=wp.vec3)):
    """Entry i of the view table: the ray from ``altitude`` to the end of the air (``floor`` below, space above)
    at the elevation sine whose :func:`view_index` is i; with aerosols or ozone also its single scattering for a
    sun of air sine ``sun_y``."""
    i = wp.tid()
    n = out.shape[0]
    v = 2.0 * float(i) / float(n - 1) - 1.0
    view_y = wp.sign(v) * v * v
    distance = float(INFINITE)
    if view_y < 0.0:
        distance = wp.max(altitude - floor, 0.0) / (-view_y)
    terms = MultipleTerms()
    if air.mixed == 0:
        terms = multiple_terms(ms, air.beta_sea_level, air.gamma, altitude, view_y,
                               air_depth(air.beta_sea_level, air.gamma, altitude, view_y, distance))
    else:
        terms = mixed_terms(ms, air, altitude, view_y, air_depths(air, altitude, view_y, distance))
        single = air_scatter(air, altitude, view_y, sun_y, distance)
        out[i, 4] = single.rayleigh
        out[i, 5] = single.mie
    out[i, 0] = terms.psi
    out[i, 1] = terms.q0
    out[i, 2] = terms.q1
    out[i, 3] = terms.q2
    out[i, 6] = terms.a0
    out[i, 7] = terms.a1
    out[i, 8] = terms.a2
    out[i, 9] = terms.a3
    out[i, 10] = terms.a4


def multiple_struct(table: MultipleTable | None, device, name: str = "air_multiple", *, views=None) -> AirMultiple:
    """Kernel view of ``table`` (None: off, a zero table); ``views`` = (atmosphere, eye altitude [m above sea
    level], floor altitude [m], the sun's air sine) also builds the frame's view table (for cameras whose rays all
    start at the eye)."""
    out = AirMultiple()
    out.enabled = int(table is not None)
    values = np.zeros((NODES, 9, 3))
    if table is not None:
        values[:, 0], values[:, 1:4] = table.values, table.quadrupole
        if table.aerosol is not None:
            values[:, 4:] = table.aerosol
    out.values = device_buffers.upload(f"{name}:values", values.astype(np.float32), wp.vec3, device)
    out.floor = float(table.floor) if table is not None else 0.0
    out.height = float(table.height) if table is not None else 1.0
    out.view_nodes = 0
    if table is None or views is None:
        out.views = device_buffers.reusable(f"{name}:no views", (2, 11), wp.vec3, device)
    else:
        atmosphere, altitude, floor, air_sine = views
        out.views = device_buffers.reusable(f"{name}:views", (VIEW_NODES, 11), wp.vec3, device)
        air = analytic_air(atmosphere, np.zeros(3))
        wp.launch(view_table_kernel, dim=VIEW_NODES, inputs=[out, air, float(air_sine), float(altitude),
                                                             float(floor), out.views], device=device)
        out.view_nodes = VIEW_NODES
    return out


__all__ = ["AirMultiple", "MultipleTable", "air_radiance", "build", "multiple_along", "multiple_inscatter",
           "multiple_struct", "quadrupole_angular", "scene_table", "whole_ray"]
