"""Ice and snow phase functions against physics the test computes itself: prism minimum deviation, Fresnel, Cauchy.

Reference numbers here do not come from the code under test: refractive indices of ice at the band centres are
Warren & Brandt 2008's (650 nm 1.3080, 550 nm 1.3110, 450 nm 1.3157), halo angles follow from the prism formula
D = 2 asin(n sin(A / 2)) - A, slab reflectance from Fresnel at normal incidence, projected areas from Cauchy's
theorem (mean projected area of a convex body = surface / 4).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from warpsky.optics.grid import angle_grid, sphere_integral
from warpsky.optics.ice import bessel_j1, diffraction_phase, ice_optics, snow_optics, trace_prisms

#: Real index of ice at the R, G, B band centres (Warren & Brandt 2008).
INDEX_AT_CENTRES = (1.3080, 1.3110, 1.3157)
THETA_DEG = np.degrees(angle_grid())
#: Enough for 0.1°-node noise of ~3 % at the 46° halo, ~1.6 s per table on two CPU cores.
TEST_PHOTONS = 2_000_000


def minimum_deviation_deg(n: float, apex_deg: float) -> float:
    """Minimum deviation [deg] of a prism with apex angle ``apex_deg`` and index ``n``."""
    half = math.radians(apex_deg) / 2.0
    return math.degrees(2.0 * math.asin(n * math.sin(half))) - apex_deg


@functools.cache
def _ice(habit: str, device: str, seed: int = 7, photons: int = TEST_PHOTONS):
    return ice_optics(habit, seed=seed, photons=photons, device=device)


def _window(lo: float, hi: float) -> np.ndarray:
    return (THETA_DEG >= lo) & (THETA_DEG <= hi)


def _inner_edge(row: np.ndarray, lo: float, hi: float) -> float:
    """First angle [deg] in [lo, hi] where ``row`` reaches halfway from its minimum to its maximum there."""
    mask = _window(lo, hi)
    values = row[mask]
    return float(THETA_DEG[mask][np.argmax(values >= 0.5 * (values.min() + values.max()))])


def _smoothed(row: np.ndarray, nodes: int = 5) -> np.ndarray:
    return np.convolve(row, np.full(nodes, 1.0 / nodes), mode="same")


def test_prism_formula_reference_values():
    assert minimum_deviation_deg(1.31, 60.0) == pytest.approx(21.84, abs=0.01)
    assert minimum_deviation_deg(1.31, 90.0) == pytest.approx(45.73, abs=0.01)


@pytest.mark.parametrize("habit", ["column", "plate"])
def test_ice_tables_are_normalised_and_non_negative(habit, device):
    optics = _ice(habit, device, photons=TEST_PHOTONS if habit == "column" else 500_000)
    assert optics.phase.shape == (3, len(THETA_DEG))
    assert np.all(np.isfinite(optics.phase)) and optics.phase.min() >= 0.0
    np.testing.assert_allclose(sphere_integral(optics.phase), 1.0, atol=1e-3)
    np.testing.assert_allclose(sphere_integral(optics.geometric), 1.0, atol=1e-3)
    # strongly forward-scattering like all large crystals (literature: g ~ 0.75-0.85 for hexagonal prisms)
    assert np.all((optics.asymmetry > 0.7) & (optics.asymmetry < 0.9))
    np.testing.assert_allclose(optics.asymmetry, sphere_integral(optics.phase * np.cos(angle_grid())), rtol=1e-12)


def test_green_halo_peaks_at_22_and_46_degrees(device):
    green = _smoothed(_ice("column", device).phase[1])
    for apex, tolerance in ((60.0, 0.7), (90.0, 1.0)):
        expected = minimum_deviation_deg(INDEX_AT_CENTRES[1], apex)
        mask = _window(expected - 4.0, expected + 4.0)
        peak = float(THETA_DEG[mask][np.argmax(green[mask])])
        assert abs(peak - expected) <= tolerance, f"{apex:g} deg prism halo at {peak:.2f}, expected {expected:.2f}"
        # a real peak: well above the halo-free inside and above the tail 2 deg further out
        inside = green[np.argmin(np.abs(THETA_DEG - (expected - 2.0)))]
        outside = green[np.argmin(np.abs(THETA_DEG - (peak + 2.0)))]
        peak_value = green[np.argmin(np.abs(THETA_DEG - peak))]
        assert peak_value > 2.0 * inside and peak_value > outside


def test_halo_inner_edges_sit_at_minimum_deviation_red_inside_blue(device):
    phase = _ice("column", device).phase
    for apex in (60.0, 90.0):
        centre = minimum_deviation_deg(1.31, apex)
        edges = [_inner_edge(phase[c], centre - 4.0, centre + 4.0) for c in range(3)]
        for channel, edge in enumerate(edges):
            expected = minimum_deviation_deg(INDEX_AT_CENTRES[channel], apex)
            assert abs(edge - expected) <= 0.35, f"apex {apex:g}: channel {channel} edge {edge} vs {expected:.2f}"
        assert edges[0] < edges[1] < edges[2], f"red must lie inside blue: edges R, G, B = {edges}"


def test_slab_at_normal_incidence_reflects_fresnel_2r_over_1_plus_r(device):
    """Along the c-axis the column is a slab: back 2R/(1+R), forward (1-R)/(1+R), R = ((n-1)/(n+1))^2."""
    n = 1.31
    trace = trace_prisms(
        2.0, 200_000, seed=3, device=device, refractive_index=np.full((3, 1), n), rotation=(0.0, 0.0, 0.0, 1.0)
    )
    r = ((n - 1.0) / (n + 1.0)) ** 2
    left = trace.hits - trace.trapped
    back = trace.histogram[:, -1] / left
    forward = trace.histogram[:, 0] / left
    sigma = np.sqrt(2.0 * r / (1.0 + r) / left)
    np.testing.assert_allclose(back, 2.0 * r / (1.0 + r), atol=float(5.0 * sigma.max()))
    np.testing.assert_allclose(forward + back, 1.0, atol=1e-12)  # nothing else: the ray never meets a side face
    # silhouette = the hexagon (circumradius 1) inside the launch square
    hexagon = 1.5 * math.sqrt(3.0)
    np.testing.assert_allclose(trace.hits / (trace.hits + trace.misses), hexagon / trace.square_area, rtol=0.02)


def test_energy_is_conserved_and_hit_rate_gives_cauchy_area(device):
    trace = trace_prisms(2.0, 300_000, seed=5, device=device)
    np.testing.assert_array_equal(trace.hits + trace.misses, 300_000)
    # every photon that hit either left (tent weights sum to 1) or is counted as trapped by the interaction cap
    np.testing.assert_allclose(trace.histogram.sum(axis=1) + trace.trapped, trace.hits, rtol=0, atol=1e-6)
    assert np.all(trace.trapped / trace.hits < 2e-3)
    # mean projected area of a hexagonal prism, circumradius 1, length 4: surface / 4
    surface = 3.0 * math.sqrt(3.0) + 6.0 * 4.0
    measured = trace.hits / 300_000 * trace.square_area
    np.testing.assert_allclose(measured, surface / 4.0, rtol=0.01)

    optics = _ice("column", device)
    side, length = optics.crystal.diameter / 2.0, optics.crystal.length
    cauchy = (3.0 * math.sqrt(3.0) * side**2 + 6.0 * side * length) / 4.0
    np.testing.assert_allclose(optics.projected_area, cauchy, rtol=5e-3)


def test_same_seed_same_table_other_seed_differs(device):
    first = ice_optics("column", seed=11, photons=100_000, device=device)
    again = ice_optics("column", seed=11, photons=100_000, device=device)
    other = ice_optics("column", seed=12, photons=100_000, device=device)
    np.testing.assert_array_equal(first.phase, again.phase)
    assert not np.array_equal(first.phase, other.phase)


@pytest.mark.slow
def test_bessel_j1_and_airy_first_dark_ring():
    # Bessel's integral J1(z) = (1/pi) int_0^pi cos(t - z sin t) dt, by a 4000-point Gauss rule (exact to 1e-12)
    z = np.linspace(0.0, 400.0, 4001)
    nodes, weights = np.polynomial.legendre.leggauss(4000)
    t = 0.5 * np.pi * (nodes + 1.0)
    reference = (0.5 * weights) @ np.cos(t[:, None] - z[None, :] * np.sin(t)[:, None])
    np.testing.assert_allclose(bessel_j1(z), reference, atol=1e-9)
    radius, wavelength = 30e-6, 550e-9
    x = 2.0 * np.pi * radius / wavelength
    phase = diffraction_phase(radius, [wavelength])
    np.testing.assert_allclose(sphere_integral(phase), 1.0, atol=1e-6)
    first_zero = math.degrees(math.asin(3.8317 / x))  # first zero of J1
    mask = _window(0.5 * first_zero, 1.5 * first_zero)
    dark = float(THETA_DEG[mask][np.argmin(phase[mask])])
    assert abs(dark - first_zero) <= 0.02  # grid step 0.02 deg there


def test_snow_is_smooth_normalised_forward_scattering():
    snow = snow_optics()
    assert snow.phase.shape == (3, len(THETA_DEG))
    assert snow.phase.min() >= 0.0
    np.testing.assert_allclose(sphere_integral(snow.phase), 1.0, atol=1e-3)
    mask = _window(5.0, 175.0)
    assert np.all(np.diff(snow.phase[:, mask], axis=1) < 0.0), "snow must have no local maxima (no halos)"
    np.testing.assert_allclose(snow.asymmetry, 0.75, atol=5e-3)
