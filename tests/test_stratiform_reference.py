"""The stratiform slab's photon tracer (Bouthors' Monte Carlo reference) against the independent adding-doubling
solver that also validates the path tracer: the same slab, the same phase function, two unrelated methods."""

from __future__ import annotations

import numpy as np
import pytest
from adding_doubling import slab_radiance

from evaluation.stratiform_reference import slab_monte_carlo
from warpsky.model.scene import PhaseKind
from warpsky.optics.grid import angle_grid, normalise
from warpsky.optics.phase import phase_numpy


@pytest.mark.parametrize("g,tau", [(0.0, 1.0), (0.8, 4.0)])
def test_photon_tracer_matches_adding_doubling(device, g, tau):
    table = normalise(np.repeat(phase_numpy(PhaseKind.HG, g, np.cos(angle_grid()))[None], 3, axis=0))
    thickness = 100.0
    tally = slab_monte_carlo(table, tau / thickness, thickness, 0.0, 400_000, device=device, seed=3)
    # adding-doubling at the bin centres; at normal incidence the field has no azimuth dependence
    centres = 0.5 * (tally.mu_edges[1:] + tally.mu_edges[:-1])
    x, w = np.polynomial.legendre.leggauss(48)
    mu_nodes = 0.5 * (x + 1.0)
    phase = lambda c: phase_numpy(PhaseKind.HG, g, c)  # noqa: E731
    reflected, transmitted = slab_radiance(phase, tau, 1.0, np.concatenate([centres, mu_nodes]))
    r_total = 2.0 * np.pi * np.sum(0.5 * w * mu_nodes * reflected[len(centres):])
    t_diffuse = 2.0 * np.pi * np.sum(0.5 * w * mu_nodes * transmitted[len(centres):])
    mc_r = tally.energy[0].sum()
    mc_t = tally.energy[1].sum()
    direct = np.exp(-tau)
    print(f"g={g} tau={tau}: R {mc_r:.4f} vs {r_total:.4f}; T {mc_t:.4f} vs {t_diffuse + direct:.4f}")
    assert mc_r == pytest.approx(r_total, abs=4 * tally.energy_error[0].sum() + 2e-3)
    assert mc_t == pytest.approx(t_diffuse + direct, abs=4 * tally.energy_error[1].sum() + 2e-3)
    # radiance per mu bin (averaged over azimuth), where the bins are well populated
    mc_reflected = tally.radiance[0].sum(axis=0).mean(axis=1)
    inner = slice(2, len(centres) - 1)  # bin averages vs centre values: skip the steep grazing bins
    np.testing.assert_allclose(mc_reflected[inner], reflected[: len(centres)][inner], rtol=0.06)
