"""Kernels of the unbiased volumetric path tracer: delta tracking, ratio tracking, phase sampling.

Free flights are sampled by delta tracking against a *local* majorant: every medium carries a coarse grid of
upper bounds on its extinction (one value per block of voxels, :class:`MajorantGrid`), and a ray advances from
block boundary to block boundary with the sum of the bounds of the blocks it is in, so thin regions are crossed in
a few steps and a thick core does not slow the rest of the cloud down. Transmittance toward the sun (next-event
estimation) and along the primary ray (the layer's transmittance AOV) uses ratio tracking with the same majorants.

RGB: one path carries three channels. Tentative collisions come at the majorant rate; a collision scatters with
probability P = Σ_c w_c σ_t,c / (μ̄ Σ_c w_c), w the path's throughput (history-aware spectral tracking, Kutz et al.
2017), and is null otherwise; each channel's weight is multiplied by its own probability over the one used
(σ_s,c / (μ̄ P) for scattering, (μ̄ - σ_t,c) / (μ̄ (1 - P)) for null collisions). This is unbiased for every
channel, keeps the sum of the weights on null collisions (no blow-up in chromatic air), and is exactly 1 for grey
media.

Positions are camera-relative metres (float32-safe far from the origin, as in :mod:`warpsky.media.voxel`).
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.media.voxel import MediumDetail, VoxelGrid, VoxelMedia, detailed_value, grid_interval, grid_value
from warpsky.optics.kernels import GRID_SIZE, grid_angle, grid_node, medium_phase, sample_table
from warpsky.optics.phase import INV_FOUR_PI, phase_eval, phase_rayleigh
from warpsky.techniques.common import Ground, PinholeCamera, Sun, camera_ray, camera_ray_at

#: Majorants are inflated by this factor so float32 interpolation never exceeds them.
MAJORANT_MARGIN = wp.constant(1.0001)
INV_4PI = wp.constant(INV_FOUR_PI)
#: Hard cap on tentative collisions per tracking call (guards against non-progress; counted in the stats).
MAX_TRACKING_STEPS = wp.constant(1000000)


@wp.struct
class MajorantGrid:
    """Coarse upper bounds of one medium's extinction: cell (i, j, k) covers voxels [i*block, (i+1)*block)."""

    offset: int  # first value in the flat majorant buffer
    shape: wp.vec3i  # coarse cells along index x, y, z
    block: float  # voxels per cell edge


@wp.struct
class Majorants:
    """Every medium's majorant grid: one :class:`MajorantGrid` per medium over one flat buffer of bounds [1/m]."""

    grids: wp.array(dtype=MajorantGrid)
    values: wp.array(dtype=float)


@wp.struct
class PhaseTables:
    """Flat phase tables and their cumulative tables (one-value dummies without species)."""

    values: wp.array(dtype=float)
    cdf: wp.array(dtype=float)


@wp.struct
class PathSettings:
    """Per-launch settings of the path tracer."""

    environment: wp.vec3  # uniform radiance from every direction
    seed: int
    pixel_jitter: int  # 1: box-filtered pixels, 0: pixel centres
    first_sample: int  # index of the launch's first path per pixel
    sample_count: int  # paths per pixel in this launch
    max_bounces: int


@wp.struct
class PixelSums:
    """Per-pixel sums the launches accumulate into."""

    radiance_sum: wp.array2d(dtype=wp.vec3)
    radiance_sq: wp.array2d(dtype=wp.vec3)
    transmittance_sum: wp.array2d(dtype=wp.vec3)
    depth_sum: wp.array2d(dtype=wp.vec2)  # (sum of depths, hits)
    counters: wp.array2d(dtype=wp.vec2i)  # (tracking steps, capped paths)


@wp.struct
class Air:
    """Riley's exponential atmosphere as a medium of the path tracer (enabled = 0: no air).

    Extinction = scattering = beta_sl e^{-gamma h} [1/m] with h = camera_altitude + y (camera-relative y), Rayleigh
    phase. Its majorant over a stretch of ray is the density at the stretch's lowest point; stretches span ``band``
    metres of height. Above the height where the remaining optical depth to space falls below 1e-6 the air is
    treated as vacuum (a relative bias below 1e-6), so upward rays end.
    """

    enabled: int
    beta_sl: wp.vec3
    gamma: float
    camera_altitude: float
    band: float


