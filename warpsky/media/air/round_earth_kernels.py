"""The air of a round earth on the device: the geometry of a ray in a spherical shell of air, its optical depth
and in-scattered light by quadrature, and the table of optical depths to the top of the air.

A round earth has no closed form for a slanted ray's optical depth (Chapman's function has none), so every ray
integral is a quadrature. Its variable follows the air: a straight ray has one point nearest the planet's centre
(its perigee, at distance r_p), and on each side of it the altitude grows monotonically as h = h_p + z^2, with
dt/dz = 2 r / sqrt(2 r_p + z^2) smooth even at the perigee (where dt/dh is infinite). Each side is cut into panels at
altitudes h_lo + H (2^k - 1) / 2 above its lowest point (H the smallest scale height: dense where the air is), and
each panel takes :data:`PANEL_NODES` Gauss-Legendre nodes in z; the optical depth from the ray's start to every node
comes from the panel's spectral integration matrix (the integral of the nodes' interpolating polynomial), so the
transmittance along the ray is as accurate as the ray's own integral, with no table differences.

Altitudes are carried beside radii (r = R + h in float32 loses half a metre at the Earth's radius): the perigee's
altitude is h0 - r0 mu0^2 / (1 + sqrt(1 - mu0^2)), and a point's h0 + t (2 r0 mu0 + t) / (r + r0).

The sun's optical depth D(h, mu_s) to the top of the air is tabulated (:func:`depth_table`) over Bruneton's (2017,
"A qualitative and quantitative evaluation of 8 clear sky models", §4) parametrisation of rays that miss the
floor: x_r = rho / H (rho = sqrt(r^2 - r_floor^2), H its value at the top) and x_mu = (d - d_min) / (d_max - d_min)
(d the distance to the top). The table is built by the same quadrature on the scene's device.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.core.files import cached_array
from warpsky.core.numerics import exp3
from warpsky.media.air.analytic import AnalyticAir, analytic_air
from warpsky.media.air.mixture_kernels import ozone_density

#: Gauss-Legendre nodes per panel of a ray integral.
PANEL_NODES = 8
#: At most this many panels on each side of a ray's perigee (the last reaches the top of the air).
MAX_PANELS = 12
#: Depth table entries over x_r (altitude) and x_mu (direction).
DEPTH_RADII = 96
DEPTH_MUS = 256
#: The air ends where its density has fallen by this factor: above it is vacuum.
TOP_FACTOR = 1.0e-6

_X, _W = np.polynomial.legendre.leggauss(PANEL_NODES)


def _integration_matrix(x: np.ndarray) -> np.ndarray:
    """S[i, j] = int_{-1}^{x_i} l_j(x) dx for the Lagrange basis l_j of the nodes ``x``."""
    n = len(x)
    vander = np.polynomial.legendre.legvander(x, n - 1)  # (node, degree)
    coefficients = np.linalg.inv(vander)  # row k: Legendre coefficients of ... columns: l_j
    out = np.zeros((n, n))
    for j in range(n):
        antiderivative = np.polynomial.legendre.legint(coefficients[:, j], lbnd=-1.0)
        out[:, j] = np.polynomial.legendre.legval(x, antiderivative)
    return out


_nodes = wp.types.vector(length=PANEL_NODES, dtype=float)
_matrix = wp.types.matrix(shape=(PANEL_NODES, PANEL_NODES), dtype=float)
PANEL_X = wp.constant(_nodes(*_X.tolist()))
PANEL_W = wp.constant(_nodes(*_W.tolist()))
PANEL_S = wp.constant(_matrix(*_integration_matrix(_X).ravel().tolist()))


def air_top(atm) -> float:
    """Altitude [m above sea level] above which the air is vacuum: every constituent's density below
    :data:`TOP_FACTOR` of its peak."""
    top = -math.log(TOP_FACTOR) * atm.scale_height
    if atm.has_aerosols:
        top = max(top, -math.log(TOP_FACTOR) * atm.mie_scale_height)
    if atm.has_ozone:
        top = max(top, atm.ozone_altitude + atm.ozone_width)
    return float(top)


def smallest_scale(atm) -> float:
    """The smallest scale height [m] of the air's constituents: the panels' first width."""
    return float(min(atm.scale_height, atm.mie_scale_height) if atm.has_aerosols else atm.scale_height)


@wp.struct
class RoundAir:
    """A round earth's air as kernels see it (its constituents are the :class:`AnalyticAir` beside it)."""

    radius: float  # of sea level [m]
    floor: float  # altitude of the air's floor (the ground, else sea level) [m above sea level]
    top: float  # altitude of the air's top [m above sea level]
    scale: float  # the smallest scale height [m]: the first panel's height
    depth: wp.array2d(dtype=wp.vec3)  # (DEPTH_RADII, DEPTH_MUS) optical depth to the top, RGB


