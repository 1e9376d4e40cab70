"""Host side of a stratiform layer's optics: extinction from the droplet distribution, Bouthors' modified Mie
tables (§4.1, from :func:`warpsky.optics.tables.modified_mie_table` of the ``stratus`` species), Appendix B.

The phase function is the ``stratus`` species' (modified Gamma, γ = 2, r_e = 7 µm); the layer's number density and
effective radius set its extinction κ = N0 π r_e² and hence the optical depth of a given thickness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.optics.grid import angle_grid, cumulative, sphere_integral
from warpsky.optics.kernels import DevicePhaseTables
from warpsky.optics.tables import modified_mie_table, phase_table
from warpsky.passes.stratiform.model1d import APPENDIX_B, KAPPA_REFERENCE
from warpsky.passes.stratiform.slab import SlabOptics

#: Bouthors' forward cut θ_f [deg] (§4.1).
FORWARD_CUT_DEG = 5.0


@dataclass(frozen=True)
class StratiformOptics:
    """Optics of a layer's droplets, per RGB channel where they differ.

    Attributes:
        kappa: Extinction coefficient κ [1/m].
        forward_weight: P_f, the share of scattering below θ_f (3,).
        p_s: P_S on the shared angle grid (3, M) [1/sr].
        p_f: P_F (3, M) [1/sr].
        p2: P² = P_S * P_S (3, M) [1/sr].
        phase: The unmodified phase function P (3, M) [1/sr].
        forward_msq: ⟨θ²⟩ of P_F [rad²] (3,).
    """

    kappa: float
    forward_weight: np.ndarray
    p_s: np.ndarray
    p_f: np.ndarray
    p2: np.ndarray
    phase: np.ndarray
    forward_msq: np.ndarray

    @property
    def kappa_s(self) -> np.ndarray:
        """Modified-Mie extinction κ_S = (1 - P_f) κ [1/m] (3,)."""
        return (1.0 - self.forward_weight) * self.kappa

    @property
    def to_reference(self) -> float:
        """κ / κ_ref: metres of this layer to Appendix B's reference metres."""
        return self.kappa / KAPPA_REFERENCE

    def device_inputs(self, device, *, cache_name: str | None = None):
        """(SlabOptics struct, DevicePhaseTables of [P_S, P²], Appendix B as a flat float array) on ``device``.
        With ``cache_name`` the tables and parameters go through :func:`warpsky.core.device_buffers.upload` (copied
        once while they stay the same)."""
        optics = SlabOptics()
        optics.kappa = float(self.kappa)
        optics.kappa_s = wp.vec3(*self.kappa_s.tolist())
        optics.to_reference = float(self.to_reference)
        optics.forward_msq = wp.vec3(*self.forward_msq.tolist())
        phase = np.stack([self.p_s, self.p2])
        params = APPENDIX_B.reshape(-1).astype(np.float32)
        if cache_name is None:
            return optics, DevicePhaseTables.upload(phase, device), wp.array(params, dtype=float, device=device)
        phase = np.asarray(phase, dtype=np.float64)
        tables = DevicePhaseTables(
            device_buffers.upload(f"{cache_name}:phase", phase.reshape(-1).astype(np.float32), float, device),
            device_buffers.upload(f"{cache_name}:phase_cdf", cumulative(phase).reshape(-1).astype(np.float32), float,
                                  device),
            phase.shape[0])
        return optics, tables, device_buffers.upload(f"{cache_name}:params", params, float, device)


def stratiform_optics(number_density: float = 3.0e8, effective_radius: float = 7.0e-6) -> StratiformOptics:
    """Optics of droplets with ``number_density`` [1/m³] and ``effective_radius`` [m] (tables cached on disk)."""
    split = modified_mie_table("stratus", FORWARD_CUT_DEG)
    theta = angle_grid()
    msq = sphere_integral(split["p_f"] * theta[None, :] ** 2)
    kappa = float(number_density) * np.pi * float(effective_radius) ** 2
    return StratiformOptics(kappa, np.asarray(split["forward_weight"]), split["p_s"], split["p_f"], split["p2"],
                            phase_table("stratus"), np.asarray(msq))
