"""Bouthors 2006 §4 on the device: per-pixel slab shading by scattering order (float32 ``@wp.func`` helpers).

A pixel of a stratiform layer is shaded as a homogeneous plane-parallel slab of thickness H lit by the sun
(unit irradiance at normal incidence; multiply by the sun's colour). Notation as in the paper: μ_l, μ_v are the
cosines of sun and view to the slab normal, θ the scattering angle (0 = forward, cos θ = L·d with d the view ray's
direction of travel and L the direction to the sun), a = κ_S H the slab's modified-Mie optical depth.

The paper's §4.3 and §4.4 formulas carry a stray factor κ (and κ²): integrating s(x) = κ e^{-κx} already gives a
dimensionless result. We use the dimensionally consistent forms (Chandrasekhar's single scattering; for double
scattering the "green path" of Fig. 7 — the second event on the way out, ∫ κ e^{-κk} e^{-κ(L-k)} dk = κL e^{-κL}):

====== ========================================================== =============================================
order  reflection (viewer on the sun's side)                      transmission
====== ========================================================== =============================================
0      --                                                         (τ_S(H_l) - τ(H_l)) G(θ): F* paths, the forward
                                                                  peak convolved n times (small-angle Gaussian of
                                                                  mean square n⟨θ²⟩_F, n the mean number of F
                                                                  events given at least one); the direct beam
                                                                  τ(H_v) is the layer's transmittance
1      P_S(θ) μ_l/(μ_l+μ_v) (1 - e^{-x}), x = a(1/μ_l + 1/μ_v)     P_S(θ) μ_l/(μ_v-μ_l) (τ(H_v) - τ(H_l))
2      P²(θ) μ_l²/(μ_l+μ_v)² (1 - (1 + x) e^{-x})                   P² (a/μ_v)² ∫₀¹ u e^{-a(1-u)/μ_l - au/μ_v} du
3+     R_3+ μ_l/π (Lambertian, vertical normal)                    T_3+ μ_l/π
====== ========================================================== =============================================

The paper's I_3+ = R_3+ μ_l/(4π μ_v) diverges at grazing views and exits only half of R_3+; a Lambertian exit
conserves R_3+ exactly. μ_v = μ_l in transmission is a 0/0 written in the stable forms
e^{-min} (1 - e^{-d})/d and their second-order analogues, with series below d = 0.1 (no branch on equality).
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import one_minus_exp_over_x
from warpsky.optics.kernels import table_phase

#: Directional cosines are clamped to at least this (grazing sun or view) before dividing.
MU_MIN = wp.constant(1.0e-6)
INV_PI = wp.constant(0.3183098861837907)
#: Appendix B row spacing [deg] and row count; columns b, c, κ_c, t, r.
B_STEP_DEG = wp.constant(10.0)
B_ROWS = wp.constant(10)
BETA = wp.constant(0.9961)
#: Table indices in the slab's phase tables (DevicePhaseTables of stacked P_S, P²).
TABLE_PS = wp.constant(0)
TABLE_P2 = wp.constant(1)


@wp.struct
class SlabOptics:
    """Optics of a stratiform layer's droplets.

    kappa: extinction κ = N0 π r_e² [1/m]; kappa_s: modified-Mie extinction (1 - P_f) κ per channel [1/m];
    to_reference: κ / κ_ref, multiplies metres into Appendix B's reference metres; forward_msq: ⟨θ²⟩ of P_F per
    channel [rad²].
    """

    kappa: float
    kappa_s: wp.vec3
    to_reference: float
    forward_msq: wp.vec3


@wp.struct
class Energies:
    """Appendix A energies per unit incident flux (see :mod:`.model1d`)."""

    t0: float
    t1: float
    t2: float
    t3p: float
    r1: float
    r2: float
    r3p: float
    t_ms: float


@wp.func
def h2_series(x: float) -> float:
    """(1 - (1 + x) e^{-x}) / x² for x >= 0 (1/2 at 0)."""
    if x < 0.1:
        return 0.5 - x * (1.0 / 3.0 - x * (0.125 - x * (1.0 / 30.0 - x * (1.0 / 144.0))))
    return (1.0 - (1.0 + x) * wp.exp(-x)) / (x * x)


@wp.func
def j2_series(y: float) -> float:
    """(e^{-y} - 1 + y) / y² for y >= 0 (1/2 at 0)."""
    if y < 0.1:
        return 0.5 - y * (1.0 / 6.0 - y * (1.0 / 24.0 - y * (1.0 / 120.0 - y * (1.0 / 720.0))))
    return (wp.exp(-y) - 1.0 + y) / (y * y)


@wp.func
def appendix_b(params: wp.array(dtype=float), theta_l_deg: float, column: int) -> float:
    """Appendix B column (0 b, 1 c, 2 κ_c, 3 t, 4 r) interpolated linearly at θ_l [deg], clamped to [0, 90]."""
    u = wp.clamp(theta_l_deg, 0.0, 90.0) / B_STEP_DEG
    i = wp.min(int(u), B_ROWS - 2)
    f = u - float(i)
    return params[i * 5 + column] * (1.0 - f) + params[(i + 1) * 5 + column] * f


@wp.func
def transmittance_ms(params: wp.array(dtype=float), h: float, theta_l_deg: float) -> float:
    """T_ms of ``h`` reference metres (Appendix A), clamped to [0, 1]."""
    b = appendix_b(params, theta_l_deg, 0)
    c = appendix_b(params, theta_l_deg, 1)
    hh = wp.max(h, 0.0)
    isotropic = BETA / (BETA + hh * (1.0 - BETA))
    return wp.clamp((b + (1.0 - b) * wp.exp(-c * hh)) * isotropic, 0.0, 1.0)


@wp.func
def order_energies(params: wp.array(dtype=float), h: float, mu_l: float, kappa_s_ref: float) -> Energies:
    """Appendix A per order for ``h`` reference metres, sun cosine ``mu_l`` to the vertical; ``kappa_s_ref`` is κ_S
    per reference metre. Low orders exceeding the total are scaled down to it (see :mod:`.model1d`)."""
    mu = wp.clamp(mu_l, MU_MIN, 1.0)
    theta_deg = wp.degrees(wp.acos(mu))
    hh = wp.max(h, 0.0)
    k = appendix_b(params, theta_deg, 2)
    t = appendix_b(params, theta_deg, 3)
    r = appendix_b(params, theta_deg, 4)
    x = 2.0 * k * hh
    tau1 = wp.exp(-k * hh)
    tau2 = tau1 * tau1
    tau3 = tau2 * tau1
    out = Energies()
    t_ms = transmittance_ms(params, hh, theta_deg)
    r_ms = 1.0 - t_ms
    t0 = wp.exp(-kappa_s_ref * hh / mu)
    t1 = t * hh * k * tau1
    t2 = 0.5 * (k * t * hh) * (k * t * hh) * tau1 + 0.25 * r * r * (1.0 + (x - 1.0) * tau2) * tau3
    r1 = 0.5 * r * x * one_minus_exp_over_x(x)
    r2 = 0.5 * r * t * x * x * h2_series(x)
    low_t = t0 + t1 + t2
    scale_t = float(1.0)
    if low_t > t_ms:
        scale_t = t_ms / low_t
    low_r = r1 + r2
    scale_r = float(1.0)
    if low_r > r_ms:
        scale_r = r_ms / wp.max(low_r, 1.0e-30)
    out.t0 = t0 * scale_t
    out.t1 = t1 * scale_t
    out.t2 = t2 * scale_t
    out.t3p = wp.max(t_ms - low_t * scale_t, 0.0)
    out.r1 = r1 * scale_r
    out.r2 = r2 * scale_r
    out.r3p = wp.max(r_ms - low_r * scale_r, 0.0)
    out.t_ms = t_ms
    return out


@wp.func
def single_reflect(mu_l: float, mu_v: float, a: float) -> float:
    """μ_l/(μ_l+μ_v) (1 - e^{-a(1/μ_l+1/μ_v)}) (multiply by P_S(θ))."""
    x = a * (1.0 / mu_l + 1.0 / mu_v)
    return mu_l / (mu_l + mu_v) * x * one_minus_exp_over_x(x)


@wp.func
def single_transmit(mu_l: float, mu_v: float, a: float) -> float:
    """μ_l/(μ_v-μ_l) (e^{-a/μ_v} - e^{-a/μ_l}) as (a/μ_v) e^{-min} (1 - e^{-d})/d; exact at μ_v = μ_l."""
    av = a / mu_v
    al = a / mu_l
    return av * wp.exp(-wp.min(av, al)) * one_minus_exp_over_x(wp.abs(av - al))


@wp.func
def double_reflect(mu_l: float, mu_v: float, a: float) -> float:
    """μ_l²/(μ_l+μ_v)² (1 - (1 + x) e^{-x}), x = a(1/μ_l+1/μ_v) (multiply by P²(θ))."""
    x = a * (1.0 / mu_l + 1.0 / mu_v)
    w = mu_l / (mu_l + mu_v)
    return w * w * x * x * h2_series(x)


@wp.func
def double_transmit(mu_l: float, mu_v: float, a: float) -> float:
    """(a/μ_v)² ∫₀¹ u e^{-a(1-u)/μ_l - au/μ_v} du in closed form: (a/μ_v)² e^{-a/μ_l} h2(x) for x = a/μ_v - a/μ_l
    >= 0, (a/μ_v)² e^{-a/μ_v} j2(-x) otherwise (never overflows; (a/μ)² e^{-a/μ} / 2 at μ_v = μ_l)."""
    av = a / mu_v
    al = a / mu_l
    x = av - al
    if x >= 0.0:
        return av * av * wp.exp(-al) * h2_series(x)
    return av * av * wp.exp(-av) * j2_series(-x)


@wp.func
def forward_peak(theta: float, msq: float) -> float:
    """Small-angle Gaussian of mean square angle ``msq`` [rad²], normalised over the sphere [1/sr]."""
    s = wp.max(msq, 1.0e-12)
    return wp.exp(-theta * theta / s) / (wp.pi * s)


@wp.struct
class SlabRadiance:
    """Radiance per order for unit sun irradiance [1/sr]; ``reflect`` 1 when viewer and sun share a side."""

    i0: wp.vec3
    i1: wp.vec3
    i2: wp.vec3
    i3: wp.vec3
    reflect: int


@wp.func
def slab_radiance(
    tables: wp.array(dtype=float),
    params: wp.array(dtype=float),
    optics: SlabOptics,
    thickness: float,
    normal: wp.vec3,
    sun: wp.vec3,
    view: wp.vec3,
) -> SlabRadiance:
    """Orders 0, 1, 2, 3+ of a slab ``thickness`` [m] with local (outward, either side) ``normal`` for orders 1-2
    and the vertical for 3+; ``sun`` points to the sun, ``view`` is the ray's direction of travel."""
    out = SlabRadiance()
    out.i0 = wp.vec3(0.0)
    out.i1 = wp.vec3(0.0)
    out.i2 = wp.vec3(0.0)
    out.i3 = wp.vec3(0.0)
    h = wp.max(thickness, 0.0)
    ls = wp.dot(sun, normal)
    vs = -wp.dot(view, normal)  # > 0: the viewer is on the normal's side
    out.reflect = int(ls * vs > 0.0)
    mu_l = wp.max(wp.abs(ls), MU_MIN)
    mu_v = wp.max(wp.abs(vs), MU_MIN)
    # vertical cosines for the diffuse 3+ term (§6)
    mu_l3 = wp.max(wp.abs(sun[1]), MU_MIN)
    reflect3 = sun[1] * (-view[1]) > 0.0
    if h <= 0.0:
        return out
    theta = wp.atan2(wp.length(wp.cross(sun, view)), wp.dot(sun, view))
    p_s = table_phase(tables, TABLE_PS, theta)
    p_2 = table_phase(tables, TABLE_P2, theta)
    h_ref = h * optics.to_reference
    for c in range(3):
        a = optics.kappa_s[c] * h
        e = order_energies(params, h_ref, mu_l3, optics.kappa_s[c] / optics.to_reference)
        if out.reflect != 0:
            out.i1[c] = p_s[c] * single_reflect(mu_l, mu_v, a)
            out.i2[c] = p_2[c] * double_reflect(mu_l, mu_v, a)
        else:
            out.i1[c] = p_s[c] * single_transmit(mu_l, mu_v, a)
            out.i2[c] = p_2[c] * double_transmit(mu_l, mu_v, a)
            # F* paths: at least one forward-peak event and no S event
            hl = h / mu_l
            kf = wp.max(optics.kappa - optics.kappa_s[c], 0.0)
            bf = kf * hl
            f_share = one_minus_exp_over_x(bf)  # (1 - e^{-b}) / b
            n_mean = 1.0 / f_share
            out.i0[c] = wp.exp(-optics.kappa_s[c] * hl) * bf * f_share * forward_peak(
                theta, n_mean * optics.forward_msq[c])
        if reflect3:
            out.i3[c] = e.r3p * mu_l3 * INV_PI
        else:
            out.i3[c] = e.t3p * mu_l3 * INV_PI
    return out
