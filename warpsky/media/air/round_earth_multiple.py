"""The light a round earth's air scatters more than once, as a table Psi(h, mu_s) built on the device.

A round earth lit by parallel sunlight is symmetric about the axis through its centre towards the sun, so the
isotropic part of any order's source at a point depends on two numbers only: its altitude h and the sun's elevation
sine mu_s there. The table solves the orders >= 2 with isotropic scattering exactly on that grid, as the flat
earth's table (:mod:`~warpsky.media.air.multiple_kernels`) does over altitude alone:

* J_2(h, mu_s) = (1 / 4 pi) int L_1 dw, the single-scattering field (each constituent's phase, the sun's disk
  clipped by each point's horizon: :func:`~warpsky.media.air.round_earth_light.round_light`'s integrand) plus, looking
  down, the sunlit floor (albedo rho, rho / pi mu_s T_sun) through the air;
* R_2(mu_s) = rho / pi E_1, the floor lit by the single-scattering sky;
* each order's source carried along every direction to the next, x_{n+1} = M x_n (the ray integrals of
  sigma_s T J_n, J_n bilinear on the grid, plus the floor's radiance R_n seen through the air, and R_{n+1} from the
  floor's irradiance), so Psi = sum_{n >= 2} J_n = (I - M)^{-1} x_2, one dense system per channel on the host.

The second order keeps its phase functions to their quadrupole: Rayleigh's phase is (1 + P_2(cos) / 2) / 4 pi, so
its anisotropic part adds (3 / 16 pi) v^T Q v along a view v, Q = int L_1 (w w^T - I / 3) dw the single-scattering
field's second moments in the point's frame (up, towards the sun's azimuth, across; mirror symmetry leaves Q_uu,
Q_hh, Q_uh); the aerosols' Henyey-Greenstein phase (1 + 3 g P_1 + 5 g^2 P_2 + ...) / 4 pi adds
(3 g F . v + (15 / 2) g^2 v^T Q v) / 4 pi, F = int L_1 w dw (F_u, F_h), the sum with J_2 kept >= 0: a strongly
forward phase sends little of the bright floor's upward light back down. These moments and J_2 are tabulated beside
Psi; orders >= 3 are isotropic.

Rows: h = floor + height u^2 (u uniform, :data:`HEIGHTS` of them); columns: the sun's elevation sine above each
row's own horizon, square-rooted (:func:`~warpsky.media.air.round_earth_kernels.sun_coordinate`, :data:`SUNS` uniform on
[-1, 1]), so the shadow of the planet, which reaches higher points at lower suns, falls on the same columns at every
height (with the plain sine, interpolating across that diagonal left the twilight sky 5-10 % dark in blue); the floor's
unknowns take the plain sine (its horizon is level). Directions: Gauss-Legendre in sqrt(|mu|) on
each hemisphere (:data:`ELEVATIONS`) times :data:`AZIMUTHS` midpoints on [0, pi] (the other half by symmetry).
Unlike Hillaire (2020, §5.5), whose table takes the same two numbers, it does not assume each order as strong as the
point's own (his geometric series) and keeps the floor's bounces between orders.

A build takes a second or two on a CPU, so the table is kept on disk (:func:`cache_path`) and read from there by later
processes; a build says so first (:mod:`warpsky.core.progress`).
"""

from __future__ import annotations

import functools
import hashlib
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.files import atomic_write, cache_dir
from warpsky.core.numerics import exp3
from warpsky.core.progress import announced
from warpsky.media.air.analytic import AnalyticAir, analytic_air
from warpsky.media.air.round_earth_kernels import (
    PANEL_NODES,
    RoundAir,
    air_key,
    floor_distance,
    horizon_sine,
    make_line,
    panel_bound,
    panel_depth,
    panel_extinction,
    piece_bounds,
    round_struct,
    side,
    sun_at_coordinate,
    sun_coordinate,
    sun_transmittance,
    top_distance,
)
from warpsky.media.air.round_earth_light import RoundMultiple, lit_node
from warpsky.optics.phase import phase_hg, phase_rayleigh

