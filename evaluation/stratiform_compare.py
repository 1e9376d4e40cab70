"""The stratiform slab model against the Monte Carlo slab (:mod:`evaluation.stratiform_reference`): per
order, energies and exit radiance in the same direction bins. Used by the tests and
``evaluation/benchmarks/bench_stratiform.py``."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from evaluation.stratiform_reference import SlabTally, slab_monte_carlo
from evaluation.stratiform_slab import slab_radiance_kernel
from warpsky.passes.stratiform.model1d import order_energies, reference_thickness
from warpsky.passes.stratiform.optics import StratiformOptics

ORDER_NAMES = ("0", "1", "2", "3+")


def model_energies(optics: StratiformOptics, thickness: float, theta_l_deg: float, channel: int = 1) -> np.ndarray:
    """(2, 4) Appendix A energies: row 0 reflected (order 0 is 0), row 1 transmitted."""
    h_ref = float(reference_thickness(thickness, optics.kappa))
    e = order_energies(h_ref, theta_l_deg, float(optics.kappa_s[channel] / optics.to_reference))
    return np.array([[0.0, e.r1, e.r2, e.r3p], [e.t0, e.t1, e.t2, e.t3p]], dtype=np.float64)


def model_radiance(optics: StratiformOptics, thickness: float, theta_l_deg: float, mu_edges, phi_edges, *,
                   samples: int = 6, channel: int = 1, device: str = "cpu") -> np.ndarray:
    """(2, 4, mu_bins, phi_bins) slab-kernel radiance averaged over each bin with weight μ dΩ (as the tally)."""
    mu_edges, phi_edges = np.asarray(mu_edges), np.asarray(phi_edges)
    nm, nphi = len(mu_edges) - 1, len(phi_edges) - 1
    frac = (np.arange(samples) + 0.5) / samples
    # uniform in μ² (the μ dμ weight) and in φ within each bin
    mu2 = mu_edges[:-1, None] ** 2 + (mu_edges[1:, None] ** 2 - mu_edges[:-1, None] ** 2) * frac[None, :]
    mu = np.sqrt(mu2)  # (nm, s)
    phi = phi_edges[:-1, None] + np.diff(phi_edges)[:, None] * frac[None, :]  # (nphi, s)
    mu_g = np.broadcast_to(mu[:, None, :, None], (nm, nphi, samples, samples))
    phi_g = np.broadcast_to(phi[None, :, None, :], (nm, nphi, samples, samples))
    sin = np.sqrt(np.maximum(1.0 - mu_g**2, 0.0))
    theta_l = math.radians(theta_l_deg)
    sun = np.array([math.sin(theta_l), math.cos(theta_l), 0.0])
    out = np.zeros((2, 4, nm, nphi))
    with wp.ScopedDevice(device):
        slab_optics, tables, params = optics.device_inputs(device)
        for side in (0, 1):
            # photon exit direction of travel; the camera ray looks back along it
            travel = np.stack([sin * np.cos(phi_g), mu_g * (1.0 if side == 0 else -1.0), sin * np.sin(phi_g)], -1)
            view = -travel.reshape(-1, 3)
            n = len(view)
            res = wp.zeros((n, 4), dtype=wp.vec3)
            wp.launch(slab_radiance_kernel, dim=n, inputs=[
                tables.values, params, slab_optics, wp.array(np.full(n, thickness, np.float32), dtype=float),
                wp.array(np.tile([0.0, 1.0, 0.0], (n, 1)).astype(np.float32), dtype=wp.vec3),
                wp.array(np.tile(sun, (n, 1)).astype(np.float32), dtype=wp.vec3),
                wp.array(view.astype(np.float32), dtype=wp.vec3), res])
            values = res.numpy()[..., channel].reshape(nm, nphi, samples, samples, 4)
            out[side] = np.moveaxis(values.mean(axis=(2, 3)), -1, 0)
    return out


@dataclass
class CaseComparison:
    """One slab case: model and Monte Carlo, energies (2, 4) and radiance (2, 4, mu, phi)."""

    thickness: float
    theta_l_deg: float
    tally: SlabTally
    model_energy: np.ndarray
    model_radiance: np.ndarray

    def shading_energy(self, side: int, order: int) -> float:
        """Energy per unit incident flux of the slab kernel's radiance of one order, integrated over the bins."""
        mu, phi = self.tally.mu_edges, self.tally.phi_edges
        projected = 0.5 * (mu[1:] ** 2 - mu[:-1] ** 2)[:, None] * (2.0 * np.diff(phi))[None, :]
        return float((self.model_radiance[side, order] * projected).sum() / math.cos(math.radians(self.theta_l_deg)))

    def radiance_error(self, side: int, order: int | None = None) -> float:
        """Relative error of the radiance of one order (None: all orders summed, order 0 excluded in transmission
        as it is the forward aureole resolved by no bin) over the bins: sum |model - MC| / sum MC, excluding the
        grazing bin μ < 0.1."""
        orders = [order] if order is not None else ([1, 2, 3] if side == 1 else [0, 1, 2, 3])
        if self.tally.energy[side, orders].sum() < 1e-3:
            return float("nan")  # (almost) no light in this order: a relative error means nothing
        mc = self.tally.radiance[side, orders].sum(axis=0)[1:]
        model = self.model_radiance[side, orders].sum(axis=0)[1:]
        return float(np.abs(model - mc).sum() / max(mc.sum(), 1e-30))


def compare_case(optics: StratiformOptics, thickness: float, theta_l_deg: float, photons: int, *, seed: int = 0,
                 device: str = "cpu", mu_bins: int = 10, phi_bins: int = 12) -> CaseComparison:
    tally = slab_monte_carlo(optics.phase, optics.kappa, thickness, theta_l_deg, photons, seed=seed, device=device,
                             mu_bins=mu_bins, phi_bins=phi_bins)
    return CaseComparison(thickness, theta_l_deg, tally, model_energies(optics, thickness, theta_l_deg),
                          model_radiance(optics, thickness, theta_l_deg, tally.mu_edges, tally.phi_edges,
                                         device=device))


def format_table(cases: list[CaseComparison]) -> str:
    """Per case and order: energy MC ± error vs model, and radiance error over the direction bins."""
    lines = [f"{'H [m]':>6} {'θ_l':>4} {'side':<5} {'order':<5} {'MC energy':>16} {'1D model':>8} {'Δ':>8} "
             f"{'shading':>8} {'radiance err':>12}"]
    for case in cases:
        for side, side_name in ((0, "R"), (1, "T")):
            for order in range(4):
                if side == 0 and order == 0:
                    continue
                mc, err = case.tally.energy[side, order], case.tally.energy_error[side, order]
                model = case.model_energy[side, order]
                rad = case.radiance_error(side, order) if (side, order) != (1, 0) else float("nan")
                shade = case.shading_energy(side, order) if (side, order) != (1, 0) else model
                lines.append(f"{case.thickness:6g} {case.theta_l_deg:4g} {side_name:<5} {ORDER_NAMES[order]:<5} "
                             f"{mc:9.4f}±{err:.4f} {model:8.4f} {model - mc:+8.4f} {shade:8.4f} {rad:12.3f}")
            mc_total = case.tally.energy[side].sum()
            model_total = case.model_energy[side].sum()
            lines.append(f"{case.thickness:6g} {case.theta_l_deg:4g} {side_name:<5} {'total':<5} {mc_total:16.4f} "
                         f"{model_total:8.4f} {model_total - mc_total:+8.4f} {'':8} {case.radiance_error(side):12.3f}")
    return "\n".join(lines)
