"""Water content to extinction (warpsky.model.water_optics): the ideal-gas air density, the size distributions'
closed forms against numerical integrals over their drops, and agreement with the species' cross sections
(Riley et al. 2004, Table 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpsky.core.errors import SceneError
from warpsky.model.water_optics import (
    CP_DRY,
    EPSILON,
    HYDROMETEORS,
    P0,
    R_DRY,
    Hydrometeor,
    dry_air_density,
    extinction,
    species_extinction,
    temperature_from_theta,
    water_content,
)


def test_air_density_is_the_ideal_gas_law():
    # 1e5 Pa at 273.15 K: 1.2754 kg/m^3 (R_d = 287.04 J/(kg K))
    np.testing.assert_allclose(dry_air_density(1.0e5, 273.15), 1.0e5 / (287.04 * 273.15), rtol=1e-12)
    np.testing.assert_allclose(dry_air_density(1.0e5, 273.15), 1.2754, rtol=1e-4)
    # with vapour: the dry air's partial pressure is p - e, e = p q_v / (eps + q_v)
    q_v = 0.012
    partial = 1.0e5 - 1.0e5 * q_v / (EPSILON + q_v)
    np.testing.assert_allclose(dry_air_density(1.0e5, 290.0, q_v), partial / (R_DRY * 290.0), rtol=1e-12)


def test_temperature_from_potential_temperature():
    np.testing.assert_allclose(temperature_from_theta(300.0, P0), 300.0)
    # 500 hPa, theta 320 K: T = 320 * 0.5^(R/cp) = 262.5 K
    np.testing.assert_allclose(temperature_from_theta(320.0, 5.0e4), 320.0 * 0.5 ** (R_DRY / CP_DRY), rtol=1e-12)
    assert 262.0 < float(temperature_from_theta(320.0, 5.0e4)) < 263.0


def test_bad_air_is_refused():
    with pytest.raises(SceneError, match="pressure"):
        dry_air_density(np.array([1e5, 0.0]), 280.0)
    with pytest.raises(SceneError, match="temperature"):
        dry_air_density(1e5, np.array([280.0, np.nan]))


def test_water_content_clips_negative_mixing_ratios():
    np.testing.assert_allclose(water_content(np.array([-1e-5, 2e-3]), 1.1), [0.0, 2.2e-3])


def test_droplets_agree_with_the_cloud_species_cross_section():
    """beta = 3W / (2 rho_w r_e) is N sigma for N monodisperse droplets of r = 10 um and the cloud species' Riley
    Table 2 cross section 2 pi r^2 = 6.28e-10 m^2."""
    from warpsky.optics.species import SPECIES

    content = 0.5e-3  # kg/m^3
    r = HYDROMETEORS["cloud"].effective_radius
    number = content / (4.0 / 3.0 * math.pi * r**3 * 1000.0)
    sigma = SPECIES["cloud"].extinction_cross_section[0]
    np.testing.assert_allclose(float(extinction(HYDROMETEORS["cloud"], content)), number * sigma, rtol=1e-3)
    np.testing.assert_allclose(float(extinction(HYDROMETEORS["cloud"], content)), 3 * content / (2 * 1000 * r))


@pytest.mark.parametrize("name", ["rain", "snow", "graupel"])
def test_exponential_distributions_against_their_integrals(name):
    """The closed form pi N0 / Lambda^3, with Lambda from W, equals a quadrature of Q_ext = 2 times the projected
    area over N0 exp(-Lambda D); the same quadrature of the particles' mass gives back W."""
    kind = HYDROMETEORS[name]
    for content in (1e-5, 1e-4, 1e-3, 5e-3):
        slope = (math.pi * kind.particle_density * kind.intercept / content) ** 0.25
        d = np.linspace(0.0, 40.0 / slope, 400_001)
        n = kind.intercept * np.exp(-slope * d)
        mass = np.trapezoid(kind.particle_density * math.pi / 6.0 * d**3 * n, d)
        beta = np.trapezoid(2.0 * math.pi / 4.0 * d**2 * n, d)
        np.testing.assert_allclose(mass, content, rtol=1e-6)
        np.testing.assert_allclose(float(extinction(kind, content)), beta, rtol=1e-6)