@wp.struct
class Line:
    """A ray's line about the planet's centre."""

    h0: float  # altitude of the start [m above sea level]
    r0: float  # its radius [m]
    mu0: float  # the ray's elevation sine there
    hp: float  # the perigee's altitude (below the floor for a ray that hits it)
    drop: float  # h0 - hp >= 0
    rp: float  # the perigee's radius
    tp: float  # distance to the perigee along the ray (negative: behind the start)


@wp.func
def make_line(ra: RoundAir, h0: float, mu0: float) -> Line:
    out = Line()
    mu = wp.clamp(mu0, -1.0, 1.0)
    out.h0 = h0
    out.r0 = ra.radius + h0
    out.mu0 = mu
    drop = out.r0 * mu * mu / (1.0 + wp.sqrt(wp.max(1.0 - mu * mu, 0.0)))  # r0 - rp, without cancellation
    out.hp = h0 - drop
    out.drop = drop
    out.rp = out.r0 - drop
    out.tp = -out.r0 * mu
    return out


@wp.func
def altitude_at(line: Line, t: float) -> float:
    """Altitude [m above sea level] at distance ``t`` along the line."""
    r2 = line.r0 * line.r0 + t * (2.0 * line.r0 * line.mu0 + t)
    return line.h0 + t * (2.0 * line.r0 * line.mu0 + t) / (wp.sqrt(wp.max(r2, 0.0)) + line.r0)


@wp.func
def horizon_sine(ra: RoundAir, h: float) -> float:
    """Elevation sine of the floor's horizon seen from altitude ``h`` (0 at the floor, negative above it)."""
    return horizon_of(ra.radius, ra.floor, h)


@wp.func
def horizon_of(radius: float, floor: float, h: float) -> float:
    """:func:`horizon_sine` of a planet of sea-level ``radius`` whose air ends at ``floor``."""
    x = wp.max(h - floor, 0.0) * (2.0 * radius + h + floor)
    return -wp.sqrt(x) / (radius + h)


@wp.func
def sun_coordinate(radius: float, floor: float, h: float, mu_s: float) -> float:
    """The sun's coordinate v in [-1, 1] at altitude ``h``: its elevation sine above the floor's horizon seen from
    there, scaled to [0, 1] above and [-1, 0] below, square-rooted (dense where the sun meets the horizon: a
    point's twilight starts at its own horizon, lower for higher points)."""
    mu_h = horizon_of(radius, floor, h)
    x = (mu_s - mu_h) / (1.0 - mu_h)
    if mu_s < mu_h:
        x = (mu_s - mu_h) / (1.0 + mu_h)
    return wp.sign(x) * wp.sqrt(wp.min(wp.abs(x), 1.0))


@wp.func
def sun_at_coordinate(radius: float, floor: float, h: float, v: float) -> float:
    """The sun's elevation sine whose :func:`sun_coordinate` at altitude ``h`` is ``v``."""
    mu_h = horizon_of(radius, floor, h)
    x = wp.sign(v) * v * v
    if x >= 0.0:
        return mu_h + x * (1.0 - mu_h)
    return mu_h + x * (1.0 + mu_h)