@wp.func
def air_coefficient(air: Air, y: float) -> wp.vec3:
    """Air's extinction (= scattering) at camera-relative height y [1/m]."""
    return air.beta_sl * wp.exp(-air.gamma * (air.camera_altitude + y))


@wp.struct
class Segment:
    """The majorant [1/m] that holds from the current point to ``end`` [m along the ray]."""

    majorant: float
    end: float


@wp.func
def majorant_segment(
    grids: wp.array(dtype=VoxelGrid),
    mgrids: wp.array(dtype=MajorantGrid),
    majorants: wp.array(dtype=float),
    grid_count: int,
    origin: wp.vec3,
    direction: wp.vec3,
    t: float,
    t_max: float,
    air: Air,
) -> Segment:
    """Sum of the majorants of all media at ``origin + t * direction`` and where the first of them changes."""
    out = Segment()
    out.majorant = 0.0
    out.end = t_max
    if air.enabled != 0:
        y = origin[1] + t * direction[1]
        dy = direction[1]
        if dy == 0.0:
            out.majorant = wp.max(air_coefficient(air, y)) * MAJORANT_MARGIN
        else:
            remaining = wp.max(air_coefficient(air, y)) / (air.gamma * wp.max(dy, 1.0e-30))
            if dy < 0.0 or remaining > 1.0e-6:
                stretch = air.band / wp.abs(dy)
                lowest = y
                if dy < 0.0:
                    lowest = y + dy * wp.min(stretch, t_max - t)
                out.majorant = wp.max(air_coefficient(air, lowest)) * MAJORANT_MARGIN
                out.end = wp.min(out.end, t + stretch)
    for m in range(grid_count):
        grid = grids[m]
        mg = mgrids[m]
        p0 = grid.eye_index + grid.index_from_world * origin
        dir_index = grid.index_from_world * direction
        span = grid_interval(grid, p0, dir_index, t, t_max)
        if span[1] <= span[0]:
            continue
        if span[0] > t:
            out.end = wp.min(out.end, span[0])  # the medium starts ahead: the majorant changes there
            continue
        # the cell holding the point just ahead of t (so a point on a boundary belongs to the next cell)
        # Float rounding can put a computed cell exit a hair before t: the step forward is at least ``nudge``
        # (1e-4 voxel, or 1e-6 of t far from the camera), so tracking always progresses.
        reach = wp.max(wp.max(wp.abs(dir_index[0]), wp.abs(dir_index[1])), wp.abs(dir_index[2]))
        nudge = wp.max(1.0e-4 / wp.max(reach, 1.0e-30), 1.0e-6 * wp.abs(t))
        probe = p0 + (t + nudge) * dir_index
        exit_t = span[1]
        cell = wp.vec3i(0, 0, 0)
        for a in range(3):
            c = int(wp.floor((probe[a] + 0.5) / mg.block))
            c = wp.clamp(c, 0, mg.shape[a] - 1)
            cell[a] = c
            if dir_index[a] > 0.0:
                exit_t = wp.min(exit_t, (float(c + 1) * mg.block - 0.5 - p0[a]) / dir_index[a])
            elif dir_index[a] < 0.0:
                exit_t = wp.min(exit_t, (float(c) * mg.block - 0.5 - p0[a]) / dir_index[a])
        out.majorant += majorants[mg.offset + (cell[0] * mg.shape[1] + cell[1]) * mg.shape[2] + cell[2]]
        out.end = wp.min(out.end, wp.max(exit_t, t + nudge))
    return out


@wp.struct
class PointMedia:
    """Summed coefficients of all media at a point [1/m]."""

    extinction: wp.vec3
    scattering: wp.vec3


@wp.func
def mean3(v: wp.vec3) -> float:
    return (v[0] + v[1] + v[2]) / 3.0


@wp.struct
class Flight:
    """Result of a free flight: where it ended, whether it scattered there, per-channel weight, cost."""

    t: float
    scattered: int
    weight: wp.vec3
    steps: int
    state: wp.uint32


