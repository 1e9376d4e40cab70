"""The shared grid, analytic phase models, cached tables, device lookup and inverse-CDF sampling."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.core.errors import SceneError
from warpsky.optics import analytic
from warpsky.optics.grid import angle_grid, cumulative, normalise, sphere_integral


def fine_mu_quadrature(p):
    """Independent check: composite Gauss-Legendre in theta, geometrically refined towards 0 so that peaks as
    narrow as 1e-4 rad are resolved; returns (integral over the sphere, mean cosine)."""
    x, w = np.polynomial.legendre.leggauss(20)
    edges = np.concatenate([[0.0], np.geomspace(1e-7, 0.2, 300), np.linspace(0.2, np.pi, 400)[1:]])
    half = 0.5 * np.diff(edges)[:, None]
    theta = (half * x + 0.5 * (edges[1:] + edges[:-1])[:, None]).ravel()
    weights = (half * w).ravel() * 2 * np.pi * np.sin(theta)
    mu = np.cos(theta)
    values = p(mu)
    return np.sum(weights * values), np.sum(weights * values * mu)


def test_grid_integrals_are_exact_for_piecewise_linear_tables():
    theta = angle_grid()
    assert theta[0] == 0.0 and theta[-1] == pytest.approx(np.pi) and np.all(np.diff(theta) > 0)
    assert np.degrees(np.diff(theta)).max() <= 0.1 + 1e-9  # Riley used 0.18 deg; we stay <= 0.1 deg
    assert sphere_integral(np.ones_like(theta)) == pytest.approx(4 * np.pi, rel=1e-14)
    assert sphere_integral(np.ones_like(theta), upto=np.pi / 2) == pytest.approx(2 * np.pi, rel=1e-14)
    # a table linear in theta: integral 2 pi int theta sin theta = 2 pi [sin - theta cos]_0^pi = 2 pi^2
    assert sphere_integral(theta) == pytest.approx(2 * np.pi**2, rel=1e-12)
    cdf = cumulative(np.vstack([theta, np.ones_like(theta)]))
    np.testing.assert_allclose(cdf[:, -1], [2 * np.pi**2, 4 * np.pi], rtol=1e-12)


def test_rayleigh_matches_riley_eq_1():
    mu = np.linspace(-1, 1, 7)
    np.testing.assert_allclose(analytic.rayleigh(mu), 3 / (16 * np.pi) * (1 + mu**2), rtol=1e-15)
    total, mean_cos = fine_mu_quadrature(analytic.rayleigh)
    assert total == pytest.approx(1.0, rel=1e-12) and abs(mean_cos) < 1e-12


@pytest.mark.parametrize("g", [-0.5, 0.0, 0.3, 0.85, 0.95])
def test_henyey_greenstein_normalised_with_mean_cosine_g(g):
    total, mean_cos = fine_mu_quadrature(lambda mu: analytic.henyey_greenstein(mu, g))
    assert total == pytest.approx(1.0, rel=1e-9) and mean_cos == pytest.approx(g, abs=1e-9)


def test_two_term_hg_moments():
    total, mean_cos = fine_mu_quadrature(lambda mu: analytic.two_term_hg(mu, 0.9, -0.3, 0.7))
    assert total == pytest.approx(1.0, rel=1e-9) and mean_cos == pytest.approx(0.7 * 0.9 - 0.3 * 0.3, abs=1e-9)


@pytest.mark.parametrize("d", [5.0, 10.0, 20.0, 50.0])
def test_hg_draine_normalised_with_its_closed_form_mean_cosine(d):
    p = analytic.jendersie_deon_params(d)
    total, mean_cos = fine_mu_quadrature(lambda mu: analytic.hg_draine(mu, d))
    # Draine 2003: <cos> = g (1 + a (3 + 2 g^2) / 5) / (1 + a (1 + 2 g^2) / 3)
    g, a = p.g_draine, p.alpha
    draine_mean = g * (1 + a * (3 + 2 * g * g) / 5) / (1 + a * (1 + 2 * g * g) / 3)
    assert total == pytest.approx(1.0, rel=1e-7)
    assert mean_cos == pytest.approx((1 - p.w_draine) * p.g_hg + p.w_draine * draine_mean, abs=1e-7)


def test_hg_draine_fit_values():
    """The published fits at d = 10 um, evaluated by hand from Jendersie & d'Eon 2023's expressions."""
    p = analytic.jendersie_deon_params(10.0)
    assert p.g_hg == pytest.approx(np.exp(-0.0990567 / 8.32846), rel=1e-12)
    assert p.g_draine == pytest.approx(np.exp(-2.20679 / 13.91029 - 0.428934), rel=1e-12)
    assert p.alpha == pytest.approx(np.exp(3.62489 - 8.29288 / 15.52825), rel=1e-12)
    assert p.w_draine == pytest.approx(np.exp(-0.599085 / 9.358417 - 0.665888), rel=1e-12)
    assert 0.98 < p.g_hg < 0.99 and 0.3 < p.w_draine < 0.5
    with pytest.raises(SceneError, match="5-50 um"):
        analytic.jendersie_deon_params(60.0)


def test_air_table_is_cached_and_second_build_is_a_load(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    from warpsky.optics import tables

    first = tables.build_tables(["air"])
    assert [(n, k) for n, k, _ in first.built] == [("air", "phase")]
    second = tables.build_tables(["air"])
    assert second.built == []
    np.testing.assert_array_equal(first.phase, second.phase)
    assert sphere_integral(second.phase[0]) == pytest.approx(np.ones(3), rel=1e-12)
    np.testing.assert_allclose(second.extinction_cross_section, [[2.28e-31, 5.33e-31, 1.30e-30]])


def hg_tables():
    theta = angle_grid()
    return np.stack([normalise(np.stack([analytic.henyey_greenstein(np.cos(theta), g) for g in (0.2, 0.85, 0.97)]))])


def test_device_lookup_matches_host_interpolation(device):
    from warpsky.optics.kernels import DevicePhaseTables, lookup

    table = hg_tables()
    tables = DevicePhaseTables.upload(table, device)
    rng = np.random.default_rng(4)
    angles = np.concatenate([rng.uniform(0, np.pi, 3000), np.radians([0.0, 0.001, 0.5, 5.0, 170.0, 180.0])])
    values = lookup(tables, 0, angles, device)
    theta = angle_grid()
    expected = np.stack([np.interp(angles.astype(np.float32), theta, table[0, c]) for c in range(3)], axis=1)
    np.testing.assert_allclose(values, expected, rtol=2e-5, atol=1e-6 * expected.max())


@pytest.mark.parametrize("channel", [0, 1, 2])
def test_sampling_chi_square_against_table(device, channel):
    """Histogram of 400k samples in bins aligned with grid nodes vs the table's exact bin masses."""
    from warpsky.optics.kernels import DevicePhaseTables, sample

    table = hg_tables()
    tables = DevicePhaseTables.upload(table, device)
    count = 400_000
    samples = sample(tables, channel, count, seed=7, device=device)
    theta = angle_grid()
    edges = theta[:: 25]
    edges = np.append(edges, theta[-1]) if edges[-1] != theta[-1] else edges
    cdf = cumulative(table[0, channel])
    masses = np.diff(np.interp(edges, theta, cdf)) / cdf[-1]
    observed, _ = np.histogram(samples[:, 0], bins=edges)
    keep = masses * count > 20
    expected = masses[keep] * count
    chi2 = np.sum((observed[keep] - expected) ** 2 / expected)
    dof = keep.sum() - 1
    # mean dof, sd sqrt(2 dof): 5 sd is a p-value far below 1e-3
    assert chi2 < dof + 5 * np.sqrt(2 * dof), (chi2, dof)
    # the returned pdf is the sampling density: its mean of 1/pdf over samples estimates 4 pi (the sphere)
    assert np.mean(1.0 / samples[:, 1]) == pytest.approx(4 * np.pi, rel=0.05)


