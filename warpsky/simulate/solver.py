"""The cloud solver: the state on the device and one time step of it (Harris et al. 2003's loop, anelastic and with
Kessler microphysics and a temperature-partitioned ice phase).

A step of ``dt`` seconds: carry θ, q_v, q_c and q_r by conservative fluxes (:mod:`.kernels_transport`) and the
velocity semi-Lagrangian (:mod:`.kernels_flow`); add
buoyancy and vorticity confinement and damp in the sponge; project (:mod:`.pressure`); then Kessler rain (with the cold
rates of cloud ice), saturation adjustment (with the heat of deposition where it is cold) and the precipitation's
fall, rain's or snow's by temperature (:mod:`.kernels_water`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core.errors import UsageError
from warpsky.simulate import kernels_flow as kf
from warpsky.simulate import kernels_transport as kt
from warpsky.simulate import kernels_water as kw
from warpsky.simulate.fields import Column, Flow, Grid, Water
from warpsky.simulate.launch import launch_slabs
from warpsky.simulate.pressure import Projection
from warpsky.simulate.sounding import BaseState, Sounding, base_state


@dataclass(frozen=True)
class SimulationSettings:
    """What a run simulates.

    ====================== ====== ========== =========== ================================================
    name                   unit   default    range       meaning
    ====================== ====== ========== =========== ================================================
    nx, nz                 -      128        >= 8        columns along x and z
    ny                     -      64         >= 8        levels
    dx                     m      500        >= 10       horizontal spacing
    dy                     m      250        >= 10       level spacing (64 levels reach 16 km)
    time_step              s      10         > 0         the longest step (frames get equal steps)
    bubble_theta           K      2          any         warm bubble's θ excess at its centre
    bubble_radius          m      10000      > 0         its horizontal radius (Weisman & Klemp 1982)
    bubble_depth           m      1400       > 0         its vertical radius; centred that high too
    noise                  K      0.1        >= 0        random θ perturbation under 1 km (breaks symmetry)
    confinement            1/s    0.001      >= 0        vorticity confinement ε
    sponge_depth           m      3000       >= 0        Rayleigh sponge under the lid
    sponge_rate            1/s    0.01       >= 0        its rate at the lid (sin² ramp)
    tolerance              -      1e-4       (0, 1)      the projection's residual over its right side
    seed                   -      1          any         the noise's seed
    domain_speed           m/s    auto       any         the grid's own motion (u, v) along +x and +z
    ====================== ====== ========== =========== ================================================

    The grid moves at ``domain_speed`` (CM1's domain translation): the solver sees the environment's wind less
    that speed, a Galilean change of frame, and the frames are written where the grid has moved to, with that
    speed added back to their wind. A storm moving with the grid stays inside its periodic domain instead of
    leaving through one side and coming back through the other. Automatic: :func:`mean_wind`, the mean wind of the
    lowest :data:`STEERING_DEPTH`, which storms roughly move with (the steering layer of e.g. Bunkers et al.
    2000's storm-motion estimate, without its deviation for supercells).
    """

    nx: int = 128
    ny: int = 64
    nz: int = 128
    dx: float = 500.0
    dy: float = 250.0
    time_step: float = 10.0
    bubble_theta: float = 2.0
    bubble_radius: float = 10000.0
    bubble_depth: float = 1400.0
    noise: float = 0.1
    confinement: float = 0.001
    sponge_depth: float = 3000.0
    sponge_rate: float = 0.01
    tolerance: float = 1.0e-4
    seed: int = 1
    domain_speed: tuple[float, float] | None = None

    def __post_init__(self):
        for name in ("nx", "ny", "nz"):
            if getattr(self, name) < 8:
                raise UsageError(f"the grid needs at least 8 cells along each axis, got {name}={getattr(self, name)}")
        for name in ("dx", "dy"):
            if not getattr(self, name) >= 10.0:
                raise UsageError(f"{name} must be at least 10 m, got {getattr(self, name)}")
        if not self.time_step > 0.0:
            raise UsageError(f"the time step must be positive, got {self.time_step} s")
        if not 0.0 < self.tolerance < 1.0:
            raise UsageError(f"the projection's tolerance must lie in (0, 1), got {self.tolerance}")
        if self.domain_speed is not None and not (
                len(self.domain_speed) == 2 and all(np.isfinite(v) for v in self.domain_speed)):
            raise UsageError(f"the domain's speed must be two finite numbers (u, v) [m/s], got {self.domain_speed}")

    @property
    def height(self) -> float:
        return self.ny * self.dy


#: Depth [m] of the layer whose mean wind the domain moves with by default.
STEERING_DEPTH = 6000.0


def mean_wind(base: BaseState, spacing: float, depth: float = STEERING_DEPTH) -> tuple[float, float]:
    """The mean environmental wind (u, v) [m/s] over the levels whose centres lie below ``depth`` [m] (levels of
    ``spacing`` [m]; all levels when the grid is shallower)."""
    below = (np.arange(len(base.wind_u)) + 0.5) * spacing < depth
    below = below if below.any() else np.ones_like(below)
    return float(np.mean(base.wind_u[below])), float(np.mean(base.wind_v[below]))


def _device_array(values, device, dtype=wp.float32):
    return wp.array(np.ascontiguousarray(values, dtype=np.float32), dtype=dtype, device=device)


class CloudSolver:
    """The storm's state on ``device`` and its time step.

    ``water_total()`` is the column-integrated water [kg] (vapour, cloud, rain and what fell through the floor);
    ``fields()`` copies the state to the host.
    """

    def __init__(self, sounding: Sounding, settings: SimulationSettings, device: str = "cpu"):
        self.settings, self.device = settings, device
        s = settings
        ground = base_state(sounding, s.ny, s.dy)
        self.domain_speed = s.domain_speed if s.domain_speed is not None else mean_wind(ground, s.dy)
        # the environment as the moving grid sees it: its wind less the grid's speed
        self.base: BaseState = dataclasses.replace(ground, wind_u=ground.wind_u - self.domain_speed[0],
                                                   wind_v=ground.wind_v - self.domain_speed[1])
        self.grid = Grid()
        self.grid.nx, self.grid.ny, self.grid.nz, self.grid.dx, self.grid.dy = s.nx, s.ny, s.nz, s.dx, s.dy
        self.column = self._column()
        shape = (s.nx, s.ny, s.nz)
        self.flows = [self._flow(shape), self._flow(shape)]
        self.waters = [self._water(shape), self._water(shape)]
        self.curl = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.force = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.fallen = wp.zeros((s.nx, s.nz), dtype=float, device=device)
        self.courant_partial = wp.zeros((s.nx, s.nz), dtype=float, device=device)
        self.courant = wp.zeros(1, dtype=float, device=device)
        self.transport_substeps = 1
        self.projection = Projection(self.grid, self.column, self.base, device, tolerance=s.tolerance)
        self.time = 0.0
        self.step_count = 0
        self._initialise()

    # -- set-up ---------------------------------------------------------------------------------------------------
    def _column(self) -> Column:
        s, b, d = self.settings, self.base, self.device
        column = Column()
        column.theta, column.vapour = _device_array(b.theta, d), _device_array(b.vapour, d)
        column.exner, column.pressure = _device_array(b.exner, d), _device_array(b.pressure, d)
        column.density, column.density_face = _device_array(b.density, d), _device_array(b.density_face, d)
        column.wind_x, column.wind_z = _device_array(b.wind_u, d), _device_array(b.wind_v, d)
        column.damping = _device_array(self.damping((np.arange(s.ny) + 0.5) * s.dy), d)
        column.damping_face = _device_array(self.damping(np.arange(s.ny + 1) * s.dy), d)
        return column

    def damping(self, height: np.ndarray) -> np.ndarray:
        """The sponge's Rayleigh rate [1/s] at ``height`` [m]: sin² from 0 at its bottom to the rate at the lid."""
        s = self.settings
        if s.sponge_depth <= 0.0:
            return np.zeros_like(height)
        ramp = np.clip((height - (s.height - s.sponge_depth)) / s.sponge_depth, 0.0, 1.0)
        return s.sponge_rate * np.sin(0.5 * np.pi * ramp) ** 2

    def _flow(self, shape) -> Flow:
        flow = Flow()
        flow.vel_x = wp.zeros(shape, dtype=float, device=self.device)
        flow.vel_y = wp.zeros((shape[0], shape[1] + 1, shape[2]), dtype=float, device=self.device)
        flow.vel_z = wp.zeros(shape, dtype=float, device=self.device)
        return flow

    def _water(self, shape) -> Water:
        water = Water()
        for name in ("theta", "vapour", "cloud", "rain"):
            setattr(water, name, wp.zeros(shape, dtype=float, device=self.device))
        return water

    def centres(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell-centre coordinates [m] along x, y, z (x and z centred on the domain's middle)."""
        s = self.settings
        return ((np.arange(s.nx) + 0.5 - 0.5 * s.nx) * s.dx, (np.arange(s.ny) + 0.5) * s.dy,
                (np.arange(s.nz) + 0.5 - 0.5 * s.nz) * s.dx)

    def _initialise(self) -> None:
        """The environment everywhere, the warm bubble (θ' cos² in its normalised radius, Weisman & Klemp 1982)
        at the domain's middle, a seeded θ noise under 1 km, and the flow projected."""
        s, b = self.settings, self.base
        x, y, z = self.centres()
        X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
        radius = np.sqrt((X / s.bubble_radius) ** 2 + (Z / s.bubble_radius) ** 2
                         + ((Y - s.bubble_depth) / s.bubble_depth) ** 2)
        theta = b.theta[None, :, None] + s.bubble_theta * np.where(radius < 1.0, np.cos(0.5 * np.pi * radius) ** 2, 0.0)
        rng = np.random.default_rng(s.seed)
        theta += s.noise * (rng.random(theta.shape) - 0.5) * 2.0 * (Y < 1000.0)
        water = self.waters[0]
        water.theta.assign(theta.astype(np.float32))
        water.vapour.assign(np.broadcast_to(b.vapour[None, :, None], X.shape).astype(np.float32))
        flow = self.flows[0]
        flow.vel_x.assign(np.broadcast_to(b.wind_u[None, :, None], X.shape).astype(np.float32))
        flow.vel_z.assign(np.broadcast_to(b.wind_v[None, :, None], X.shape).astype(np.float32))
        # condense what the bubble or the sounding holds above saturation before the first step
        launch_slabs(kw.microphysics, X.shape, [self.column, water, 0.0], self.device)

    # -- the step ------------------------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance the state by ``dt`` [s]."""
        g, d, shape = self.grid, self.device, (self.grid.nx, self.grid.ny, self.grid.nz)
        self._transport_scalars(dt)
        flow, new_flow = self.flows
        launch_slabs(kf.advect, (g.nx, g.ny + 1, g.nz), [g, flow, new_flow, float(dt)], d)
        self.flows.reverse()
        flow, water = self.flows[0], self.waters[0]
        if self.settings.confinement > 0.0:
            launch_slabs(kf.vorticity, shape, [g, flow, self.curl], d)
            launch_slabs(kf.confinement, shape, [g, self.curl, float(self.settings.confinement), self.force], d)
        launch_slabs(kf.apply_forces, (g.nx, g.ny + 1, g.nz), [g, self.column, water, self.force, flow, float(dt)], d)
        launch_slabs(kf.damp_theta, shape, [self.column, water, float(dt)], d)
        self.projection.project(flow)
        launch_slabs(kw.microphysics, shape, [self.column, water, float(dt)], d)
        substeps = max(1, int(np.ceil(dt * 15.0 / (0.9 * g.dy))))  # rain falls under 15 m/s below 20 km
        launch_slabs(kw.sediment, (g.nx, g.nz), [g, self.column, water, self.fallen, float(dt), substeps], d)
        self.time += dt
        self.step_count += 1

    def _transport_scalars(self, dt: float) -> None:
        """θ, q_v, q_c, q_r carried conservatively by the current flow over ``dt`` [s], in sub-steps whose summed
        Courant numbers stay under :data:`~.kernels_transport.MAX_COURANT`."""
        g, d = self.grid, self.device
        launch_slabs(kt.column_courant, (g.nx, g.nz), [g, self.flows[0], float(dt), self.courant_partial], d)
        wp.launch(kt.largest_value, dim=1, inputs=[self.courant_partial, self.courant], device=d)
        substeps = max(1, int(np.ceil(float(self.courant.numpy()[0]) / kt.MAX_COURANT)))
        self.transport_substeps = substeps
        for _ in range(substeps):
            water, new_water = self.waters
            launch_slabs(kt.transport, (g.nx, g.ny, g.nz),
                         [g, self.column, self.flows[0], water, new_water, float(dt / substeps)], d)
            self.waters.reverse()

    def run(self, seconds: float, *, callback=None) -> None:
        """Advance by ``seconds`` in equal steps no longer than the settings' time step."""
        steps = max(1, int(np.ceil(seconds / self.settings.time_step - 1.0e-9)))
        for _ in range(steps):
            self.step(seconds / steps)
            if callback is not None:
                callback(self)

    # -- reading the state ---------------------------------------------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        """The state on the host: theta, vapour, cloud, rain (cell centres) and velocity (cell centres, (..., 3))
        [SI], and fallen (the rain that left through the floor per column [kg/m^2])."""
        water, flow = self.waters[0], self.flows[0]
        # copies: on the CPU .numpy() is a view of the device memory, which the next step overwrites
        out = {name: getattr(water, name).numpy().copy() for name in ("theta", "vapour", "cloud", "rain")}
        vx, vy, vz = flow.vel_x.numpy(), flow.vel_y.numpy(), flow.vel_z.numpy()
        out["velocity"] = np.stack([0.5 * (vx + np.roll(vx, -1, axis=0)), 0.5 * (vy[:, 1:] + vy[:, :-1]),
                                    0.5 * (vz + np.roll(vz, -1, axis=2))], axis=-1)
        out["fallen"] = self.fallen.numpy().copy()
        return out

    def water_total(self, fields: dict | None = None) -> float:
        """All the water in the domain and what fell out of it [kg]."""
        f = fields or self.fields()
        s = self.settings
        mixing = f["vapour"].astype(np.float64) + f["cloud"] + f["rain"]
        in_air = np.sum(mixing * self.base.density[None, :, None]) * s.dx * s.dx * s.dy
        return float(in_air + np.sum(f["fallen"], dtype=np.float64) * s.dx * s.dx)

    def divergence(self) -> np.ndarray:
        """∇·(ρ0 u) [kg/(m^3 s)] of the current flow, per cell."""
        out = wp.zeros(self.projection.cell_count, dtype=float, device=self.device)
        self.projection.divergence(self.flows[0], out)
        return out.numpy().reshape(self.grid.nx, self.grid.ny, self.grid.nz)