@wp.struct
class Transmittance:
    """A ratio-tracking estimate per channel, its tentative collisions, and the advanced random state."""

    value: wp.vec3
    steps: int
    state: wp.uint32


@functools.cache
def tracking_functions(has_detail: bool):
    """(media_at, delta_track, ratio_track), specialised on animated detail: with it every density lookup is
    multiplied by the medium's detail factor (the majorant grids are scaled by its bound on the host)."""

    @wp.func
    def media_at(
        values: wp.array(dtype=float), grids: wp.array(dtype=VoxelGrid), grid_count: int,
        details: wp.array(dtype=MediumDetail), p: wp.vec3, air: Air,
    ) -> PointMedia:
        """Summed extinction and scattering of all media (and the air) at the camera-relative point ``p``."""
        out = PointMedia()
        out.extinction = wp.vec3(0.0)
        out.scattering = wp.vec3(0.0)
        if air.enabled != 0:
            out.extinction = air_coefficient(air, p[1])
            out.scattering = out.extinction
        for m in range(grid_count):
            grid = grids[m]
            value = grid_value(values, grid, grid.eye_index + grid.index_from_world * p)
            if wp.static(has_detail):
                value = detailed_value(value, details, m, p)
            if value > 0.0:
                out.extinction += grid.extinction * value
                out.scattering += grid.scattering * value
        return out


    @wp.func
    def delta_track(
        values: wp.array(dtype=float),
        grids: wp.array(dtype=VoxelGrid),
        mgrids: wp.array(dtype=MajorantGrid),
        majorants: wp.array(dtype=float),
        grid_count: int,
        details: wp.array(dtype=MediumDetail),
        origin: wp.vec3,
        direction: wp.vec3,
        t_max: float,
        air: Air,
        history: wp.vec3,
        state: wp.uint32,
    ) -> Flight:
        """Weighted delta tracking from ``origin`` along ``direction`` up to ``t_max`` (see the module docstring)."""
        out = Flight()
        out.t = t_max
        out.scattered = 0
        out.steps = 0
        weight = wp.vec3(1.0)
        steps = int(0)
        t = float(0.0)
        while t < t_max and steps < MAX_TRACKING_STEPS:
            seg = majorant_segment(grids, mgrids, majorants, grid_count, origin, direction, t, t_max, air)
            if seg.majorant <= 0.0:
                if seg.end >= t_max:
                    break
                t = wp.max(seg.end, t)
                steps += 1
                continue
            step = -wp.log(1.0 - wp.randf(state)) / seg.majorant
            steps += 1
            if t + step >= seg.end:
                t = seg.end
                continue
            t = t + step
            point = media_at(values, grids, grid_count, details, origin + t * direction, air)
            # history-aware spectral tracking (Kutz et al. 2017): scatter with the throughput-weighted probability,
            # so the channels' weights keep their sum on null collisions and cannot blow up in chromatic air
            hw = wp.cw_mul(history, weight)
            total = hw[0] + hw[1] + hw[2]
            p_scatter = float(0.0)
            if total > 0.0:
                p_scatter = wp.clamp(wp.dot(hw, point.extinction) / (total * seg.majorant), 0.0, 1.0)
            if wp.randf(state) < p_scatter:
                out.t = t
                out.scattered = 1
                out.weight = wp.cw_mul(weight, point.scattering) / (seg.majorant * p_scatter)
                out.steps = steps
                out.state = state
                return out
            null = seg.majorant * wp.vec3(1.0) - point.extinction
            null = wp.vec3(wp.max(null[0], 0.0), wp.max(null[1], 0.0), wp.max(null[2], 0.0))
            weight = wp.cw_mul(weight, null) / (seg.majorant * (1.0 - p_scatter))
        out.t = t_max
        out.weight = weight
        out.steps = steps
        out.state = state
        return out


    @wp.func
    def ratio_track(
        values: wp.array(dtype=float),
        grids: wp.array(dtype=VoxelGrid),
        mgrids: wp.array(dtype=MajorantGrid),
        majorants: wp.array(dtype=float),
        grid_count: int,
        details: wp.array(dtype=MediumDetail),
        origin: wp.vec3,
        direction: wp.vec3,
        t_max: float,
        air: Air,
        state: wp.uint32,
    ) -> Transmittance:
        """Unbiased transmittance estimate per channel along the segment (ratio tracking)."""
        out = Transmittance()
        tr = wp.vec3(1.0)
        t = float(0.0)
        steps = int(0)
        while t < t_max and steps < MAX_TRACKING_STEPS:
            seg = majorant_segment(grids, mgrids, majorants, grid_count, origin, direction, t, t_max, air)
            if seg.majorant <= 0.0:
                if seg.end >= t_max:
                    break
                t = wp.max(seg.end, t)
                steps += 1
                continue
            step = -wp.log(1.0 - wp.randf(state)) / seg.majorant
            steps += 1
            if t + step >= seg.end:
                t = seg.end
                continue
            t = t + step
            point = media_at(values, grids, grid_count, details, origin + t * direction, air)
            keep = wp.vec3(1.0) - point.extinction / seg.majorant
            tr = wp.cw_mul(tr, wp.vec3(wp.max(keep[0], 0.0), wp.max(keep[1], 0.0), wp.max(keep[2], 0.0)))
            if wp.max(tr) < 1.0e-3:
                # Russian roulette on a nearly opaque segment keeps the estimate unbiased and the cost bounded
                if wp.randf(state) < 0.5:
                    tr = wp.vec3(0.0)
                    break
                tr = tr * 2.0
        out.value = tr
        out.steps = steps
        out.state = state
        return out

    return media_at, delta_track, ratio_track


