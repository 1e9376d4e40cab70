"""The solver's cold processes against their formulas computed here (numpy): snow's slow fall (Lin et al. 1983's
mass-weighted speed of Locatelli & Hobbs 1974's aggregates), its blend with rain's over the frames' ice partition
kept conservative, and the slower conversion of cloud ice to precipitation where it is cold."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.simulate import kernels_water as kw
from warpsky.simulate.frames import ALL_ICE, ALL_LIQUID, ice_fraction
from warpsky.simulate.solver import CloudSolver, SimulationSettings
from warpsky.simulate.sounding import saturation_mixing_ratio, weisman_klemp


def column_solver() -> CloudSolver:
    """A Weisman-Klemp environment on 8 x 8 columns of 64 levels of 250 m (the default levels), at rest."""
    settings = SimulationSettings(nx=8, ny=64, nz=8, dx=1000.0, dy=250.0, bubble_theta=0.0, noise=0.0)
    return CloudSolver(weisman_klemp(), settings, "cpu")


@wp.kernel
def speeds(column: kw.Column, rain: wp.array(dtype=float), temperature: wp.array(dtype=float),
           level: wp.array(dtype=int), out: wp.array(dtype=float)):
    n = wp.tid()
    out[n] = kw.fall_speed(column, rain[n], temperature[n], level[n])


def fall_speed(solver, rain, temperature, level):
    out = wp.zeros(len(rain), dtype=float, device="cpu")
    wp.launch(speeds, dim=len(rain), inputs=[solver.column, wp.array(rain, dtype=float), wp.array(temperature,
              dtype=float), wp.array(level, dtype=int), out], device="cpu")
    return out.numpy()


def test_the_solver_partitions_ice_as_the_frames_do():
    assert (kw.ALL_LIQUID, kw.ALL_ICE) == (ALL_LIQUID, ALL_ICE)


def test_snow_falls_at_about_a_metre_a_second_and_rain_at_kw78s_speed():
    """At 1 g/kg, snow (below -20 C) falls at Lin et al.'s c Γ(4 + d)/6 (ρ q / (π ρ_s n0s))^(d/4) (ρ0/ρ)^½, about
    1.2-2 m/s aloft, rain (above 0 C) at KW78's 36.34 (0.001 ρ q)^0.1364 (ρ0/ρ)^½, and between them the speed is
    the partition's blend."""
    solver = column_solver()
    base = solver.base
    levels = np.array([4, 40, 40, 40])
    temperature = np.array([290.0, 240.0, 263.15, 273.15], np.float32)
    rain = np.full(4, 1.0e-3, np.float32)
    got = fall_speed(solver, rain, temperature, levels)
    density = base.density[levels]
    thinning = np.sqrt(base.density_face[0] / density)
    liquid = 36.34 * (0.001 * density * rain) ** 0.1364 * thinning
    snow = 11.72 * math.gamma(4.41) / 6.0 * (density * rain / (math.pi * 100.0 * 3.0e6)) ** 0.1025 * thinning
    share = ice_fraction(temperature)
    np.testing.assert_allclose(got, (1.0 - share) * liquid + share * snow, rtol=1.0e-4)
    assert 1.2 < got[1] < 2.0 and got[0] > 4.0, got


def test_snow_falls_conservatively_through_the_partition():
    """Precipitation between 3 and 9 km (through the freezing level near 4.5 km) keeps its water to rounding in
    the air plus what fell out; what starts at -40 C has come down about its speed times the time."""
    solver = column_solver()
    water, dy = solver.waters[0], solver.settings.dy
    rain = np.zeros((8, 64, 8), np.float32)
    rain[:, 12:36, :] = 1.0e-3
    water.rain.assign(rain)
    density = solver.base.density[None, :, None]
    before = np.sum(rain * density) * dy
    top_before = 36
    for _ in range(30):  # 300 s
        wp.launch(kw.sediment, dim=(8, 8), inputs=[solver.grid, solver.column, water, solver.fallen, 10.0, 2, 0],
                  device="cpu")
    after = water.rain.numpy()
    kept = np.sum(after * density) * dy + np.sum(solver.fallen.numpy())
    assert abs(kept / before - 1.0) < 1.0e-5
    profile = after[0, :, 0]
    top_after = np.nonzero(profile > 0.5e-3)[0].max() + 1
    drop = (top_before - top_after) * dy
    assert 250.0 <= drop <= 750.0, drop  # about 1.5 m/s for 300 s


def test_cloud_ice_turns_to_precipitation_slower_where_cold():
    """2 g/kg of cloud without precipitation converts at Kessler's 0.001 (q_c - 0.001) 1/s where it is warm and at
    Lin et al.'s 0.001 exp(0.025 (T - 273.15)) (q_c - 0.001) where it is all ice."""
    solver = column_solver()
    water = solver.waters[0]
    temperature = solver.base.temperature
    cloud = np.zeros((8, 64, 8), np.float32)
    warm, cold = 4, 44
    cloud[:, [warm, cold], :] = 2.0e-3
    water.cloud.assign(cloud)
    water.rain.zero_()
    vapour = water.vapour.numpy()  # saturated there, so that nothing evaporates
    for level in (warm, cold):
        vapour[:, level, :] = 1.001 * saturation_mixing_ratio(temperature[level], solver.base.pressure[level])
    water.vapour.assign(vapour)
    wp.launch(kw.microphysics, dim=(8, 64, 8), inputs=[solver.column, water, 10.0, 0], device="cpu")
    rain = water.rain.numpy()[0, :, 0]
    assert temperature[cold] < ALL_ICE
    np.testing.assert_allclose(rain[warm], 10.0 * 0.001 * 1.0e-3, rtol=1.0e-3)
    np.testing.assert_allclose(rain[cold], 10.0 * 0.001 * np.exp(0.025 * (temperature[cold] - 273.15)) * 1.0e-3,
                               rtol=1.0e-3)
