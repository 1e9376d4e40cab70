"""Device kernels that evaluate the slab model of :mod:`warpsky.passes.stratiform.slab` on batches of inputs,
for the tests, the comparison with the Monte Carlo slab (:mod:`evaluation.stratiform_compare`) and the
benchmarks: per-order radiance, Appendix A energies, and the order-1/2 geometry factors.
"""

from __future__ import annotations

import warp as wp

from warpsky.passes.stratiform.slab import (
    MU_MIN,
    SlabOptics,
    double_reflect,
    double_transmit,
    order_energies,
    single_reflect,
    single_transmit,
    slab_radiance,
)


@wp.kernel
def slab_radiance_kernel(
    tables: wp.array(dtype=float),
    params: wp.array(dtype=float),
    optics: SlabOptics,
    thickness: wp.array(dtype=float),
    normal: wp.array(dtype=wp.vec3),
    sun: wp.array(dtype=wp.vec3),
    view: wp.array(dtype=wp.vec3),
    out: wp.array2d(dtype=wp.vec3),
):
    """Per-order radiance (rows 0..3 of ``out[i]``) for a batch of slab configurations (tests, benchmarks)."""
    i = wp.tid()
    s = slab_radiance(tables, params, optics, thickness[i], normal[i], sun[i], view[i])
    out[i, 0] = s.i0
    out[i, 1] = s.i1
    out[i, 2] = s.i2
    out[i, 3] = s.i3


@wp.kernel
def order_energies_kernel(
    params: wp.array(dtype=float),
    h_ref: wp.array(dtype=float),
    mu_l: wp.array(dtype=float),
    kappa_s_ref: float,
    out: wp.array2d(dtype=float),
):
    """Appendix A energies on the device (t0, t1, t2, t3p, r1, r2, r3p, t_ms), to test against :mod:`.model1d`."""
    i = wp.tid()
    e = order_energies(params, h_ref[i], mu_l[i], kappa_s_ref)
    out[i, 0] = e.t0
    out[i, 1] = e.t1
    out[i, 2] = e.t2
    out[i, 3] = e.t3p
    out[i, 4] = e.r1
    out[i, 5] = e.r2
    out[i, 6] = e.r3p
    out[i, 7] = e.t_ms


@wp.kernel
def slab_terms_kernel(
    mu_l: wp.array(dtype=float), mu_v: wp.array(dtype=float), depth: wp.array(dtype=float),
    out: wp.array2d(dtype=float),
):
    """The order-1/2 geometry factors (single/double reflect, single/double transmit) at (μ_l, μ_v, a), for the
    stiff-case tests."""
    i = wp.tid()
    ml = wp.max(mu_l[i], MU_MIN)
    mv = wp.max(mu_v[i], MU_MIN)
    out[i, 0] = single_reflect(ml, mv, depth[i])
    out[i, 1] = double_reflect(ml, mv, depth[i])
    out[i, 2] = single_transmit(ml, mv, depth[i])
    out[i, 3] = double_transmit(ml, mv, depth[i])