@wp.func
def sphere_below(radius: float, h0: float, level: float, mu0: float) -> float:
    """Distance [m] along a ray from altitude ``h0`` of elevation sine ``mu0`` down to the sphere at altitude
    ``level`` < ``h0`` (of a planet whose sea level has ``radius``); -1 when it misses."""
    if mu0 >= 0.0:
        return -1.0
    r0 = radius + h0
    c = (h0 - level) * (2.0 * radius + h0 + level)  # r0^2 - r_level^2 > 0
    disc = r0 * r0 * mu0 * mu0 - c
    if disc < 0.0:
        return -1.0
    return c / (-r0 * mu0 + wp.sqrt(disc))


@wp.func
def floor_distance(ra: RoundAir, h0: float, mu0: float) -> float:
    """Distance [m] along a ray from altitude ``h0`` of elevation sine ``mu0`` to the floor's sphere; -1 when it
    misses."""
    if h0 <= ra.floor:
        if mu0 < 0.0:
            return 0.0
        return -1.0
    return sphere_below(ra.radius, h0, ra.floor, mu0)


@wp.func
def top_distance(ra: RoundAir, h0: float, mu0: float) -> float:
    """Distance [m] along a ray from altitude ``h0`` (at or below the top) to the top of the air."""
    h = wp.min(h0, ra.top)
    r0 = ra.radius + h
    c = (ra.top - h) * (2.0 * ra.radius + ra.top + h)  # r_top^2 - r0^2 >= 0
    disc = r0 * r0 * mu0 * mu0 + c
    if mu0 > 0.0:
        return c / (r0 * mu0 + wp.sqrt(disc))
    return -r0 * mu0 + wp.sqrt(disc)


@wp.func
def extinction_at(air: AnalyticAir, h: float) -> wp.vec3:
    """Every constituent's extinction [1/m] at altitude ``h``."""
    out = air.beta_sea_level * wp.exp(-air.gamma * h)
    if air.mixed != 0:
        out += air.mie_extinction * wp.exp(-air.mie_gamma * h) + air.ozone * ozone_density(air, h)
    return out


# ---- the optical depth table ----------------------------------------------------------------------------------


@wp.func
def depth_cell(ra: RoundAir, h: float, mu: float) -> wp.vec2:
    """(x_r, x_mu) in [0, 1]^2 of the ray from altitude ``h`` of elevation sine ``mu`` (clamped to the rays that
    miss the floor)."""
    hh = wp.clamp(h, ra.floor, ra.top)
    r_floor = ra.radius + ra.floor
    rho = wp.sqrt((hh - ra.floor) * (2.0 * r_floor + hh - ra.floor))
    big_h = wp.sqrt((ra.top - ra.floor) * (2.0 * r_floor + ra.top - ra.floor))
    d = top_distance(ra, hh, wp.max(mu, horizon_sine(ra, hh)))
    d_min = ra.top - hh
    d_max = rho + big_h
    x_mu = float(0.0)
    if d_max - d_min > 1.0e-3:
        x_mu = wp.clamp((d - d_min) / (d_max - d_min), 0.0, 1.0)
    return wp.vec2(wp.clamp(rho / big_h, 0.0, 1.0), x_mu)


@wp.func
def table_depth(ra: RoundAir, h: float, mu: float) -> wp.vec3:
    """Optical depth from altitude ``h`` along elevation sine ``mu`` to the top of the air (the table, bilinear);
    below the floor's horizon, the grazing ray's."""
    x = depth_cell(ra, h, mu)
    fr = x[0] * float(ra.depth.shape[0] - 1)
    fm = x[1] * float(ra.depth.shape[1] - 1)
    i = wp.min(int(fr), ra.depth.shape[0] - 2)
    j = wp.min(int(fm), ra.depth.shape[1] - 2)
    a = fr - float(i)
    b = fm - float(j)
    return ((ra.depth[i, j] * (1.0 - b) + ra.depth[i, j + 1] * b) * (1.0 - a)
            + (ra.depth[i + 1, j] * (1.0 - b) + ra.depth[i + 1, j + 1] * b) * a)