def chi_square(samples: np.ndarray, table: np.ndarray) -> tuple[float, int]:
    """chi^2 of sampled angles against the exact bin masses of a tabulated phase function (bins of 25 nodes)."""
    theta = angle_grid()
    edges = theta[::25]
    edges = np.append(edges, theta[-1]) if edges[-1] != theta[-1] else edges
    cdf = cumulative(table)
    masses = np.diff(np.interp(edges, theta, cdf)) / cdf[-1]
    observed, _ = np.histogram(samples, bins=edges)
    keep = masses * len(samples) > 20
    expected = masses[keep] * len(samples)
    return float(np.sum((observed[keep] - expected) ** 2 / expected)), int(keep.sum() - 1)


@pytest.mark.parametrize("name", ["cloud", pytest.param("rain", marks=pytest.mark.slow)])
def test_sampling_chi_square_for_mie_tables(device, species_phase, name):
    """The path tracer samples species by the green row's inverse CDF: chi^2 against cloud and rain Mie tables."""
    from warpsky.optics.kernels import DevicePhaseTables, sample

    table = species_phase(name)
    samples = sample(DevicePhaseTables.upload(table[None], device), 1, 400_000, seed=3, device=device)
    chi2, dof = chi_square(samples[:, 0], table[1])
    assert chi2 < dof + 5 * np.sqrt(2 * dof), (chi2, dof)


def test_path_tracer_hg_sampling_chi_square(device):
    """Henyey-Greenstein sampling of the path tracer (exact inversion) against the closed-form CDF in cos theta."""
    import warp as wp

    from warpsky.optics.phase import hg_sample_cos

    @wp.kernel
    def draw(g: float, out: wp.array(dtype=float)):
        i = wp.tid()
        state = wp.rand_init(11, i)
        out[i] = hg_sample_cos(g, wp.randf(state))

    for g in (0.0, 0.85, -0.5):
        count = 200_000
        out = wp.zeros(count, dtype=float, device=device)
        wp.launch(draw, dim=count, inputs=[g, out], device=device)
        mu = out.numpy()
        edges = np.linspace(-1.0, 1.0, 101)
        if abs(g) < 1e-4:
            cdf = (edges + 1.0) / 2.0
        else:  # P(cos <= m) = (1 - g^2) / (2 g) (1 / sqrt(1 + g^2 - 2 g m) - 1 / (1 + g))
            cdf = (1 - g * g) / (2 * g) * (1 / np.sqrt(1 + g * g - 2 * g * edges) - 1 / (1 + g))
        expected = np.diff(cdf) * count
        observed, _ = np.histogram(mu, bins=edges)
        keep = expected > 20
        chi2 = np.sum((observed[keep] - expected[keep]) ** 2 / expected[keep])
        dof = keep.sum() - 1
        assert chi2 < dof + 5 * np.sqrt(2 * dof), (g, chi2, dof)