@wp.func
def table_pdf(cdf: wp.array(dtype=float), row: int, theta: float) -> float:
    """Density per steradian with which :func:`sample_table` returns ``theta`` from row ``row``."""
    node = grid_node(theta)
    i = int(node[0])
    base = row * GRID_SIZE
    total = cdf[base + GRID_SIZE - 1]
    mass = cdf[base + i + 1] - cdf[base + i]
    width = grid_angle(i + 1) - grid_angle(i)
    return mass / total / width / (2.0 * wp.pi * wp.max(wp.sin(theta), 1.0e-12))


@wp.func
def hg_sample_cos(g: float, u: float) -> float:
    """cos θ of a Henyey–Greenstein sample (exact inversion; isotropic for |g| < 1e-4)."""
    if wp.abs(g) < 1.0e-4:
        return 1.0 - 2.0 * u
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return wp.clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


@wp.func
def model_pdf(cdf: wp.array(dtype=float), kind: int, g: float, theta: float) -> float:
    """Sampling density [1/sr] of one medium's phase sampling at ``theta``."""
    if kind >= 3:
        return table_pdf(cdf, (kind - 3) * 3 + 1, theta)  # tables are sampled by their green channel
    if kind == 1:
        return phase_eval(kind, g, wp.cos(theta))
    return INV_4PI  # isotropic; Rayleigh is sampled uniformly too and weighted by p / pdf


@wp.func
def rotate_about(d: wp.vec3, cos_theta: float, phi: float) -> wp.vec3:
    """The direction at angle acos(cos_theta) from unit ``d`` with azimuth ``phi``."""
    helper = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(d[0]) > 0.9:
        helper = wp.vec3(0.0, 1.0, 0.0)
    u = wp.normalize(wp.cross(helper, d))
    v = wp.cross(d, u)
    sin_theta = wp.sqrt(wp.max(1.0 - cos_theta * cos_theta, 0.0))
    return wp.normalize(d * cos_theta + (u * wp.cos(phi) + v * wp.sin(phi)) * sin_theta)


@wp.struct
class PhaseSample:
    direction: wp.vec3
    weight: wp.vec3  # combined phase / sampling pdf, per channel
    state: wp.uint32