@wp.func
def disk_fraction(elevation: float, radius: float) -> float:
    """Fraction of a disk of angular ``radius`` [rad] centred ``elevation`` [rad] above a horizon (a step for
    a disk of radius 0), as :func:`warpsky.light.sun.visible_fraction`."""
    if radius <= 0.0:
        if elevation > 0.0:
            return 1.0
        return 0.0
    if elevation >= radius:
        return 1.0
    if elevation <= -radius:
        return 0.0
    x = elevation / radius
    return wp.clamp((wp.acos(-x) + x * wp.sqrt(1.0 - x * x)) / wp.pi, 0.0, 1.0)


@wp.func
def sun_transmittance(ra: RoundAir, h: float, mu_s: float, sun_radius: float) -> wp.vec3:
    """Sunlight's transmittance to altitude ``h`` from a sun of elevation sine ``mu_s`` there and angular radius
    ``sun_radius`` [rad]: the part of its disk above the floor's horizon times the air's transmittance."""
    mu_h = horizon_sine(ra, h)
    f = disk_fraction(wp.asin(wp.clamp(mu_s, -1.0, 1.0)) - wp.asin(mu_h), sun_radius)
    out = wp.vec3(0.0)
    if f > 0.0:
        out = exp3(table_depth(ra, h, wp.max(mu_s, mu_h))) * f
    return out


# ---- ray integrals --------------------------------------------------------------------------------------------


@wp.struct
class Panels:
    """One side of a ray's perigee between two distances, as panels in z (h = h_p + z^2)."""

    h_start: float  # altitude where the side starts along the ray
    h_end: float  # ... and ends
    direction: float  # +1: altitude rises along the ray (z grows), -1: it falls
    h_lo: float  # the side's lowest altitude
    count: int  # panels


@wp.func
def side(ra: RoundAir, line: Line, t_a: float, t_b: float) -> Panels:
    """The panels of the stretch [t_a, t_b] of ``line`` (one side of its perigee)."""
    out = Panels()
    out.h_start = altitude_at(line, t_a)
    out.h_end = altitude_at(line, t_b)
    # at the perigee exactly (z = 0: the float32 altitude there is off by up to a metre, a few km of grazing ray)
    if t_a == line.tp:
        out.h_start = line.hp
    if t_b == line.tp:
        out.h_end = line.hp
    out.direction = 1.0
    out.h_lo = out.h_start
    h_hi = out.h_end
    if t_b <= line.tp:
        out.direction = -1.0
        out.h_lo = out.h_end
        h_hi = out.h_start
    count = int(1)
    while count < MAX_PANELS and out.h_lo + ra.scale * 0.5 * (wp.pow(2.0, float(count)) - 1.0) < h_hi:
        count += 1
    out.count = count
    if t_b <= t_a:
        out.count = 0
    return out


@wp.func
def panel_bound(ra: RoundAir, line: Line, s: Panels, k: int) -> float:
    """Altitude at the k-th panel boundary along the ray (0: the side's start, ``count``: its end)."""
    if k <= 0:
        return s.h_start
    if k >= s.count:
        return s.h_end
    index = k
    if s.direction < 0.0:
        index = s.count - k
    return s.h_lo + ra.scale * 0.5 * (wp.pow(2.0, float(index)) - 1.0)


@wp.struct
class Node:
    """One quadrature node of a ray: where it is and its weight dt."""

    t: float
    h: float
    mu: float  # the ray's elevation sine there
    dt: float  # Gauss-Legendre weight times dt/dz times the panel's half width