#: Psi and J_2 are tabulated as logarithms of themselves plus this (both fall by orders of magnitude across twilight,
#: where linear interpolation between nodes 2.4 deg apart doubled them).
LOG_FLOOR = 1.0e-30
#: Table rows (altitudes) and columns (sun elevation sines), and terms per node.
HEIGHTS = 24
SUNS = 48
#: The floor's unknowns: its radiance against the sun's elevation sine there (finer: in twilight it falls by orders
#: of magnitude within a few degrees, and it enters the system linearly).
FLOOR_SUNS = 144
TERMS = 7
#: Directions of the build: Gauss-Legendre nodes per hemisphere, azimuths on [0, pi].
ELEVATIONS = 8
AZIMUTHS = 6
#: The sun's angular radius [rad] the table is built for (the real sun's; the disk matters only at the horizon).
SUN_RADIUS = 0.5 * math.radians(0.53)


@dataclass(frozen=True)
class RoundTable:
    """Psi on the grid, per unit sun irradiance [1/sr], RGB: ``values`` (HEIGHTS, SUNS, TERMS, 3), per node
    ln(Psi + LOG_FLOOR), ln(J_2 + LOG_FLOOR) (the second order's isotropic source), the single-scattering field's
    second moments Q_uu, Q_hh, Q_uh and first moments F_u, F_h over J_2
    (:func:`~warpsky.media.air.round_earth_light.multiple_terms`); the rows span ``floor`` + ``height`` u^2 [m above sea
    level]; ``seconds`` the build's time."""

    values: np.ndarray
    floor: float
    height: float
    seconds: float
    mie_g: float = 0.0
    radius: float = 0.0


def directions() -> np.ndarray:
    """(count, 4): mu, cos(phi), sin(phi), weight (summing to 4 pi) of the build's sphere."""
    x, w = np.polynomial.legendre.leggauss(ELEVATIONS)
    u, wu = 0.5 * (x + 1.0), 0.5 * w
    mu, wmu = u * u, wu * 2.0 * u  # int_0^1 f(mu) dmu in u = sqrt(mu)
    phi = (np.arange(AZIMUTHS) + 0.5) * math.pi / AZIMUTHS
    rows = [(sign * m, math.cos(p), math.sin(p), wm * 2.0 * math.pi / AZIMUTHS)
            for sign in (1.0, -1.0) for m, wm in zip(mu, wmu, strict=True) for p in phi]
    return np.array(rows, dtype=np.float64)


@wp.struct
class Grid:
    """The table's grid and the floor's albedo."""

    floor: float
    height: float
    albedo: wp.vec3
    radius: float  # of sea level [m]


@wp.func
def grid_cell(grid: Grid, h: float, mu_s: float) -> wp.vec4:
    """(row, column, row weight, column weight) of bilinear interpolation on the grid (row + 1, column + 1 take
    the weights)."""
    u = wp.sqrt(wp.clamp((h - grid.floor) / grid.height, 0.0, 1.0)) * float(HEIGHTS - 1)
    v = sun_coordinate(grid.radius, grid.floor, h, mu_s)
    s = wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(SUNS - 1)
    i = wp.min(int(u), HEIGHTS - 2)
    j = wp.min(int(s), SUNS - 2)
    return wp.vec4(float(i), float(j), u - float(i), s - float(j))


@wp.func
def add_cell(m: wp.array3d(dtype=float), row: int, cell: wp.vec4, value: wp.vec3):
    """Spread ``value`` (per channel) over the four grid nodes of ``cell`` in row ``row`` of ``m``."""
    i = int(cell[0])
    j = int(cell[1])
    for di in range(2):
        for dj in range(2):
            w = (1.0 - cell[2]) * (1.0 - cell[3])
            if di == 1 and dj == 0:
                w = cell[2] * (1.0 - cell[3])
            elif di == 0 and dj == 1:
                w = (1.0 - cell[2]) * cell[3]
            elif di == 1 and dj == 1:
                w = cell[2] * cell[3]
            column = (i + di) * SUNS + j + dj
            for c in range(3):
                wp.atomic_add(m, c, row, column, w * value[c])


@wp.func
def floor_column(mu_s: float) -> float:
    """Fractional column of the floor's unknowns for a sun of elevation sine ``mu_s`` there (sign(mu_s)
    sqrt(|mu_s|) uniform on [-1, 1]: the floor's horizon is level)."""
    v = wp.sign(mu_s) * wp.sqrt(wp.abs(mu_s))
    return wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(FLOOR_SUNS - 1)


