"""Mie tables: known angles of rainbows, glory and fogbow, normalisation, distributions, and the cache."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.optics import mie
from warpsky.optics.grid import angle_grid, sphere_integral

DEG = np.degrees(angle_grid())


def peak_angle(table: np.ndarray, lo: float, hi: float) -> float:
    """Scattering angle [deg] of the table's maximum within [lo, hi]."""
    inside = (DEG >= lo) & (DEG <= hi)
    return float(DEG[inside][np.argmax(table[inside])])


def geometric_bow(n: float, k: int) -> float:
    """Scattering angle [deg] of the k-th order rainbow of a sphere of index n (Descartes' minimum deviation)."""
    incidence = np.arccos(np.sqrt((n * n - 1.0) / (k * (k + 2))))
    refraction = np.arcsin(np.sin(incidence) / n)
    deviation = np.degrees(2.0 * (incidence - refraction) + k * (np.pi - 2.0 * refraction)) % 360.0
    return float(deviation if deviation <= 180.0 else 360.0 - deviation)


@pytest.mark.parametrize("name", ["cloud", pytest.param("rain", marks=pytest.mark.slow), "stratus"])
def test_mie_tables_are_normalised_and_non_negative(species_phase, name):
    table = species_phase(name)
    assert table.shape == (3, len(DEG))
    np.testing.assert_allclose(sphere_integral(table), 1.0, atol=1e-3)
    assert table.min() >= -1e-6 * table.max()
    # the forward diffraction peak is the global maximum, without negative lobes or ringing above it
    assert np.all(np.argmax(table, axis=1) == 0)


@pytest.mark.slow
def test_rain_primary_and_secondary_rainbows(species_phase):
    rain = species_phase("rain")
    green = rain[1]
    primary, secondary = peak_angle(green, 132.0, 145.0), peak_angle(green, 122.0, 133.0)
    assert 137.5 <= primary <= 138.6, primary  # bow radius 41.4-42.5 deg around the antisolar point
    assert 128.5 <= secondary <= 130.5, secondary
    # Descartes' angles for n = 1.333 (550 nm), independent of Mie: Airy/Mie maxima lie within ~0.5 deg
    assert abs(primary - geometric_bow(1.333, 1)) < 0.6
    assert abs(secondary - geometric_bow(1.333, 2)) < 1.0
    # Alexander's dark band between the bows is darker than either bow
    band = green[(DEG > secondary + 1.5) & (DEG < primary - 1.5)].mean()
    assert band < 0.5 * green[np.argmin(np.abs(DEG - primary))]
    assert band < green[np.argmin(np.abs(DEG - secondary))]
    # dispersion: red (lower index) bends less, so its primary bow has the larger radius = smaller angle
    red, blue = peak_angle(rain[0], 132.0, 145.0), peak_angle(rain[2], 132.0, 145.0)
    assert red < blue, (red, blue)


def test_cloud_glory_and_fogbow(species_phase):
    cloud = species_phase("cloud")
    for channel in range(3):
        assert peak_angle(cloud[channel], 170.0, 180.0) == pytest.approx(180.0)  # glory
        radius = 180.0 - peak_angle(cloud[channel], 120.0, 165.0)
        assert 32.0 <= radius <= 40.0, radius  # fogbow


def test_single_droplet_table_matches_miepython_asymmetry():
    import miepython

    # one radius, one wavelength, no smoothing: the table is miepython's own intensity, and g must agree
    optics = mie.mie_optics(mie.LogNormal(5e-6, 1e-6), samples=1, samples_per_band=1, sun_diameter_deg=0.0)
    wavelength = 550e-9
    x = 2 * np.pi * 5e-6 / wavelength
    _, _, _, g = miepython.efficiencies_mx(mie.water_index(wavelength), x)
    assert optics.asymmetry[1] == pytest.approx(g, abs=2e-3)


@pytest.mark.parametrize("distribution", [mie.CLOUD, mie.RAIN, mie.BOUTHORS_STRATUS])
def test_area_weighted_sampling_reproduces_the_effective_radius(distribution):
    # r_e = <r^3> / <r^2> is the mean radius of the area-weighted law; closed forms for both families
    u = (np.arange(20000) + 0.5) / 20000
    if isinstance(distribution, mie.LogNormal):
        expected = distribution.median * np.exp(2.5 * distribution.sigma_ln**2)
    else:
        expected = distribution.effective_radius
    assert distribution.area_weighted_quantiles(u).mean() == pytest.approx(expected, rel=2e-3)


def test_water_index_and_band_edges():
    assert mie.water_index(550e-9).real == pytest.approx(1.333)
    assert mie.water_index(400e-9).real > mie.water_index(700e-9).real  # normal dispersion
    with pytest.raises(ValueError, match="400-700 nm"):
        mie.water_index(380e-9)
    # the blue band reaches the edge of the visible range: 10 samples per band put one at 405 nm
    optics = mie.mie_optics(mie.CLOUD, samples=10, samples_per_band=10)
    np.testing.assert_allclose(sphere_integral(optics.phase), 1.0, atol=1e-3)
    assert np.all(np.isfinite(optics.phase)) and optics.phase.min() >= 0.0


def test_albedo_below_one_is_carried_to_the_tables(monkeypatch, tmp_path):
    from warpsky.optics import species, tables

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    dark = species.Species("air", (1e-31,) * 3, "rayleigh", albedo=(0.9, 0.8, 0.7))
    monkeypatch.setitem(species.SPECIES, "air", dark)
    built = tables.build_tables(["air"])
    np.testing.assert_allclose(built.albedo, [[0.9, 0.8, 0.7]])
    np.testing.assert_allclose(sphere_integral(built.phase[0]), 1.0, atol=1e-12)


def test_a_cloud_only_scene_builds_only_cloud_tables(monkeypatch, tmp_path):
    from warpsky.optics import tables

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    monkeypatch.setattr(tables, "BUILD_LOG", [])
    monkeypatch.setattr(mie, "default_samples", lambda distribution: 2)  # the kind of table is what matters
    first = tables.build_tables(["cloud"])
    assert {entry[0] for entry in first.built} == {"cloud"}
    calls = []
    monkeypatch.setattr(mie, "mie_optics", lambda *a, **k: calls.append(a))
    second = tables.build_tables(["cloud"])
    assert second.built == [] and calls == []  # a load, no Mie call
    np.testing.assert_array_equal(first.phase, second.phase)
    assert not tables.is_cached("rain") and not tables.is_cached("ice")