@wp.func
def panel_node(line: Line, s: Panels, h_a: float, h_b: float, j: int) -> Node:
    """Node ``j`` of the panel between altitudes ``h_a`` and ``h_b`` (in the ray's order) on the side ``s``: in z
    with h = h_p + z^2, the panel's width in z and each node's altitude taken from the altitudes (z itself is
    large for a steep ray, its differences small)."""
    z_a = wp.sqrt(wp.max(h_a - line.h0 + line.drop, 0.0))
    z_b = wp.sqrt(wp.max(h_b - line.h0 + line.drop, 0.0))
    width = float(0.0)
    if z_a + z_b > 0.0:
        width = (h_b - h_a) / (z_a + z_b)
    delta = 0.5 * width * (PANEL_X[j] + 1.0)
    z = z_a + delta
    root = wp.sqrt(2.0 * line.rp + z * z)
    out = Node()
    out.h = h_a + delta * (2.0 * z_a + delta)
    r = line.rp + z * z
    out.t = line.tp + s.direction * z * root
    out.mu = s.direction * z * root / r
    out.dt = PANEL_W[j] * 0.5 * width * s.direction * 2.0 * r / root
    return out


_nodes = wp.types.vector(length=PANEL_NODES, dtype=float)


@wp.struct
class PanelExtinction:
    """The air's extinction at a panel's nodes times dt/dx (x the panel's Gauss-Legendre variable on [-1, 1]), per
    channel: the integrand whose integral up to each node is that node's optical depth from the panel's start."""

    r: _nodes
    g: _nodes
    b: _nodes


@wp.func
def panel_extinction(air: AnalyticAir, line: Line, s: Panels, h_a: float, h_b: float) -> PanelExtinction:
    out = PanelExtinction()
    for j in range(PANEL_NODES):
        node = panel_node(line, s, h_a, h_b, j)
        e = extinction_at(air, node.h) * (node.dt / PANEL_W[j])
        out.r[j] = e[0]
        out.g[j] = e[1]
        out.b[j] = e[2]
    return out


@wp.func
def depth_to_node(panel: PanelExtinction, j: int) -> wp.vec3:
    """Optical depth from the panel's start to its node ``j`` (the spectral integration matrix)."""
    return wp.vec3(wp.dot(PANEL_S[j], panel.r), wp.dot(PANEL_S[j], panel.g), wp.dot(PANEL_S[j], panel.b))


@wp.func
def panel_depth(panel: PanelExtinction) -> wp.vec3:
    """The panel's whole optical depth."""
    return wp.vec3(wp.dot(PANEL_W, panel.r), wp.dot(PANEL_W, panel.g), wp.dot(PANEL_W, panel.b))


@wp.func
def piece_bounds(line: Line, piece: int, distance: float) -> wp.vec2:
    """[t_a, t_b] of side ``piece`` (0: before the perigee, 1: after it) of the ray's first ``distance`` metres
    (t_b <= t_a: empty)."""
    if piece == 0:
        return wp.vec2(0.0, wp.min(distance, line.tp))
    return wp.vec2(wp.max(line.tp, 0.0), distance)


@wp.func
def ray_depth(air: AnalyticAir, ra: RoundAir, h0: float, mu0: float, distance: float) -> wp.vec3:
    """Optical depth of the air from altitude ``h0`` over ``distance`` [m] along elevation sine ``mu0`` (a ray
    that stays above the floor)."""
    line = make_line(ra, h0, mu0)
    out = wp.vec3(0.0)
    for piece in range(2):
        bounds = piece_bounds(line, piece, distance)
        if bounds[1] > bounds[0]:
            s = side(ra, line, bounds[0], bounds[1])
            for k in range(s.count):
                out += panel_depth(panel_extinction(air, line, s, panel_bound(ra, line, s, k),
                                                    panel_bound(ra, line, s, k + 1)))
    return out


