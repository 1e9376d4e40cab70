"""The sky pass on a round earth: per pixel the air in front of the media and behind them, and the sun's disk, from
the ray integrals of :mod:`~warpsky.media.air.round_earth_light`.

For a pinhole camera every ray starts at the eye, so a frame's view table holds the whole rays' integrals against
the view's elevation sine and its azimuth from the sun (the phase functions factor out); a pixel without media
costs one lookup, a pixel with media one integral of the air in front of them (the air behind is the whole ray's
less the front's, seen through it).
"""

from __future__ import annotations

import warp as wp

from warpsky.core.numerics import exp3
from warpsky.light.sun import Sun
from warpsky.media.air.analytic import AnalyticAir
from warpsky.media.air.round_earth_kernels import (
    RoundAir,
    altitude_at,
    floor_distance,
    make_line,
    table_depth,
    top_distance,
)
from warpsky.media.air.round_earth_light import RoundLight, RoundMultiple, SunGeometry, round_light
from warpsky.model.camera_rays import PinholeCamera, primary_ray
from warpsky.optics.phase import phase_hg, phase_rayleigh


@wp.struct
class RoundView:
    """The frame's view table (``count`` 0: none, integrate every ray)."""

    count: int
    table: wp.array3d(dtype=wp.vec3)  # (elevations, azimuths, 4): S_R, S_M, M, optical depth of the whole ray


@wp.struct
class RoundRay:
    """One camera ray's stretch of air on a round earth."""

    altitude: float  # of its start [m above sea level]
    mu: float  # its elevation sine
    t_end: float  # [m] to the floor or the top of the air
    split: float  # [m] to the media's representative depth, at most t_end
    hits_floor: int


@wp.func
def sun_geometry(sun: Sun, view: wp.vec3, sun_radius: float) -> SunGeometry:
    """The sun as the ray along ``view`` from the eye sees it (the eye's vertical is +y)."""
    out = SunGeometry()
    out.mu_s0 = sun.disk_direction[1]
    out.nu = wp.dot(sun.disk_direction, view)
    out.radius = sun_radius
    return out


@wp.func
def round_ray(air: AnalyticAir, ra: RoundAir, cam: PinholeCamera, origin_y: float, view: wp.vec3, cos_axis: float,
              media_depth: float) -> RoundRay:
    """The air along a camera ray from camera-relative height ``origin_y`` along ``view``, split at the media's
    depth ``media_depth`` along the view axis (the far plane or beyond: no media)."""
    out = RoundRay()
    out.altitude = air.camera_altitude + origin_y
    out.mu = view[1]
    out.t_end = floor_distance(ra, out.altitude, out.mu)
    out.hits_floor = int(out.t_end >= 0.0)
    if out.t_end < 0.0:
        out.t_end = top_distance(ra, out.altitude, out.mu)
    out.split = out.t_end
    if media_depth < cam.far:
        out.split = wp.min(media_depth / cos_axis, out.t_end)
    return out


@wp.func
def view_coordinates(view: wp.vec3, sun: wp.vec3, elevations: int, azimuths: int) -> wp.vec2:
    """Fractional (row, column) of ``view`` in the view table: rows uniform in sign(mu) sqrt(|mu|), columns in the
    azimuth from the sun's on [0, pi]."""
    mu = view[1]
    v = wp.sign(mu) * wp.sqrt(wp.abs(mu))
    row = wp.clamp(0.5 * (v + 1.0), 0.0, 1.0) * float(elevations - 1)
    horizontal = wp.sqrt(view[0] * view[0] + view[2] * view[2])
    sun_h = wp.sqrt(sun[0] * sun[0] + sun[2] * sun[2])
    cos_az = float(1.0)
    if horizontal > 1.0e-7 and sun_h > 1.0e-7:
        cos_az = wp.clamp((view[0] * sun[0] + view[2] * sun[2]) / (horizontal * sun_h), -1.0, 1.0)
    column = wp.acos(cos_az) / wp.pi * float(azimuths - 1)
    return wp.vec2(row, column)


@wp.func
def view_lookup(view_table: RoundView, view: wp.vec3, sun: wp.vec3) -> RoundLight:
    """The view table's integrals over the whole camera ray along ``view``, bilinear."""
    n_e = view_table.table.shape[0]
    n_a = view_table.table.shape[1]
    x = view_coordinates(view, sun, n_e, n_a)
    i = wp.min(int(x[0]), n_e - 2)
    j = wp.min(int(x[1]), n_a - 2)
    a = x[0] - float(i)
    b = x[1] - float(j)
    values = RoundLight()
    for term in range(4):
        v = ((view_table.table[i, j, term] * (1.0 - b) + view_table.table[i, j + 1, term] * b) * (1.0 - a)
             + (view_table.table[i + 1, j, term] * (1.0 - b) + view_table.table[i + 1, j + 1, term] * b) * a)
        if term == 0:
            values.rayleigh = v
        elif term == 1:
            values.mie = v
        elif term == 2:
            values.multiple = v
        else:
            values.depth = v
    return values


