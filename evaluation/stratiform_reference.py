"""Photon tracing through a homogeneous plane-parallel slab with the *unmodified* Mie phase function, tallied by
modified-Mie order (the number of S events: scattering angles >= θ_f), exit side and exit direction — the Monte
Carlo reference of Bouthors 2006 Figs. 6, 8 and 9, used to measure the slab model
(:mod:`evaluation.stratiform_compare`); no render uses it.

Frame: Y up, the slab spans 0 <= y <= H, infinite in x and z; the sun lies in the +x half of the x-y plane at zenith
angle θ_l, so photons enter the top travelling along (-sin θ_l, -cos θ_l, 0). Exit azimuth φ is measured from +x
(the sun's side) and folded to [0, π] (the slab is symmetric about the principal plane).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.device import is_cpu
from warpsky.optics.kernels import DevicePhaseTables, sample_table
from warpsky.optics.phase_sampling import rotate_about

ORDER_BINS = wp.constant(4)  # 0, 1, 2, 3+


@wp.kernel
def slab_photon_kernel(
    cdf: wp.array(dtype=float),
    row: int,
    kappa: float,
    thickness: float,
    entry: wp.vec3,
    theta_f: float,
    seed: int,
    photons_per_thread: int,
    mu_bins: int,
    phi_bins: int,
    max_events: int,
    tally: wp.array(dtype=float),
    counters: wp.array(dtype=int),
):
    tid = wp.tid()
    for k in range(photons_per_thread):
        state = wp.rand_init(seed, tid * photons_per_thread + k)
        d = entry
        y = thickness
        s_events = int(0)
        events = int(0)
        done = bool(False)
        while not done:
            y = y + d[1] * (-wp.log(1.0 - wp.randf(state)) / kappa)
            if y >= thickness or y <= 0.0:
                side = int(0)
                if y <= 0.0:
                    side = 1
                mu = wp.abs(d[1])
                mb = wp.min(int(mu * float(mu_bins)), mu_bins - 1)
                phi = wp.abs(wp.atan2(d[2], d[0]))
                pb = wp.min(int(phi / wp.pi * float(phi_bins)), phi_bins - 1)
                order = wp.min(s_events, ORDER_BINS - 1)
                wp.atomic_add(tally, ((side * ORDER_BINS + order) * mu_bins + mb) * phi_bins + pb, 1.0)
                done = True
            elif events >= max_events:
                wp.atomic_add(counters, 1, 1)
                done = True
            else:
                sample = sample_table(cdf, row, wp.randf(state))
                if sample[0] >= theta_f:
                    s_events += 1
                d = rotate_about(d, wp.cos(sample[0]), 2.0 * wp.pi * wp.randf(state))
                events += 1
        wp.atomic_add(counters, 0, events)


@dataclass
class SlabTally:
    """Monte Carlo slab result for unit sun irradiance at normal incidence.

    Attributes:
        energy: (2, 4) exiting energy per unit incident flux by side (0 reflected, 1 transmitted) and order
            (0, 1, 2, 3+ S events).
        energy_error: (2, 4) standard errors of ``energy``.
        radiance: (2, 4, mu_bins, phi_bins) bin-averaged exit radiance [1/sr] (averaged with weight μ dΩ).
        radiance_error: Standard errors of ``radiance``.
        mu_edges: (mu_bins + 1,) bin edges in μ = |cos| of the exit direction to the vertical.
        phi_edges: (phi_bins + 1,) bin edges of the folded exit azimuth [rad] (0 = towards the sun's side).
        events: Scattering events traced; capped: photons dropped at the event cap.
    """

    energy: np.ndarray
    energy_error: np.ndarray
    radiance: np.ndarray
    radiance_error: np.ndarray
    mu_edges: np.ndarray
    phi_edges: np.ndarray
    photons: int
    events: int
    capped: int
    seconds: float


def slab_monte_carlo(
    phase: np.ndarray, kappa: float, thickness: float, theta_l_deg: float, photons: int, *, channel: int = 1,
    theta_f_deg: float = 5.0, mu_bins: int = 10, phi_bins: int = 12, seed: int = 0, device: str = "cpu",
    max_events: int = 100000,
) -> SlabTally:
    """Trace ``photons`` through a slab of extinction ``kappa`` [1/m] and ``thickness`` [m] with the phase table
    ``phase`` (3, M) (channel ``channel``), sun at zenith angle ``theta_l_deg``."""
    theta_l = math.radians(theta_l_deg)
    threads = 256 if is_cpu(device) else 16384
    per_thread = max(1, -(-int(photons) // threads))
    total = threads * per_thread
    started = time.perf_counter()
    with wp.ScopedDevice(device):
        tables = DevicePhaseTables.upload(np.asarray(phase)[None], device)
        tally = wp.zeros(2 * 4 * mu_bins * phi_bins, dtype=float)
        counters = wp.zeros(2, dtype=int)
        entry = wp.vec3(-math.sin(theta_l), -math.cos(theta_l), 0.0)
        wp.launch(slab_photon_kernel, dim=threads,
                  inputs=[tables.cdf, int(channel), float(kappa), float(thickness), entry,
                          math.radians(theta_f_deg), int(seed), per_thread, mu_bins, phi_bins, int(max_events),
                          tally, counters])
        counts = tally.numpy().astype(np.float64).reshape(2, 4, mu_bins, phi_bins)
        events, capped = (int(v) for v in counters.numpy())
    fraction = counts / total
    mu_l = math.cos(theta_l)
    energy = fraction.sum(axis=(2, 3))  # per unit incident flux: every photon carries 1/N of it
    energy_error = np.sqrt(energy * (1 - energy) / total)
    mu_edges = np.linspace(0.0, 1.0, mu_bins + 1)
    phi_edges = np.linspace(0.0, np.pi, phi_bins + 1)
    # radiance per unit sun irradiance: flux E μ_l / N per photon over ∫ μ dΩ of the bin (both azimuth signs)
    projected = 0.5 * (mu_edges[1:] ** 2 - mu_edges[:-1] ** 2)[:, None] * (2.0 * np.diff(phi_edges))[None, :]
    radiance = fraction * mu_l / projected
    radiance_error = np.sqrt(fraction * (1 - fraction) / total) * mu_l / projected
    return SlabTally(energy, energy_error, radiance, radiance_error, mu_edges, phi_edges, total, events, capped,
                     time.perf_counter() - started)