@wp.kernel
def depth_table_kernel(air: AnalyticAir, ra: RoundAir, out: wp.array2d(dtype=wp.vec3), row_offset: int):
    """Entry (i, j), i = row_offset + k: the optical depth to the top of x_r = i / (rows - 1), x_mu = j / (cols - 1)."""
    k, j = wp.tid()
    x_r = float(row_offset + k) / float(out.shape[0] - 1)
    x_mu = float(j) / float(out.shape[1] - 1)
    r_floor = ra.radius + ra.floor
    big_h = wp.sqrt((ra.top - ra.floor) * (2.0 * r_floor + ra.top - ra.floor))
    rho = big_h * x_r
    h = ra.floor + rho * rho / (wp.sqrt(rho * rho + r_floor * r_floor) + r_floor)
    r = r_floor + (h - ra.floor)
    d_min = ra.top - h
    d_max = rho + big_h
    d = d_min + x_mu * (d_max - d_min)
    mu = float(1.0)
    if d > 0.0:
        mu = wp.clamp((big_h * big_h - rho * rho - d * d) / (2.0 * r * d), -1.0, 1.0)
    out[row_offset + k, j] = ray_depth(air, ra, h, mu, d)


def air_key(atm, floor: float) -> tuple:
    """What of ``atm`` and its floor the round air's tables depend on, hashable."""
    colours = (atm.beta_sea_level, atm.mie_scattering, atm.mie_absorption, atm.ozone_absorption)
    return (tuple(float(v) for c in colours for v in c), float(atm.scale_height), float(atm.mie_scale_height),
            float(atm.mie_g), float(atm.ozone_altitude), float(atm.ozone_width), float(atm.planet_radius),
            float(floor))


_TABLES: dict = {}


def depth_table(atm, floor: float, device) -> wp.array2d:
    """The optical depth table of ``atm`` over a floor at ``floor`` [m above sea level] on ``device``: built once
    per air, floor and kind of device and kept on disk (:func:`~warpsky.core.files.cached_array`)."""
    key, device = air_key(atm, floor), str(wp.get_device(device))
    if (key, device) not in _TABLES:

        def build():
            out = wp.zeros((DEPTH_RADII, DEPTH_MUS), dtype=wp.vec3, device=device)
            inputs = [analytic_air(atm, np.zeros(3)), round_struct(atm, floor, device, table=False), out]
            launch_rows(depth_table_kernel, DEPTH_RADII, DEPTH_MUS, inputs, device)
            return out.numpy()

        module = depth_table_kernel.module.get_module_hash().hex()  # the kernel and every function it calls
        identity = (key, DEPTH_RADII, DEPTH_MUS, device.split(":")[0], module)
        values = cached_array("air", "round-depth", identity, build)
        _TABLES[key, device] = wp.array(values, dtype=wp.vec3, device=device)
    return _TABLES[key, device]


def round_struct(atm, floor: float, device, *, table: bool = True) -> RoundAir:
    """Kernel view of the round earth of ``atm`` (which must have ``planet_radius`` > 0) over a floor at ``floor``
    [m above sea level]; with ``table`` its optical depth table (built on ``device`` on first use)."""
    out = RoundAir()
    out.radius = float(atm.planet_radius)
    out.floor = float(floor)
    out.top = max(air_top(atm), float(floor) + 1.0)
    out.scale = smallest_scale(atm)
    if table:
        out.depth = depth_table(atm, floor, device)
    return out


def reference_depth(atm, h0: float, mu0: float, distance: float, count: int = 200_000) -> np.ndarray:
    """(3,) optical depth along a round earth's ray by the trapezoid rule in t over ``count`` points, every point's
    altitude in float64, on the host (a brute-force reference for tests)."""
    from warpsky.media.air.mixture import mie_extinction
    from warpsky.media.air.mixture import ozone_density as ozone

    radius = atm.planet_radius
    t = np.linspace(0.0, distance, count)
    r0 = radius + h0
    r = np.sqrt(r0 * r0 + 2.0 * r0 * mu0 * t + t * t)
    h = (r - radius)[:, None]
    kappa = atm.beta_sea_level * np.exp(-atm.gamma * h)
    if atm.has_aerosols:
        kappa = kappa + mie_extinction(atm) * np.exp(-h / atm.mie_scale_height)
    if atm.has_ozone:
        kappa = kappa + atm.ozone_absorption * ozone(atm, h)
    return np.trapezoid(kappa, t, axis=0)