@functools.cache
def path_trace_kernel(has_ground: bool, has_tables: bool, has_detail: bool = False) -> wp.Kernel:
    """The per-pixel progressive path tracer, specialised on ground, tabulated species and animated detail."""

    media_at, delta_track, ratio_track = tracking_functions(has_detail)

    @wp.func
    def density(values: wp.array(dtype=float), grids: wp.array(dtype=VoxelGrid),
                details: wp.array(dtype=MediumDetail), m: int, p: wp.vec3) -> float:
        """Medium ``m``'s field value at ``p`` (with its animated detail when the kernel has any)."""
        grid = grids[m]
        value = grid_value(values, grid, grid.eye_index + grid.index_from_world * p)
        if wp.static(has_detail):
            value = detailed_value(value, details, m, p)
        return value

    @wp.func
    def combined_phase_at(
        values: wp.array(dtype=float),
        grids: wp.array(dtype=VoxelGrid),
        grid_count: int,
        details: wp.array(dtype=MediumDetail),
        tables: wp.array(dtype=float),
        p: wp.vec3,
        theta: float,
        air: Air,
    ) -> wp.vec3:
        """Riley Eq. 6: the scattering-weighted phase of all media (and the air) at ``p`` [1/sr]."""
        num = wp.vec3(0.0)
        den = wp.vec3(0.0)
        if air.enabled != 0:
            s_air = air_coefficient(air, p[1])
            num = s_air * phase_rayleigh(wp.cos(theta))
            den = s_air
        for m in range(grid_count):
            grid = grids[m]
            value = density(values, grids, details, m, p)
            if value > 0.0:
                phase = wp.vec3(0.0)
                if wp.static(has_tables):
                    phase = medium_phase(tables, grid.phase_kind, grid.phase_g, theta)
                else:
                    phase = wp.vec3(phase_eval(grid.phase_kind, grid.phase_g, wp.cos(theta)))
                s = grid.scattering * value
                num += wp.cw_mul(s, phase)
                den += s
        out = wp.vec3(0.0)
        for c in range(3):
            if den[c] > 0.0:
                out[c] = num[c] / den[c]
        return out

    @wp.func
    def sample_phase(
        values: wp.array(dtype=float),
        grids: wp.array(dtype=VoxelGrid),
        grid_count: int,
        details: wp.array(dtype=MediumDetail),
        tables: wp.array(dtype=float),
        cdf: wp.array(dtype=float),
        p: wp.vec3,
        d: wp.vec3,
        air: Air,
        state: wp.uint32,
    ) -> PhaseSample:
        """Pick the air or a medium by mean scattering, sample its phase (air: uniformly), and weight by the
        mixture's phase over the mixture pdf."""
        air_w = float(0.0)
        if air.enabled != 0:
            air_w = mean3(air_coefficient(air, p[1]))
        total = air_w
        for m in range(grid_count):
            grid = grids[m]
            total += mean3(grid.scattering) * density(values, grids, details, m, p)
        target = wp.randf(state) * total
        use_air = target < air_w or grid_count == 0
        chosen = int(0)
        running = air_w
        for m in range(grid_count):
            grid = grids[m]
            running += mean3(grid.scattering) * density(values, grids, details, m, p)
            if running < target:
                chosen = m + 1
        chosen = wp.clamp(chosen, 0, wp.max(grid_count - 1, 0))
        u = wp.randf(state)
        cos_theta = 1.0 - 2.0 * u
        if not use_air:
            grid = grids[chosen]
            if grid.phase_kind >= 3:
                if wp.static(has_tables):
                    cos_theta = wp.cos(sample_table(cdf, (grid.phase_kind - 3) * 3 + 1, u)[0])
            elif grid.phase_kind == 1:
                cos_theta = hg_sample_cos(grid.phase_g, u)
        theta = wp.acos(wp.clamp(cos_theta, -1.0, 1.0))
        out = PhaseSample()
        out.direction = rotate_about(d, cos_theta, 2.0 * wp.pi * wp.randf(state))
        theta = wp.atan2(wp.length(wp.cross(d, out.direction)), wp.dot(d, out.direction))
        pdf = air_w * INV_4PI
        for m in range(grid_count):
            g2 = grids[m]
            w = mean3(g2.scattering) * density(values, grids, details, m, p)
            if w > 0.0:
                if wp.static(has_tables):
                    pdf += w * model_pdf(cdf, g2.phase_kind, g2.phase_g, theta)
                else:
                    pdf += w * model_pdf(cdf, wp.min(g2.phase_kind, 2), g2.phase_g, theta)
        pdf = pdf / wp.max(total, 1.0e-30)
        out.state = state
        out.weight = wp.vec3(0.0)
        if pdf > 0.0:
            out.weight = combined_phase_at(values, grids, grid_count, details, tables, p, theta, air) / pdf
        return out

    @wp.kernel(module="unique")
    def path_trace(
        media: VoxelMedia,
        majorant_data: Majorants,
        phase_tables: PhaseTables,
        air: Air,
        sun: Sun,
        cam: PinholeCamera,
        ground: Ground,
        settings: PathSettings,
        sums: PixelSums,
        row_offset: int,
    ):
        values = media.values
        grids = media.grids
        grid_count = media.count
        details = media.details
        mgrids = majorant_data.grids
        majorants = majorant_data.values
        tables = phase_tables.values
        cdf = phase_tables.cdf
        sun_cos_radius = sun.cos_radius
        sun_solid_angle = sun.solid_angle
        sun_dir = sun.direction
        sun_irradiance = sun.irradiance
        environment = settings.environment
        ground_offset = ground.offset
        ground_albedo = ground.albedo
        seed = settings.seed
        pixel_jitter = settings.pixel_jitter
        first_sample = settings.first_sample
        sample_count = settings.sample_count
        max_bounces = settings.max_bounces
        radiance_sum = sums.radiance_sum
        radiance_sq = sums.radiance_sq
        transmittance_sum = sums.transmittance_sum
        depth_sum = sums.depth_sum
        counters = sums.counters
        r, col = wp.tid()
        row = r + row_offset
        view = camera_ray(cam, row, col)
        axis = wp.vec3(-cam.rotation[0, 2], -cam.rotation[1, 2], -cam.rotation[2, 2])
        cos_axis = wp.dot(view, axis)
        t_near = cam.near / cos_axis
        t_far = cam.far / cos_axis
        lit = wp.max(sun_irradiance) > 0.0
        sun_up = bool(True)
        if wp.static(has_ground):
            sun_up = sun_dir[1] > 0.0
        if air.enabled != 0:
            sun_up = sun_dir[1] > 0.0  # a flat earth's air hides a sun below the horizon
        pixel = row * cam.width + col
        # Warp passes a random state to a function by value, so each function hands back its advanced state and
        # the path carries one stream (re-seeding from the stream would replay it: rand_init(randi(s)) is s's next).
        steps = int(0)
        capped = int(0)
        centre = view
        for s in range(sample_count):
            state = wp.rand_init(seed + (first_sample + s) * 9973, pixel)
            view = centre
            if pixel_jitter != 0:
                # a box-filtered pixel, as Mitsuba and pbrt sample it (used by the Mitsuba cross-check)
                view = camera_ray_at(cam, row, col, wp.randf(state), wp.randf(state))
                cos_axis = wp.dot(view, axis)
                t_near = cam.near / cos_axis
                t_far = cam.far / cos_axis
            # primary transmittance (the layer's transmittance AOV) by ratio tracking, 0 where the ground is hit
            origin = view * t_near
            t_end = t_far - t_near
            hits_ground = bool(False)
            sea_floor = bool(False)
            if air.enabled != 0 and view[1] < 0.0:
                t_sea = wp.max(air.camera_altitude + origin[1], 0.0) / (-view[1])
                if t_sea < t_end:
                    t_end = t_sea
                    sea_floor = True
            if wp.static(has_ground):
                if view[1] < 0.0 and origin[1] > ground_offset:
                    tg = (ground_offset - origin[1]) / view[1]
                    if tg < t_end:
                        t_end = tg
                        hits_ground = True
                        sea_floor = False
            if not hits_ground and not sea_floor:
                tr = ratio_track(values, grids, mgrids, majorants, grid_count, details, origin, view, t_end, air, state)
                state = tr.state
                transmittance_sum[row, col] = transmittance_sum[row, col] + tr.value
                steps += tr.steps
            # the path
            radiance = wp.vec3(0.0)
            throughput = wp.vec3(1.0)
            d = view
            bounce = int(0)
            alive = bool(True)
            while alive:
                if bounce >= max_bounces:
                    capped += 1
                    break
                t_max = t_end
                on_ground = bool(False)
                if bounce > 0:
                    t_max = float(1.0e30)
                    if wp.static(has_ground):
                        if d[1] < 0.0 and origin[1] > ground_offset:
                            t_max = (ground_offset - origin[1]) / d[1]
                            on_ground = True
                else:
                    on_ground = hits_ground
                if air.enabled != 0 and d[1] < 0.0:
                    t_sea = wp.max(air.camera_altitude + origin[1], 0.0) / (-d[1])
                    if t_sea < t_max:
                        t_max = t_sea  # the air ends at a black sea level (no ground plane above it here)
                        on_ground = False
                        if bounce == 0:
                            sea_floor = True
                flight = delta_track(values, grids, mgrids, majorants, grid_count, details, origin, d, t_max, air,
                                     throughput, state)
                state = flight.state
                steps += flight.steps
                throughput = wp.cw_mul(throughput, flight.weight)
                if flight.scattered == 0 and not on_ground:
                    if air.enabled != 0 and d[1] < 0.0:
                        break  # reached the black sea level
                    if bounce > 0:
                        radiance += wp.cw_mul(throughput, environment)
                    elif air.enabled != 0 and lit and sun_up and wp.dot(d, sun_dir) >= sun_cos_radius:
                        # with air the path tracer draws the sun's disk itself (the sky pass is not used)
                        radiance += wp.cw_mul(throughput, sun_irradiance) / sun_solid_angle
                    break
                p = origin + flight.t * d
                if bounce == 0:
                    depth_sum[row, col] = depth_sum[row, col] + wp.vec2((t_near + flight.t) * cos_axis, 1.0)
                if flight.scattered == 1:
                    # next-event estimation toward the sun
                    if lit and sun_up:
                        t_sun = float(1.0e30)
                        tr_sun = ratio_track(values, grids, mgrids, majorants, grid_count, details, p, sun_dir,
                                             t_sun, air, state)
                        state = tr_sun.state
                        steps += tr_sun.steps
                        phase = combined_phase_at(values, grids, grid_count, details, tables, p,
                                                  wp.atan2(wp.length(wp.cross(sun_dir, d)), wp.dot(sun_dir, d)), air)
                        radiance += wp.cw_mul(wp.cw_mul(throughput, phase),
                                              wp.cw_mul(sun_irradiance, tr_sun.value))
                    ps = sample_phase(values, grids, grid_count, details, tables, cdf, p, d, air, state)
                    state = ps.state
                    throughput = wp.cw_mul(throughput, ps.weight)
                    d = ps.direction
                    origin = p
                else:
                    # Lambertian ground: sun through the media, then a cosine-weighted bounce
                    p = wp.vec3(p[0], ground_offset, p[2])
                    if wp.static(has_ground):
                        if lit and sun_up:
                            tr_sun = ratio_track(values, grids, mgrids, majorants, grid_count, details, p, sun_dir,
                                                 float(1.0e30), air, state)
                            state = tr_sun.state
                            steps += tr_sun.steps
                            lit_ground = wp.cw_mul(sun_irradiance, tr_sun.value)
                            radiance += wp.cw_mul(wp.cw_mul(throughput, ground_albedo), lit_ground) * (
                                sun_dir[1] / wp.pi
                            )
                        throughput = wp.cw_mul(throughput, ground_albedo)
                        u1 = wp.randf(state)
                        phi = 2.0 * wp.pi * wp.randf(state)
                        rr = wp.sqrt(u1)
                        d = wp.vec3(rr * wp.cos(phi), wp.sqrt(wp.max(1.0 - u1, 0.0)), rr * wp.sin(phi))
                        origin = p + wp.vec3(0.0, 1.0e-4, 0.0)
                bounce += 1
                # Russian roulette once a path is a few bounces deep
                if bounce >= 3:
                    q = wp.min(wp.max(throughput), 1.0)
                    if q <= 0.0:
                        alive = False
                    elif q < 1.0:
                        if wp.randf(state) < q:
                            throughput = throughput / q
                        else:
                            alive = False
            radiance_sum[row, col] = radiance_sum[row, col] + radiance
            radiance_sq[row, col] = radiance_sq[row, col] + wp.cw_mul(radiance, radiance)
        counters[row, col] = counters[row, col] + wp.vec2i(steps, capped)

    return path_trace
