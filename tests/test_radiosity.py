"""Bouthors 2006 §5 radiosity between the cloud base and the ground: closed form for infinite uniform planes,
ring (MIP) gather against the exact form-factor gather on a square cloud, snow, and the iteration cap."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from warpsky.passes.stratiform.radiosity import Radiosity, ground_direct, pyramid_shape


@pytest.mark.parametrize("rho_g,rho_c", [(0.15, 0.7), (0.9, 0.8), (0.5, 0.95)])
def test_infinite_uniform_planes_reach_the_closed_form(device, rho_g, rho_c):
    """Ground lit by S, cloud base of reflectance ρ_C: E = S / (1 - ρ_G ρ_C) within 1e-3."""
    shape = (16, 24)
    solver = Radiosity(tolerance=1e-5, device=device)
    result = solver.solve(ground_albedo=np.full(shape, rho_g), cloud_reflectance=np.full(shape, rho_c),
                          ground_direct=np.full((*shape, 3), 2.0))
    expected = 2.0 / (1.0 - rho_g * rho_c)
    np.testing.assert_allclose(result.ground_total, expected, rtol=1e-3)
    np.testing.assert_allclose(result.cloud_received, rho_g * expected, rtol=1e-3)
    assert result.converged and result.residual < 1e-5
    print(f"\nuniform planes rho_G={rho_g} rho_C={rho_c}: {result.iterations} iterations, residual "
          f"{result.residual:.2e}, E/closed form - 1 = {result.ground_total[0, 0, 1] / expected - 1:+.2e}")


def test_cloud_source_and_sky_through_gaps(device):
    """A diffuse source on the cloud plane reaches the ground once, then bounces like the direct light."""
    shape = (16, 16)
    rho_g, rho_c = 0.3, 0.6
    result = Radiosity(tolerance=1e-6, device=device).solve(
        ground_albedo=np.full(shape, rho_g), cloud_reflectance=np.full(shape, rho_c),
        ground_direct=np.zeros((*shape, 3)), cloud_source=np.full((*shape, 3), 1.5))
    np.testing.assert_allclose(result.ground_total, 1.5 / (1 - rho_g * rho_c), rtol=1e-3)


@pytest.mark.parametrize("detail,side,max_error", [(0, 8, 0.16), (1, 16, 0.13), (0, 4, 0.16)])
def test_ring_gather_against_exact_form_factors_on_a_square_cloud(device, detail, side, max_error):
    """A square cloud base (side 8h or 4h) of unit exitance over a dark ground: the three-ring MIP gather against
    the exact per-texel form factors. Measured: max error 15% of the peak at 1 texel per h, 12% at 2 texels per h;
    the integral over the ground agrees within 0.5%."""
    n = 64
    c = n // 2
    source = np.zeros((n, n))
    source[c - side // 2:c + side // 2, c - side // 2:c + side // 2] = 1.0
    ring = Radiosity(pixel_over_h=2.0**-detail, device=device).gather(source)[..., 1]
    exact = Radiosity(pixel_over_h=2.0**-detail, method="exact", device=device).gather(source)[..., 1]
    error = np.abs(ring - exact).max() / exact.max()
    print(f"\nsquare cloud {side * 2.0**-detail:g}h, {2**detail} texel(s) per h: ring vs exact max error "
          f"{error:.3f} of the peak, mean {np.abs(ring - exact).mean() / exact.mean():.3f}, integral ratio "
          f"{ring.sum() / exact.sum():.4f}")
    assert error < max_error
    assert ring.sum() == pytest.approx(exact.sum(), rel=0.005)
    # the exact gather of an infinite-looking plane: a 64h-wide uniform emitter gives ~1 at the centre
    uniform = Radiosity(pixel_over_h=1.0, method="exact", device=device).gather(np.ones((n, n)))[c, c, 1]
    # against midpoint quadrature of h² / (π r⁴) over the 64h square, in float64
    x = (np.arange(4096) + 0.5) / 4096 * 64 - 32
    r2 = x[:, None] ** 2 + x[None, :] ** 2 + 1.0
    assert uniform == pytest.approx(float(np.sum(1.0 / (np.pi * r2**2)) * (64 / 4096) ** 2), rel=1e-4)


def test_snow_converges_and_albedo_099_hits_the_cap_with_a_warning(device):
    shape = (16, 16)
    rng = np.random.default_rng(1)
    cloud = 0.6 + 0.3 * rng.random(shape)
    snow = Radiosity(device=device).solve(ground_albedo=np.full(shape, 0.9), cloud_reflectance=cloud,
                                          ground_direct=np.ones((*shape, 3)))
    assert snow.converged and snow.iterations < 64
    print(f"\nsnow (0.9): {snow.iterations} iterations, residual {snow.residual:.2e}")
    assert snow.warning is None
    capped = Radiosity(max_iterations=12, device=device).solve(
        ground_albedo=np.full(shape, 0.99), cloud_reflectance=np.full(shape, 0.99),
        ground_direct=np.ones((*shape, 3)))
    assert "residual" in capped.warning and "cap of 12 iterations" in capped.warning
    assert not capped.converged and capped.iterations == 12 and capped.residual > 1e-4
    assert np.all(np.isfinite(capped.ground_total))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        empty = Radiosity(device=device).solve(ground_albedo=np.full(shape, 0.99), cloud_reflectance=np.zeros(shape),
                                               ground_direct=np.ones((*shape, 3)))  # 0% cover: one pass, no bounce
    assert empty.converged and empty.iterations == 1
    np.testing.assert_allclose(empty.ground_total, 1.0)


def test_sun_shadow_parallax(device):
    """A single opaque texel on the cloud base shadows the ground h tan θ_l away from the sun."""
    n = 32
    tc = np.ones((n, n))
    tc[16, 16] = 0.0
    sun = np.array([np.sin(np.radians(45.0)), np.cos(np.radians(45.0)), 0.0])
    direct = ground_direct(tc, pixel=100.0, h=400.0, sun_direction=sun, sun_irradiance=[1.0, 1.0, 1.0],
                           device=device)
    dark = np.unravel_index(np.argmin(direct[..., 0]), direct.shape[:2])
    assert dark == (12, 16)  # 400 m x tan 45° = 4 texels away from the sun (+x)
    assert direct.max() == pytest.approx(sun[1], rel=1e-6)
    assert pyramid_shape((30, 17), 3) == (32, 24)