@wp.func
def add_floor(m: wp.array3d(dtype=float), row: int, mu_s: float, value: wp.vec3):
    """Spread ``value`` over the floor's two unknowns about ``mu_s`` in row ``row`` of ``m``."""
    s = floor_column(mu_s)
    j = wp.min(int(s), FLOOR_SUNS - 2)
    b = s - float(j)
    for c in range(3):
        wp.atomic_add(m, c, row, HEIGHTS * SUNS + j, (1.0 - b) * value[c])
        wp.atomic_add(m, c, row, HEIGHTS * SUNS + j + 1, b * value[c])


@wp.func
def floor_seen(ra: RoundAir, grid: Grid, m: wp.array3d(dtype=float), x2: wp.array(dtype=wp.vec3), row: int,
               t_floor: wp.vec3, mu_g: float, share: float) -> wp.vec3:
    """A build ray that ends on the floor (through the air's transmittance ``t_floor``, where the sun's elevation
    sine is ``mu_g``): the floor's radiance R_n (unknown) in M, the sunlit floor in J_2; returns the sunlit
    floor's radiance through the air (its share of L_1)."""
    mu = wp.clamp(mu_g, -1.0, 1.0)
    add_floor(m, row, mu, t_floor * share)
    sunlit = wp.cw_mul(grid.albedo, sun_transmittance(ra, ra.floor, mu, SUN_RADIUS)) * (wp.max(mu, 0.0) / wp.pi)
    seen = wp.cw_mul(t_floor, sunlit)
    wp.atomic_add(x2, row, seen * share)
    return seen


@wp.struct
class BuildRay:
    """One ray of the build: from altitude ``h0`` along elevation sine ``mu0`` under a sun of elevation sine
    ``mu_s0`` at its start, cos(ray, sun) ``nu``; its row of the system, and the weight of its contributions there
    (1 / 4 pi of its solid angle for a source row, albedo / pi times its projected solid angle for a floor row)."""

    h0: float
    mu0: float
    mu_s0: float
    nu: float
    row: int
    weight: wp.vec3


@wp.func
def trace_build_ray(air: AnalyticAir, ra: RoundAir, grid: Grid, ray: BuildRay, m: wp.array3d(dtype=float),
                    x2: wp.array(dtype=wp.vec3)) -> wp.vec3:
    """Add ``ray``'s share of M and of x_2 (the air it crosses, and the floor where it ends there) to its row;
    returns the single-scattering radiance it brings (L_1, the sunlit floor included)."""
    distance = floor_distance(ra, ray.h0, ray.mu0)
    hits = distance >= 0.0
    if not hits:
        distance = top_distance(ra, ray.h0, ray.mu0)
    phase_r = phase_rayleigh(ray.nu)
    phase_m = phase_hg(ray.nu, air.mie_g)
    line = make_line(ra, ray.h0, ray.mu0)
    tau = wp.vec3(0.0)
    first = wp.vec3(0.0)
    for piece in range(2):
        bounds = piece_bounds(line, piece, distance)
        if bounds[1] > bounds[0]:
            s = side(ra, line, bounds[0], bounds[1])
            for p in range(s.count):
                h_a = panel_bound(ra, line, s, p)
                h_b = panel_bound(ra, line, s, p + 1)
                panel = panel_extinction(air, line, s, h_a, h_b)
                for j in range(PANEL_NODES):
                    n = lit_node(air, ra, line, s, panel, tau, h_a, h_b, j, ray.mu_s0, ray.nu)
                    carried = wp.cw_mul(n.parts.rayleigh + n.parts.mie, n.t_view) * n.dt
                    single = wp.cw_mul(wp.cw_mul(n.parts.rayleigh * phase_r + n.parts.mie * phase_m, n.t_view),
                                       sun_transmittance(ra, n.h, n.mu_s, SUN_RADIUS)) * n.dt
                    add_cell(m, ray.row, grid_cell(grid, n.h, n.mu_s), wp.cw_mul(carried, ray.weight))
                    wp.atomic_add(x2, ray.row, wp.cw_mul(single, ray.weight))
                    first += single
                tau += panel_depth(panel)
    if hits:
        mu_g = (line.r0 * ray.mu_s0 + distance * ray.nu) / (ra.radius + ra.floor)
        first += floor_seen(ra, grid, m, x2, ray.row, exp3(tau), mu_g, ray.weight[0])
    return first


