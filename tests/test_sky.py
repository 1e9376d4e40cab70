"""The analytic sky against brute-force quadrature of Riley Eq. 8 (with Eqs. 10-12), degenerate angles included."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.sky_quadrature import BETA, GAMMA, cases, quadrature
from warpsky.media.air import analytic as sky


@pytest.mark.slow
def test_analytic_inscatter_matches_quadrature_including_degenerate_angles():
    worst = 0.0
    for h0, view_y, sun_y, distance in cases(1200):
        got = sky.inscatter(BETA, GAMMA, h0, view_y, sun_y, distance)
        want = quadrature(h0, view_y, sun_y, distance)
        assert np.all(np.isfinite(got)) and np.all(got >= 0.0)
        scale = max(want.max(), 1e-12)
        error = np.max(np.abs(got - want)) / scale
        worst = max(worst, error)
        assert error < 1e-3, (h0, view_y, sun_y, distance, got, want)
    print(f"worst relative error {worst:.2e}")


def test_float32_kernel_matches_float64(device):
    import warp as wp

    @wp.kernel
    def evaluate(rows: wp.array(dtype=wp.vec4), beta: wp.vec3, gamma: float, out: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        r = rows[i]
        out[i] = sky.air_inscatter(beta, gamma, r[0], r[1], r[2], r[3])

    rows = np.array([(h, v, s, 1e30 if np.isinf(d) else d) for h, v, s, d in cases(1200, seed=1)])
    out = wp.zeros(len(rows), dtype=wp.vec3, device=device)
    wp.launch(evaluate, dim=len(rows), inputs=[wp.array(rows.astype(np.float32), dtype=wp.vec4, device=device),
                                                 wp.vec3(*BETA.tolist()), GAMMA, out], device=device)
    got = out.numpy()
    want = np.array([sky.inscatter(BETA, GAMMA, h, v, s, np.inf if d >= 1e30 else d) for h, v, s, d in rows])
    assert np.all(np.isfinite(got)) and got.min() >= 0.0
    scale = np.maximum(want.max(axis=1, keepdims=True), 1e-12)
    assert np.max(np.abs(got - want) / scale) < 1e-4


def test_continuity_through_the_horizon_and_the_sun_elevation():
    for sun_y in (0.05, 0.4):
        v = np.concatenate([np.linspace(-0.01, 0.01, 2001), sun_y + np.linspace(-1e-3, 1e-3, 2001)])
        values = sky.inscatter(BETA[None, :], GAMMA, 10.0, v[:, None], sun_y, np.inf)
        for block in (values[:2001], values[2001:]):
            jumps = np.abs(np.diff(block, axis=0))
            neighbours = np.maximum(jumps[:-1], jumps[1:])
            assert np.all(jumps[1:-1] <= 2.0 * neighbours[1:] + 1e-12)


def test_sunset_reddens_and_noon_zenith_is_blue():
    noon = sky.inscatter(BETA, GAMMA, 0.0, 1.0, 1.0, np.inf)
    assert noon[2] > noon[1] > noon[0]
    ratios_sun, ratios_sky = [], []
    for sun_y in np.sin(np.radians([60, 30, 15, 8, 4, 2, 1])):
        t = sky.sun_transmittance(BETA, GAMMA, 0.0, sun_y)
        ratios_sun.append(t[0] / t[2])
        s = sky.inscatter(BETA, GAMMA, 0.0, 0.05, sun_y, np.inf)
        ratios_sky.append(s[0] / s[2])
    assert np.all(np.diff(ratios_sun) > 0) and np.all(np.diff(ratios_sky) > 0)


def test_transmittance_multiplies_over_split_segments():
    for view_y in (0.0, 1e-7, 0.3, -0.2):
        whole = sky.transmittance(BETA, GAMMA, 500.0, view_y, 5_000.0)
        first = sky.transmittance(BETA, GAMMA, 500.0, view_y, 2_000.0)
        second = sky.transmittance(BETA, GAMMA, 500.0 + view_y * 2_000.0, view_y, 3_000.0)
        np.testing.assert_allclose(whole, first * second, rtol=1e-12)
    np.testing.assert_array_equal(sky.transmittance(BETA, GAMMA, 0.0, 0.3, 0.0), 1.0)  # distance 0: identity
    # through the horizon the air mass stays finite (night comes from the disk's visible fraction, not from here)
    low = sky.sun_transmittance(BETA, GAMMA, 0.0, np.array([-0.1, 0.0, 0.05])[:, None])
    assert np.all(np.isfinite(low)) and np.all(low > 0.0) and np.all(np.diff(low, axis=0) > 0.0)