@wp.kernel
def view_table_kernel(air: AnalyticAir, ra: RoundAir, ms: RoundMultiple, sun: Sun, sun_radius: float,
                      out: wp.array3d(dtype=wp.vec3), row_offset: int):
    """Entry (i, j): the whole ray from the eye at the elevation and azimuth whose coordinates are (i, j); the
    launch covers the rows from ``row_offset`` (:func:`~warpsky.core.device.launch_rows`)."""
    r, j = wp.tid()
    i = r + row_offset
    v = 2.0 * float(i) / float(out.shape[0] - 1) - 1.0
    mu = wp.sign(v) * v * v
    azimuth = wp.pi * float(j) / float(out.shape[1] - 1)
    s = sun.disk_direction
    sun_h = wp.sqrt(s[0] * s[0] + s[2] * s[2])
    ahead = wp.vec3(0.0, 0.0, -1.0)
    side = wp.vec3(1.0, 0.0, 0.0)
    if sun_h > 1.0e-7:
        ahead = wp.vec3(s[0] / sun_h, 0.0, s[2] / sun_h)
        side = wp.vec3(-ahead[2], 0.0, ahead[0])
    horizontal = wp.sqrt(wp.max(1.0 - mu * mu, 0.0))
    view = ahead * (horizontal * wp.cos(azimuth)) + side * (horizontal * wp.sin(azimuth)) + wp.vec3(0.0, mu, 0.0)
    h0 = air.camera_altitude
    distance = floor_distance(ra, h0, mu)
    if distance < 0.0:
        distance = top_distance(ra, h0, mu)
    light = round_light(air, ra, ms, h0, mu, sun_geometry(sun, view, sun_radius), distance)
    out[i, j, 0] = light.rayleigh
    out[i, j, 1] = light.mie
    out[i, j, 2] = light.multiple
    out[i, j, 3] = light.depth


@wp.func
def front_light(air: AnalyticAir, ra: RoundAir, ms: RoundMultiple, view_table: RoundView, along: RoundRay,
                view: wp.vec3, sun: Sun, sun_radius: float) -> RoundLight:
    """The integrals of the air in front of the media (to ``split``): the view table's for a whole ray, else the
    ray's own quadrature."""
    if view_table.count > 0 and along.split >= along.t_end:
        return view_lookup(view_table, view, sun.disk_direction)
    return round_light(air, ra, ms, along.altitude, along.mu, sun_geometry(sun, view, sun_radius), along.split)


@wp.func
def seen(light: RoundLight, sun: Sun, view: wp.vec3, mie_g: float) -> wp.vec3:
    """The radiance the integrals ``light`` send along ``view``."""
    cos_theta = wp.dot(sun.disk_direction, view)
    single = light.rayleigh * phase_rayleigh(cos_theta) + light.mie * phase_hg(cos_theta, mie_g)
    return wp.cw_mul(sun.irradiance, single + light.multiple)


@wp.kernel
def round_sky_kernel(
    cam: PinholeCamera,
    air: AnalyticAir,
    ra: RoundAir,
    ms: RoundMultiple,
    view_table: RoundView,
    sun: Sun,
    sun_radius: float,
    media_depth: wp.array2d(dtype=float),
    front_radiance: wp.array2d(dtype=wp.vec3),
    front_transmittance: wp.array2d(dtype=wp.vec3),
    back_radiance: wp.array2d(dtype=wp.vec3),
):
    row, col = wp.tid()
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    view = ray.direction
    along = round_ray(air, ra, cam, ray.origin[1], view, ray.cos_axis, media_depth[row, col])
    front = front_light(air, ra, ms, view_table, along, view, sun, sun_radius)
    t_front = exp3(front.depth)
    front_radiance[row, col] = seen(front, sun, view, air.mie_g)
    front_transmittance[row, col] = t_front
    back = wp.vec3(0.0)
    line = make_line(ra, along.altitude, along.mu)
    if along.split < along.t_end:
        if view_table.count > 0:
            whole = seen(view_lookup(view_table, view, sun.disk_direction), sun, view, air.mie_g)
            rest = whole - front_radiance[row, col]
            for c in range(3):
                if t_front[c] > 1.0e-30:
                    back[c] = wp.max(rest[c], 0.0) / t_front[c]
        else:
            h = altitude_at(line, along.split)
            r = ra.radius + h
            mu = wp.clamp((line.r0 * along.mu + along.split) / r, -1.0, 1.0)
            geometry = sun_geometry(sun, view, sun_radius)
            geometry.mu_s0 = wp.clamp((line.r0 * geometry.mu_s0 + along.split * geometry.nu) / r, -1.0, 1.0)
            rest_light = round_light(air, ra, ms, h, mu, geometry, along.t_end - along.split)
            back = seen(rest_light, sun, view, air.mie_g)
    # the sun's disk, behind everything, through the air beyond the split, where the ray leaves the air
    if along.hits_floor == 0 and wp.dot(sun.disk_direction, view) >= sun.cos_radius and sun.lit != 0:
        beyond = wp.vec3(1.0)
        if along.split < along.t_end:
            h = altitude_at(line, along.split)
            mu = wp.clamp((line.r0 * along.mu + along.split) / (ra.radius + h), -1.0, 1.0)
            beyond = exp3(table_depth(ra, h, mu))
        back += wp.cw_mul(sun.disk_radiance, beyond)
    back_radiance[row, col] = back