def test_marshall_palmer_rain_magnitude_and_power_law():
    rain = HYDROMETEORS["rain"]
    # 1 g/m^3 of Marshall-Palmer rain (about 20 mm/h): Lambda = 2239 1/m, beta = 2.24e-3 1/m (visibility ~1.7 km)
    np.testing.assert_allclose(float(extinction(rain, 1e-3)), 2.24e-3, rtol=5e-3)
    # beta grows as W^(3/4)
    ratio = float(extinction(rain, 16e-3)) / float(extinction(rain, 1e-3))
    np.testing.assert_allclose(ratio, 16**0.75, rtol=1e-12)
    assert float(extinction(rain, 0.0)) == 0.0


def test_effective_radius_from_the_file_wins_where_positive():
    content = np.full(3, 1e-3)
    radius = np.array([5e-6, 0.0, np.nan])
    beta = extinction(HYDROMETEORS["cloud"], content, radius)
    np.testing.assert_allclose(beta, [3e-3 / (2e3 * 5e-6), 3e-3 / (2e3 * 10e-6), 3e-3 / (2e3 * 10e-6)])


def test_graupel_adds_to_snow_and_empty_species_are_left_out():
    w = {"snow": np.array([1e-3]), "graupel": np.array([2e-3]), "cloud": np.array([1e-4])}
    beta = species_extinction(w)
    assert set(beta) == {"snow", "cloud"}
    expected = extinction(HYDROMETEORS["snow"], 1e-3) + extinction(HYDROMETEORS["graupel"], 2e-3)
    np.testing.assert_allclose(beta["snow"], expected)
    with pytest.raises(SceneError, match="unknown hydrometeor 'hail'"):
        species_extinction({"hail": np.zeros(1)})


def test_hydrometeor_needs_exactly_one_size_model():
    with pytest.raises(SceneError, match="exactly one"):
        Hydrometeor("x", "cloud", 1000.0)
    with pytest.raises(SceneError, match="exactly one"):
        Hydrometeor("x", "cloud", 1000.0, effective_radius=1e-5, intercept=1e6)
    with pytest.raises(SceneError, match="density"):
        Hydrometeor("x", "cloud", 0.0, effective_radius=1e-5)
    assert "r_e=10 um" in repr(HYDROMETEORS["cloud"])


@pytest.mark.parametrize("name", ["rain", "snow", "graupel"])
def test_two_moment_exponential_against_its_integrals(name):
    """With a number concentration N the slope is Lambda = (pi rho N / W)^(1/3); the distribution
    N Lambda exp(-Lambda D) then holds N particles and W of water, and its extinction is the closed form."""
    kind = HYDROMETEORS[name]
    for content, number in ((1e-4, 1e3), (1e-3, 5e4), (3e-3, 2e5)):
        slope = (math.pi * kind.particle_density * number / content) ** (1.0 / 3.0)
        d = np.linspace(0.0, 40.0 / slope, 400_001)
        n = number * slope * np.exp(-slope * d)
        np.testing.assert_allclose(np.trapezoid(n, d), number, rtol=1e-6)
        np.testing.assert_allclose(np.trapezoid(kind.particle_density * math.pi / 6.0 * d**3 * n, d), content,
                                   rtol=1e-6)
        beta = np.trapezoid(2.0 * math.pi / 4.0 * d**2 * n, d)
        np.testing.assert_allclose(float(extinction(kind, content, number=number)), beta, rtol=1e-6)


def test_two_moment_droplets_take_the_mean_mass_and_missing_numbers_fall_back():
    kind = HYDROMETEORS["cloud"]
    content, number = 1e-3, 1e8  # 1 g/m^3 in 100 droplets per cm^3: r = 13.4 um
    r = (3 * content / (4 * math.pi * 1000.0 * number)) ** (1 / 3)
    np.testing.assert_allclose(float(extinction(kind, content, number=number)), 2 * math.pi * r**2 * number)
    beta = extinction(kind, np.full(2, content), number=np.array([0.0, np.nan]))
    np.testing.assert_allclose(beta, extinction(kind, np.full(2, content)))
