"""The light a round earth's air sends along a ray, on the device: single scattering of the sun (its transmittance
from the table of optical depths, its disk clipped by each point's own horizon) and the light scattered more than
once (the table of :mod:`~warpsky.media.air.round_earth_multiple`), by the panel quadrature of
:mod:`~warpsky.media.air.round_earth_kernels`.

Along a straight ray from altitude h0 with elevation sine mu0, towards a sun of elevation sine mu_s0 at the start,
nu = cos(view, sun) is constant and a point at distance t sees the sun at elevation sine (r0 mu_s0 + t nu) / r
(Bruneton 2017), so the phase functions factor out of the integrals:

    S_c = int sigma_s,c T T_sun dt (c: the Rayleigh gas, the aerosols),   M = int sigma_s T Psi(h, mu_s) dt,

and the radiance is E (P_R(nu) S_R + P_M(nu) S_M + M).
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import exp3
from warpsky.media.air.analytic import AnalyticAir
from warpsky.media.air.mixture_kernels import AirScatter
from warpsky.media.air.round_earth_kernels import (
    PANEL_NODES,
    Line,
    PanelExtinction,
    Panels,
    RoundAir,
    depth_to_node,
    make_line,
    panel_bound,
    panel_depth,
    panel_extinction,
    panel_node,
    piece_bounds,
    side,
    sun_coordinate,
    sun_transmittance,
)

#: The multiple-scattering table's logarithms are of the values plus this
#: (:mod:`~warpsky.media.air.round_earth_multiple`).
LOG_FLOOR_WP = wp.constant(1.0e-30)


@wp.struct
class RoundMultiple:
    """The multiple-scattering table Psi(h, mu_s) as kernels see it (``enabled`` 0: single scattering only)."""

    enabled: int
    psi: wp.array3d(dtype=wp.vec3)  # (heights, suns, 7): Psi, J_2, Q_uu, Q_hh, Q_uh, F_u, F_h per unit irradiance
    mie_g: float  # the aerosols' Henyey-Greenstein g
    radius: float  # the planet's at sea level [m]
    floor: float  # altitude of the first row [m above sea level]
    height: float  # the rows span floor + height u^2, u uniform in [0, 1]


@wp.struct
class MultipleAt:
    """The table at one point of a view ray: the isotropic Psi (for every scatterer) and the second order's
    anisotropic parts towards the view for the Rayleigh gas and for the aerosols, per unit irradiance, RGB."""

    isotropic: wp.vec3
    rayleigh: wp.vec3
    mie: wp.vec3


@wp.func
def multiple_terms(ms: RoundMultiple, h: float, mu_s: float, mu: float, nu: float) -> MultipleAt:
    """The table at altitude ``h`` for a sun of elevation sine ``mu_s`` there, towards a view of elevation sine
    ``mu`` there and cos(view, sun) ``nu``: bilinear in u = sqrt((h - floor) / height) and in the sun's
    :func:`~warpsky.media.air.round_earth_kernels.sun_coordinate` (rows dense near the floor, columns near the point's
    horizon), Psi and J_2 through their logarithms, the moments as fractions of J_2."""
    u = wp.sqrt(wp.clamp((h - ms.floor) / ms.height, 0.0, 1.0)) * float(ms.psi.shape[0] - 1)
    v = sun_coordinate(ms.radius, ms.floor, h, mu_s)
    s = wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(ms.psi.shape[1] - 1)
    i = wp.min(int(u), ms.psi.shape[0] - 2)
    j = wp.min(int(s), ms.psi.shape[1] - 2)
    a = u - float(i)
    b = s - float(j)
    # the view in the point's frame: up, towards the sun's azimuth, across
    sun_across = wp.sqrt(wp.max(1.0 - mu_s * mu_s, 0.0))
    v_h = float(0.0)
    if sun_across > 1.0e-6:
        v_h = wp.clamp((nu - mu * mu_s) / sun_across, -1.0, 1.0)
    v_s2 = wp.max(1.0 - mu * mu - v_h * v_h, 0.0)
    quadratic = wp.vec3(mu * mu - v_s2, v_h * v_h - v_s2, 2.0 * mu * v_h)
    terms = MultipleAt()
    form = wp.vec3(0.0)
    dipole = wp.vec3(0.0)
    for term in range(7):
        value = ((ms.psi[i, j, term] * (1.0 - b) + ms.psi[i, j + 1, term] * b) * (1.0 - a)
                 + (ms.psi[i + 1, j, term] * (1.0 - b) + ms.psi[i + 1, j + 1, term] * b) * a)
        if term == 0:
            terms.isotropic = from_log(value)
        elif term == 1:
            terms.mie = from_log(value)  # J_2 for now
        elif term < 5:
            form += value * quadratic[term - 2]
        elif term == 5:
            dipole += value * mu
        else:
            dipole += value * v_h
    g = ms.mie_g
    j2 = terms.mie
    out = MultipleAt()
    out.isotropic = terms.isotropic
    out.rayleigh = wp.cw_mul(j2, form) * (3.0 / (16.0 * wp.pi))
    aerosol = wp.cw_mul(j2, dipole * (3.0 * g) + form * (7.5 * g * g)) / (4.0 * wp.pi)
    for c in range(3):
        out.mie[c] = wp.max(aerosol[c], -j2[c])
    return out


@wp.func
def from_log(value: wp.vec3) -> wp.vec3:
    """exp(value) - LOG_FLOOR per channel, not below 0 (the table's logarithms)."""
    return wp.vec3(wp.max(wp.exp(value[0]) - LOG_FLOOR_WP, 0.0), wp.max(wp.exp(value[1]) - LOG_FLOOR_WP, 0.0),
                   wp.max(wp.exp(value[2]) - LOG_FLOOR_WP, 0.0))


@wp.func
def scattering_at(air: AnalyticAir, h: float) -> AirScatter:
    """The Rayleigh gas's and the aerosols' scattering coefficients [1/m] at altitude ``h``."""
    out = AirScatter()
    out.rayleigh = air.beta_sea_level * wp.exp(-air.gamma * h)
    if air.mixed != 0:
        out.mie = wp.cw_mul(air.mie_extinction, air.mie_albedo) * wp.exp(-air.mie_gamma * h)
    return out


@wp.struct
class LitNode:
    """One quadrature node of a ray with the sun: its altitude, the ray's transmittance to it, the sun's elevation
    sine there, the air's scattering there and the node's weight dt."""

    h: float
    t: float  # distance along the ray [m]
    t_view: wp.vec3
    mu_s: float
    parts: AirScatter
    dt: float


@wp.func
def lit_node(air: AnalyticAir, ra: RoundAir, line: Line, s: Panels, panel: PanelExtinction, tau: wp.vec3,
             h_a: float, h_b: float, j: int, mu_s0: float, nu: float) -> LitNode:
    """Node ``j`` of the panel [h_a, h_b] of side ``s`` (whose extinction is ``panel``, ``tau`` the ray's optical
    depth at the panel's start), for a sun of elevation sine ``mu_s0`` at the ray's start and cos(ray, sun) ``nu``."""
    node = panel_node(line, s, h_a, h_b, j)
    out = LitNode()
    out.h = node.h
    out.t = node.t
    out.t_view = exp3(tau + depth_to_node(panel, j))
    out.mu_s = wp.clamp((line.r0 * mu_s0 + node.t * nu) / (ra.radius + node.h), -1.0, 1.0)
    out.parts = scattering_at(air, node.h)
    out.dt = node.dt
    return out


@wp.struct
class RoundLight:
    """Integrals along one ray (multiply the first three by E, the single-scattering ones by their phase)."""

    rayleigh: wp.vec3  # int sigma_s,R T T_sun dt
    mie: wp.vec3  # int sigma_s,M T T_sun dt
    multiple: wp.vec3  # int sigma_s T Psi dt
    depth: wp.vec3  # the ray's optical depth


@wp.struct
class SunGeometry:
    """The sun as a ray sees it: its elevation sine at the ray's start, cos(view, sun), its disk's radius."""

    mu_s0: float
    nu: float
    radius: float  # [rad]


@wp.func
def round_light(air: AnalyticAir, ra: RoundAir, ms: RoundMultiple, h0: float, mu0: float, sun: SunGeometry,
                distance: float) -> RoundLight:
    """The single- and multiple-scattering integrals and the optical depth over ``distance`` [m] of the ray from
    altitude ``h0`` [m above sea level] of elevation sine ``mu0`` (staying above the floor)."""
    line = make_line(ra, h0, mu0)
    out = RoundLight()
    tau = wp.vec3(0.0)
    for piece in range(2):
        bounds = piece_bounds(line, piece, distance)
        if bounds[1] > bounds[0]:
            s = side(ra, line, bounds[0], bounds[1])
            for k in range(s.count):
                h_a = panel_bound(ra, line, s, k)
                h_b = panel_bound(ra, line, s, k + 1)
                panel = panel_extinction(air, line, s, h_a, h_b)
                for j in range(PANEL_NODES):
                    n = lit_node(air, ra, line, s, panel, tau, h_a, h_b, j, sun.mu_s0, sun.nu)
                    lit = wp.cw_mul(n.t_view, sun_transmittance(ra, n.h, n.mu_s, sun.radius)) * n.dt
                    out.rayleigh += wp.cw_mul(n.parts.rayleigh, lit)
                    out.mie += wp.cw_mul(n.parts.mie, lit)
                    if ms.enabled != 0:
                        mu = wp.clamp((line.r0 * mu0 + n.t) / (ra.radius + n.h), -1.0, 1.0)
                        terms = multiple_terms(ms, n.h, n.mu_s, mu, sun.nu)
                        out.multiple += wp.cw_mul(n.t_view, wp.cw_mul(n.parts.rayleigh + n.parts.mie,
                                                                      terms.isotropic)
                                                  + wp.cw_mul(n.parts.rayleigh, terms.rayleigh)
                                                  + wp.cw_mul(n.parts.mie, terms.mie)) * n.dt
                tau += panel_depth(panel)
    out.depth = tau
    return out
