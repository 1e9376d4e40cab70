"""Ams_n (Riley Eq. 20) and F_n (Eq. 23) against closed forms and brute-force Monte Carlo; Bouthors' P_f."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.optics import multiple
from warpsky.optics.analytic import henyey_greenstein
from warpsky.optics.grid import angle_grid, cumulative, delta_table, normalise, sphere_integral

THETA = angle_grid()
MU = np.cos(THETA)


def hg_table(g: float) -> np.ndarray:
    return normalise(henyey_greenstein(MU, g)[None])


def test_order_zero_is_the_delta_and_order_one_the_phase_function():
    phase = hg_table(0.8)
    ams = multiple.ams_tables(phase, 3)
    np.testing.assert_array_equal(ams[0, 0], delta_table())
    np.testing.assert_array_equal(ams[1], phase)


@pytest.mark.parametrize("g", [0.5, 0.9, 0.99])
def test_hg_powers_are_hg_of_g_to_the_n(g):
    # Legendre coefficients of HG are g^l, so the n-fold convolution is HG with asymmetry g^n: a closed form
    ams, info = multiple.ams_tables(hg_table(g), 6, diagnostics=True)
    for n in range(2, 7):
        expected = hg_table(g**n)[0]
        np.testing.assert_allclose(ams[n, 0], expected, rtol=1e-3)
    np.testing.assert_allclose(info.raw_integral, 1.0, atol=1e-3)  # normalised before renormalisation


def sample_table(table: np.ndarray, count: int, rng) -> np.ndarray:
    """Scattering angles drawn from a tabulated phase function by inverse CDF (numpy, fine grid)."""
    fine = np.linspace(0.0, np.pi, 400001)
    density = np.interp(fine, THETA, table) * np.sin(fine)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(fine))])
    return np.interp(rng.random(count) * cdf[-1], cdf, fine)


def test_ams_2_matches_brute_force_monte_carlo(species_phase):
    cloud = species_phase("cloud")[1:2]
    ams = multiple.ams_tables(cloud, 2)[2, 0]
    rng = np.random.default_rng(7)
    count = 2_000_000
    first, second = sample_table(cloud[0], count, rng), sample_table(cloud[0], count, rng)
    phi = rng.random(count) * 2 * np.pi
    cos_total = np.cos(first) * np.cos(second) + np.sin(first) * np.sin(second) * np.cos(phi)
    total = np.arccos(np.clip(cos_total, -1.0, 1.0))
    edges = np.radians(np.concatenate([np.arange(0, 10, 1.0), np.arange(10, 180.1, 10.0)]))
    counts, _ = np.histogram(total, bins=edges)
    caps = np.array([sphere_integral(ams, upto=e) if e > 0 else 0.0 for e in edges])
    caps[-1] = sphere_integral(ams)
    expected = count * np.diff(caps)
    z = (counts - expected) / np.sqrt(expected)
    assert np.max(np.abs(z)) < 5.0, z  # 26 bins: |z| < 5 fails by chance with probability ~1e-5


@pytest.mark.slow
def test_rain_orders_to_60_stay_normalised_and_tend_to_isotropy(species_phase):
    rain = species_phase("rain")
    ams, info = multiple.ams_tables(rain, 60, diagnostics=True)
    np.testing.assert_allclose(sphere_integral(ams), 1.0, atol=1e-3)
    np.testing.assert_allclose(info.raw_integral[2:], 1.0, atol=5e-3)  # the series itself, before renormalising
    assert ams.min() >= -1e-6 * ams.max() and np.all(info.clipped < 1e-6)
    deviation = np.max(np.abs(4 * np.pi * ams - 1.0), axis=-1)  # (61, 3)
    assert np.all(np.diff(deviation[1:], axis=0) < 0)  # monotone approach to 1 / 4 pi
    assert np.all(deviation[60] < 1e-2)
    forward = multiple.forward_fractions(ams)
    np.testing.assert_allclose(forward[0], 1.0)
    np.testing.assert_allclose(forward[1], sphere_integral(rain, upto=np.pi / 2))
    np.testing.assert_allclose(forward[60], 0.5, atol=2e-3)


def test_convolution_is_commutative_and_matches_ams_2():
    a, b = hg_table(0.7), hg_table(0.3)
    np.testing.assert_allclose(multiple.convolve(a, b), multiple.convolve(b, a), rtol=1e-9)
    np.testing.assert_allclose(multiple.convolve(a, b), hg_table(0.21), rtol=1e-3)


def test_forward_weight_of_hg_has_its_closed_form():
    g, cut = 0.85, np.radians(5.0)
    expected = (1 - g * g) / (2 * g) * (1 / (1 - g) - 1 / np.sqrt(1 + g * g - 2 * g * np.cos(cut)))
    split = multiple.modified_mie(hg_table(g), cut)
    assert split.forward_weight[0] == pytest.approx(expected, rel=1e-4)
    for table in (split.p_s, split.p_f, split.p2):
        np.testing.assert_allclose(sphere_integral(table), 1.0, atol=1e-3)
    assert np.all(split.p_f[0][THETA > cut + 1e-9] == 0) and np.all(split.p_s[0][THETA < cut - 1e-9] == 0)


@pytest.mark.slow  # builds the stratus phase and modified Mie tables (about 15 s)
def test_bouthors_stratus_forward_weight(species_phase):
    # Bouthors 2006 §4.1 reports P_f = 51% for theta_f = 5 deg with his droplets; ours (N0 300/cm^3, gamma 2,
    # r_e 7 um, band-averaged) lands at 44-47%: the paper's figure is for a different spectral sampling
    split = multiple.modified_mie(species_phase("stratus"), np.radians(5.0))
    assert np.all((split.forward_weight > 0.40) & (split.forward_weight < 0.55))
    assert split.forward_weight[2] > split.forward_weight[0]  # blue: larger size parameter, more in the peak


def test_isotropic_order_reports_the_first_order_within_tolerance():
    ams = multiple.ams_tables(hg_table(0.5), 12)
    # HG(h) deviates from isotropy most at 0 and pi: 4 pi p = (1 + h)/(1 - h)^2 and (1 - h)/(1 + h)^2
    def deviation(h):
        return max((1 + h) / (1 - h) ** 2 - 1, 1 - (1 - h) / (1 + h) ** 2)

    expected = next(n for n in range(1, 13) if deviation(0.5**n) < 1e-2)
    assert multiple.isotropic_order(ams, 1e-2)[0] == expected
    assert np.isclose(cumulative(ams[5])[0, -1], 1.0)