@wp.kernel
def transport_kernel(air: AnalyticAir, ra: RoundAir, grid: Grid, dirs: wp.array(dtype=wp.vec4),
                     m: wp.array3d(dtype=float), x2: wp.array(dtype=wp.vec3), quad: wp.array2d(dtype=wp.vec3)):
    """Row ``row`` of the system, direction k. Rows below HEIGHTS * SUNS: the source J at node (i, j), the ray
    from altitude h_i towards direction k under a sun of column j: its share of M and of J_2, and the single-
    scattering field's moments. Then the floor's rows: its radiance under a sun of floor column j, from its
    irradiance by the rays looking up."""
    row, k = wp.tid()
    d = dirs[k]
    ray = BuildRay()
    ray.row = row
    ray.mu0 = d[0]
    if row < HEIGHTS * SUNS:
        i = row // SUNS
        u = float(i) / float(HEIGHTS - 1)
        ray.h0 = grid.floor + grid.height * u * u
        ray.mu_s0 = sun_at_coordinate(grid.radius, grid.floor, ray.h0, 2.0 * float(row - i * SUNS) / float(SUNS - 1)
                                      - 1.0)
        ray.weight = wp.vec3(d[3] / (4.0 * wp.pi))
    else:
        if ray.mu0 <= 0.0:
            return
        v = 2.0 * float(row - HEIGHTS * SUNS) / float(FLOOR_SUNS - 1) - 1.0
        ray.h0 = grid.floor
        ray.mu_s0 = wp.sign(v) * v * v
        ray.weight = grid.albedo * (d[3] * ray.mu0 / wp.pi)
    across = wp.sqrt(wp.max(1.0 - ray.mu0 * ray.mu0, 0.0))
    ray.nu = across * d[1] * wp.sqrt(wp.max(1.0 - ray.mu_s0 * ray.mu_s0, 0.0)) + ray.mu0 * ray.mu_s0
    first = trace_build_ray(air, ra, grid, ray, m, x2)
    if row < HEIGHTS * SUNS:
        # the direction's second moments in the point's frame (up, towards the sun's azimuth, across) less 1/3,
        # and its components
        moments = wp.vec3(ray.mu0 * ray.mu0 - 1.0 / 3.0, across * across * d[1] * d[1] - 1.0 / 3.0,
                          ray.mu0 * across * d[1])
        for term in range(3):
            wp.atomic_add(quad, row, term, first * (moments[term] * d[3]))
        wp.atomic_add(quad, row, 3, first * (ray.mu0 * d[3]))
        wp.atomic_add(quad, row, 4, first * (across * d[1] * d[3]))


def build(atm, floor: float, albedo, device) -> RoundTable:
    """The table of the round earth's air ``atm`` over a Lambertian floor of ``albedo`` (RGB) at ``floor`` [m above
    sea level], built on ``device`` (the system solved on the host in float64)."""
    started = time.perf_counter()
    ra = round_struct(atm, floor, device)
    grid = Grid()
    grid.floor = float(floor)
    grid.height = float(ra.top - floor)
    grid.albedo = wp.vec3(*np.asarray(albedo, dtype=np.float64).tolist())
    grid.radius = float(atm.planet_radius)
    count = HEIGHTS * SUNS + FLOOR_SUNS
    sphere = directions()
    with wp.ScopedDevice(device):
        dirs = wp.array(sphere.astype(np.float32), dtype=wp.vec4)
        m = wp.zeros((3, count, count), dtype=float)
        x2 = wp.zeros(count, dtype=wp.vec3)
        quad = wp.zeros((HEIGHTS * SUNS, 5), dtype=wp.vec3)
        wp.launch(transport_kernel, dim=(count, len(sphere)),
                  inputs=[analytic_air(atm, np.zeros(3)), ra, grid, dirs, m, x2, quad])
        matrix = m.numpy().astype(np.float64)
        source = x2.numpy().astype(np.float64)
        moments = quad.numpy().astype(np.float64)
    values = np.zeros((HEIGHTS * SUNS, 3))
    for c in range(3):
        values[:, c] = np.linalg.solve(np.eye(count) - matrix[c], source[:, c])[:HEIGHTS * SUNS]
    j2 = source[:HEIGHTS * SUNS]
    ratios = np.divide(moments, j2[:, None, :], out=np.zeros_like(moments), where=j2[:, None, :] > LOG_FLOOR)
    terms = np.concatenate([np.log(np.maximum(values, 0.0) + LOG_FLOOR)[:, None, :],
                            np.log(np.maximum(j2, 0.0) + LOG_FLOOR)[:, None, :], ratios], axis=1)
    return RoundTable(terms.reshape(HEIGHTS, SUNS, TERMS, 3), float(floor), float(grid.height),
                      time.perf_counter() - started, float(atm.mie_g), float(atm.planet_radius))


