"""The cloud solver's dynamics: the projection leaves the divergence its tolerance allows, a dry warm bubble rises at
the speed thermal theory gives and keeps its buoyancy, and runs repeat bit for bit for a seed."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpsky.simulate.solver import CloudSolver, SimulationSettings
from warpsky.simulate.sounding import Sounding, weisman_klemp


def neutral_dry() -> Sounding:
    """θ = 300 K everywhere, no vapour, no wind: a neutral atmosphere."""
    z = np.array([100.0, 20000.0])
    return Sounding(1.0e5, 300.0, 0.0, z, np.full(2, 300.0), np.zeros(2), np.zeros(2), np.zeros(2))


def test_projection_leaves_the_divergence_within_its_tolerance(device):
    """A random, strongly divergent flow projected: |∇·(ρ0 u)| falls by the solver's tolerance (its relative
    residual, as the MAC grid makes the divergence the residual), and a second projection changes the velocity by
    under 1e-3 of its largest value."""
    settings = SimulationSettings(nx=16, ny=12, nz=20, dx=700.0, dy=300.0, tolerance=1.0e-5)
    solver = CloudSolver(weisman_klemp(), settings, device)
    rng = np.random.default_rng(3)
    flow = solver.flows[0]
    for array in (flow.vel_x, flow.vel_z):
        array.assign(rng.normal(0.0, 5.0, array.shape).astype(np.float32))
    vy = rng.normal(0.0, 5.0, flow.vel_y.shape).astype(np.float32)
    vy[:, [0, -1]] = 0.0
    flow.vel_y.assign(vy)
    before = np.linalg.norm(solver.divergence())
    solver.projection.project(flow)
    after = np.linalg.norm(solver.divergence())
    assert solver.projection.relative_residual <= 1.0e-5
    assert after / before <= 1.0e-5 * 1.05 + 1.0e-6
    kept = flow.vel_x.numpy().copy()
    solver.projection.project(flow)
    np.testing.assert_allclose(flow.vel_x.numpy(), kept, atol=1.0e-3 * np.abs(kept).max())


def test_a_dry_bubble_rises_at_the_thermal_speed_and_keeps_its_buoyancy(device):
    """+2 K bubble (400 m radius) in a neutral, dry atmosphere: after 3 minutes its centroid (weighted by ρ0 θ')
    rises at 0.4-1.0 sqrt(g' R) (thermals rise at about 0.6-0.7 of it: Scorer 1957's thermals ~1.2 sqrt(g' r) with
    g' the mean, about half the peak here), and the buoyancy integral ∫ρ0 θ' dV is kept to 1e-3 (the transport is
    conservative; no heating)."""
    settings = SimulationSettings(nx=24, ny=32, nz=24, dx=100.0, dy=100.0, time_step=5.0, bubble_theta=2.0,
                                  bubble_radius=400.0, bubble_depth=700.0, noise=0.0, confinement=0.0,
                                  sponge_depth=0.0)
    solver = CloudSolver(neutral_dry(), settings, device)
    height = solver.centres()[1]
    density = solver.base.density[None, :, None]

    def centroid_and_integral():
        excess = solver.fields()["theta"].astype(np.float64) - 300.0
        weight = np.clip(excess, 0.0, None) * density
        return float(np.sum(weight.sum(axis=(0, 2)) * height) / weight.sum()), float(np.sum(excess * density))

    _, integral = centroid_and_integral()
    solver.run(180.0)
    z_180, _ = centroid_and_integral()
    solver.run(60.0)
    z_240, integral_240 = centroid_and_integral()
    speed = (z_240 - z_180) / 60.0
    scale = np.sqrt(9.81 * 2.0 / 300.0 * 400.0)
    assert 0.4 * scale < speed < 1.0 * scale, (speed, scale)
    assert abs(integral_240 / integral - 1.0) < 1.0e-3


def test_a_run_repeats_bit_for_bit_for_its_seed(monkeypatch):
    """Two runs with seed 5 agree in every value, the second launched on one CPU thread instead of two slabs;
    seed 6 differs (its θ noise)."""
    def run(seed):
        settings = SimulationSettings(nx=12, ny=16, nz=12, dx=1000.0, dy=500.0, time_step=10.0,
                                      bubble_radius=4000.0, seed=seed)
        solver = CloudSolver(weisman_klemp(), settings, "cpu")
        solver.run(60.0)
        return solver.fields()

    monkeypatch.setenv("WARPSKY_CPU_THREADS", "2")
    a, c = run(5), run(6)
    monkeypatch.setenv("WARPSKY_CPU_THREADS", "1")
    b = run(5)
    for name in ("theta", "vapour", "cloud", "rain", "velocity"):
        assert np.array_equal(a[name], b[name]), name
    assert not np.array_equal(a["theta"], c["theta"])


@pytest.mark.parametrize("bad, message", [({"nx": 4}, "at least 8"), ({"dx": 1.0}, "dx must be"),
                                          ({"time_step": 0.0}, "time step"), ({"tolerance": 2.0}, "tolerance"),
                                          ({"domain_speed": (1.0, float("nan"))}, "domain's speed")])
def test_settings_refuse_bad_values(bad, message):
    from warpsky.core.errors import UsageError

    with pytest.raises(UsageError, match=message):
        SimulationSettings(**bad)


def test_kernels_compile_to_sm_90_ptx(tmp_path):
    """Every simulate kernel module compiles for CUDA (Warp's NVRTC, no GPU needed)."""
    from warpsky.cli.kernel_registry import compile_ptx, kernel_modules

    modules = kernel_modules()
    mine = [n for n, m in enumerate(modules) if m.name.startswith("warpsky.simulate.")]
    assert {modules[n].name for n in mine} >= {"warpsky.simulate.kernels_flow", "warpsky.simulate.kernels_water",
                                               "warpsky.simulate.kernels_transport", "warpsky.simulate.pressure"}
    for n in mine:
        paths = compile_ptx(n, str(tmp_path / str(n)))
        text = next(p for p in paths if p.endswith(".ptx"))
        assert ".target sm_90" in open(text).read()
    wp.synchronize()


def test_the_grid_moves_with_the_mean_wind_of_the_lowest_6_km():
    """Weisman & Klemp's u = 15 tanh(z / 3 km): its mean over 0-6 km is 15 (3/6) ln cosh 2 = 9.9375 m/s (the
    solver's 24 levels of 250 m, a midpoint rule, within 0.01), and the solver takes the environment's wind less
    it, so the sponge relaxes to the relative wind."""
    settings = SimulationSettings(nx=8, ny=32, nz=8, dx=1000.0, dy=250.0)
    solver = CloudSolver(weisman_klemp(), settings, "cpu")
    assert solver.domain_speed[0] == pytest.approx(7.5 * np.log(np.cosh(2.0)), abs=0.01)
    assert solver.domain_speed[1] == 0.0
    heights = (np.arange(32) + 0.5) * 250.0
    np.testing.assert_allclose(solver.base.wind_u, 15.0 * np.tanh(heights / 3000.0) - solver.domain_speed[0],
                               atol=0.05)
    still = CloudSolver(weisman_klemp(), SimulationSettings(nx=8, ny=32, nz=8, dx=1000.0, dy=250.0,
                                                            domain_speed=(0.0, 0.0)), "cpu")
    np.testing.assert_allclose(still.base.wind_u - solver.base.wind_u, solver.domain_speed[0], atol=1e-9)
