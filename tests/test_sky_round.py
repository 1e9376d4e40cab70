"""A round earth's air (warpsky.media.air.round_earth_kernels*, the sky pass on it): the panel quadrature and the
optical depth table against brute-force float64 quadrature, the sun's transmittance with each point's horizon, a planet
of huge radius against Riley's flat earth, twilight, the front transmittance shared with hybrid, the USD attribute."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import warp as wp
from conftest import add_atmosphere

from evaluation import sky_error as se
from warpsky.core.errors import SceneError
from warpsky.media.air import round_earth as air_round_host
from warpsky.media.air import round_earth_kernels as ar
from warpsky.media.air.analytic import analytic_air
from warpsky.model.scene import EARTH_AEROSOLS, EARTH_OZONE, EARTH_RADIUS, Atmosphere
from warpsky.usd.stage import StageReader

EARTH = Atmosphere(planet_radius=EARTH_RADIUS, **EARTH_AEROSOLS, **EARTH_OZONE)
SMOOTH = Atmosphere(planet_radius=EARTH_RADIUS, **EARTH_AEROSOLS)  # no ozone: no kinks in the profile


@wp.kernel
def _depths(air: ar.AnalyticAir, ra: ar.RoundAir, rays: wp.array(dtype=wp.vec3), quadrature: wp.array(dtype=wp.vec3),
            table: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    quadrature[i] = ar.ray_depth(air, ra, rays[i][0], rays[i][1], rays[i][2])
    table[i] = ar.table_depth(ra, rays[i][0], rays[i][1])


def _rays(atm):
    """(altitude, mu, distance to the floor or the top, reaches the top) over altitudes and directions, grazing
    ones included."""
    out = []
    radius, top = atm.planet_radius, ar.air_top(atm)
    for h in (1.0, 500.0, 3000.0, 12000.0, 40000.0):
        for mu in (1.0, 0.5, 0.1, 0.02, 0.0, -0.01, -0.05):
            r0 = radius + h
            c = h * (2.0 * radius + h)
            disc = r0 * r0 * mu * mu - c
            if mu < 0.0 and disc >= 0.0:
                out.append((h, mu, c / (-r0 * mu + math.sqrt(disc)), False))
            else:
                cc = (top - h) * (2.0 * radius + top + h)
                out.append((h, mu, -r0 * mu + math.sqrt(r0 * r0 * mu * mu + cc), True))
    return out


@pytest.mark.parametrize("atm,quadrature_tol", [(SMOOTH, 5e-4), (EARTH, 3e-3)])
def test_ray_depths_match_brute_force(device, atm, quadrature_tol):
    """The panel quadrature within 5e-4 of a 400,000-point float64 trapezoid rule (measured 3.0e-4 for rays
    descending from 40 km through a perigee 8 km lower, below 7e-7 elsewhere; 3e-3 with ozone, whose tent profile
    has kinks inside the panels: measured 2.1e-3 at 12 km), the table within 4e-3 (measured 1.5e-3)."""
    rays = _rays(atm)
    ra = ar.round_struct(atm, 0.0, device)
    packed = wp.array(np.array([r[:3] for r in rays], np.float32), dtype=wp.vec3, device=device)
    quadrature = wp.zeros(len(rays), dtype=wp.vec3, device=device)
    table = wp.zeros(len(rays), dtype=wp.vec3, device=device)
    wp.launch(_depths, dim=len(rays), inputs=[analytic_air(atm, np.zeros(3)), ra, packed, quadrature, table],
              device=device)
    for (h, mu, d, to_top), q, t in zip(rays, quadrature.numpy(), table.numpy(), strict=True):
        want = ar.reference_depth(atm, h, mu, d, count=400_000)
        np.testing.assert_allclose(q, want, rtol=quadrature_tol, err_msg=f"h {h} mu {mu}")
        if to_top:
            np.testing.assert_allclose(t, want, rtol=4e-3, err_msg=f"table h {h} mu {mu}")


def test_sun_transmittance_takes_each_points_horizon():
    """Sunlight at altitude h: the table's depth towards the sun, times the part of the disk above the floor's
    horizon seen from h, which lies acos(R / (R + h)) below the horizontal (3.2 deg at 10 km)."""
    radius = 0.5 * math.radians(0.53)
    for h in (0.0, 2000.0, 10000.0):
        dip = math.acos(EARTH_RADIUS / (EARTH_RADIUS + h))
        mu_s = math.sin(-dip + 2.0 * radius)  # all of the disk up, just
        t = air_round_host.sunlight_transmittance(EARTH, 0.0, h, mu_s, radius)
        r0 = EARTH_RADIUS + h
        top = ar.air_top(EARTH)
        cc = (top - h) * (2.0 * EARTH_RADIUS + top + h)
        d = -r0 * mu_s + math.sqrt(r0 * r0 * mu_s * mu_s + cc)
        np.testing.assert_allclose(t, np.exp(-ar.reference_depth(EARTH, h, mu_s, d)), rtol=0.02, atol=1e-12)
        half = air_round_host.sunlight_transmittance(EARTH, 0.0, h, math.sin(-dip), radius)
        assert np.all(half < t) and np.all(half > 0.0)  # half the disk, further through the air
        assert np.all(air_round_host.sunlight_transmittance(EARTH, 0.0, h, math.sin(-dip - 2.0 * radius),
                                                            radius) == 0.0)


def _sky(scene, pixels: int = 4) -> np.ndarray:
    from warpsky.passes.sky.sky import Sky

    return Sky(device="cpu").render(scene, pixels, pixels)[0].radiance.reshape(-1, 3).mean(axis=0)


@pytest.mark.slow
@pytest.mark.parametrize("air", ["rayleigh", "earth"])
def test_a_huge_round_earth_is_the_flat_one(air):
    """A planet of radius 1e9 m draws the flat earth's sky (Riley's closed form plus its multiple-scattering table)
    within 1.2 % (measured up to 1.0 %: the tables' different grids)."""
    for sun, view, albedo in ((30.0, (10.0, 90.0), 0.3), (60.0, (45.0, 180.0), 0.0), (5.0, (2.0, 90.0), 0.3),
                              (10.0, (90.0, 0.0), 0.0)):
        flat = se.case_scene(sun, se.direction(*view), albedo, air=air)
        huge = dataclasses.replace(flat, atmosphere=dataclasses.replace(flat.atmosphere, planet_radius=1e9))
        np.testing.assert_allclose(_sky(huge), _sky(flat), rtol=0.012)


@pytest.mark.slow
def test_twilight_is_finite_continuous_and_decays_to_black():
    """Sun from +2 to -12 deg on the Earth: the sky stays finite and non-negative, falls monotonically at the zenith
    and towards the sun, without jumps (each step within a factor of the neighbouring steps' ratio), and is black
    once the sun is below the whole air's horizon; the ozone keeps the twilight zenith blue."""
    suns = np.arange(2.0, -12.5, -0.5)
    zenith, towards = [], []
    for sun in suns:
        zenith.append(_sky(se.case_scene(sun, se.direction(90.0, 0.0), 0.3, air="earth", earth="round")))
        towards.append(_sky(se.case_scene(sun, se.direction(10.0, 0.0), 0.3, air="earth", earth="round")))
    for series in (np.array(zenith), np.array(towards)):
        assert np.all(np.isfinite(series)) and np.all(series >= 0.0)
        lum = series @ np.array([0.2126, 0.7152, 0.0722])
        assert np.all(np.diff(lum) <= 1e-12)
        lit = lum[lum > 0.0]
        ratios = lit[1:] / lit[:-1]
        assert np.all(ratios > 0.5 * np.median(ratios) ** 2)
        assert lum[-1] == 0.0
    at_six = zenith[int(np.argmin(np.abs(suns + 6.0)))]
    assert at_six[2] > at_six[0]


def test_hybrids_front_transmittance_is_the_sky_passs():
    """The front air's transmittance hybrid divides by is the sky pass's, bit for bit, with and without media
    (a depth map with a near and a far half)."""
    from warpsky.passes.sky.front import front_air_transmittance
    from warpsky.passes.sky.sky import Sky

    scene = se.case_scene(8.0, se.direction(3.0, 40.0), 0.3, air="earth", earth="round")
    depth = np.full((6, 6), 1e9, np.float32)
    depth[:3] = 4000.0
    want = Sky(device="cpu").render(scene, 6, 6, media_depth=depth)[0].transmittance
    np.testing.assert_array_equal(front_air_transmittance(scene, 6, 6, depth, "cpu"), want)


def test_planet_radius_attribute(tmp_path, homogeneous_npy):
    from conftest import StageSpec, write_stage

    path = write_stage(tmp_path / "a.usda", StageSpec(volume_file=homogeneous_npy))
    add_atmosphere(path, planetRadius=6.36e6)
    atm = StageReader(path).scene_at(None).atmosphere
    assert atm.round and atm.planet_radius == pytest.approx(6.36e6)
    bad = write_stage(tmp_path / "b.usda", StageSpec(volume_file=homogeneous_npy))
    add_atmosphere(bad, planetRadius=5000.0)
    with pytest.raises(SceneError, match="planetRadius must be 0 .* or a radius >= 1e\\+06 m"):
        StageReader(bad).scene_at(None)