#: What a first build takes, for its progress line (1.4 s on 2 idle CPU cores).
BUILD_ESTIMATE = "about 2 s on a CPU"


def cache_path(key: tuple, albedo: tuple, device: str) -> Path:
    """Where the table of the air and floor ``key`` and ``albedo`` built on ``device`` is kept:
    ``$WARPSKY_CACHE/air/round-earth-<hash>.npz``, the hash covering them, the device's kind (a GPU's atomic sums
    run in another order), the build kernel's Warp module hash (its code and every function it calls) and this
    file's code, so that a change to the build is never answered from an old file."""
    source = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()
    kind = "cpu" if device.startswith("cpu") else "cuda"
    text = repr((key, albedo, kind, transport_kernel.module.get_module_hash().hex(), source))
    return cache_dir() / "air" / f"round-earth-{hashlib.sha256(text.encode()).hexdigest()[:20]}.npz"


def _stored(path: Path) -> RoundTable | None:
    try:
        with np.load(path) as data:
            return RoundTable(data["values"], *(float(data[name]) for name in _SCALARS))
    except (OSError, ValueError, EOFError, KeyError):
        return None  # missing or unreadable: built again and overwritten


_SCALARS = ("floor", "height", "seconds", "mie_g", "radius")


@functools.lru_cache(maxsize=32)
def _cached(key: tuple, albedo: tuple, device: str) -> RoundTable:
    """The table read from the disk cache, else built (saying so first) and written there."""
    path = cache_path(key, albedo, device)
    table = _stored(path) if path.is_file() else None
    if table is not None:
        return table
    atm, floor = _KEYED[key]
    with announced("air", "air table",
                   f"building the air's multiple-scattering table on {device} ({BUILD_ESTIMATE}, once per air and "
                   f"ground; then loaded from {path.parent})"):
        table = build(atm, floor, np.array(albedo), device)
    atomic_write(path, lambda tmp: np.savez(tmp, values=table.values,
                                            **{name: getattr(table, name) for name in _SCALARS}))
    return table


_KEYED: dict = {}


def round_table(atm, floor: float, albedo, device) -> RoundTable:
    """The table for ``atm`` over a floor at ``floor`` of ``albedo``, built once per air, floor and kind of device
    and kept in the disk cache (it holds every sun elevation: a sunrise builds it once)."""
    key = air_key(atm, floor)
    _KEYED.setdefault(key, (atm, float(floor)))
    return _cached(key, tuple(float(a) for a in np.asarray(albedo, dtype=np.float64)), str(wp.get_device(device)))


def multiple_struct(table: RoundTable | None, device, name: str = "round_multiple") -> RoundMultiple:
    """Kernel view of ``table`` (None: off, a zero table)."""
    out = RoundMultiple()
    out.enabled = int(table is not None)
    values = table.values if table is not None else np.full((2, 2, TERMS, 3), math.log(LOG_FLOOR))
    out.psi = device_buffers.upload(f"{name}:psi", values.astype(np.float32), wp.vec3, device)
    out.floor = float(table.floor) if table is not None else 0.0
    out.height = float(table.height) if table is not None else 1.0
    out.mie_g = float(table.mie_g) if table is not None else 0.0
    out.radius = float(table.radius) if table is not None else 1.0e7
    return out


__all__ = ["RoundTable", "build", "horizon_sine", "multiple_struct", "round_table"]
