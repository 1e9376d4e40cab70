"""Per-pixel rendering of a stratiform layer over a textured ground (Bouthors 2006 §4.6, §6).

From below, the ray meets the flat cloud base (the paper's textured quad); from above, it is marched against the
height field top = base + thickness(x, z) and refined by bisection, with the local normal from the map's gradient
for orders 1-2. Radiance: I C_sun + T_ms C_sky + R_ms C_ground (below) or I^r C_sun + R_ms C_sky + T_ms C_ground
(above), with C_ground = R_C / π the cloud base's received radiosity, C_sky the uniform-equivalent sky radiance.
The ground, seen through the cloud's transmittance τ(H_v), is ρ_G (S_G^d + R_G) / π with S_G^d the sun through
T_C = T_0 + T_1 + T_2 at the h tan θ_l parallax point (full resolution) and R_G the radiosity buffer.
Positions are camera-relative metres.
"""

from __future__ import annotations

import warp as wp

from warpsky.camera_rays import PinholeCamera, primary_ray
from warpsky.light.sun import Sun
from warpsky.passes.stratiform.radiosity_kernels import bilinear
from warpsky.passes.stratiform.slab import INV_PI, MU_MIN, SlabOptics, order_energies, slab_radiance
from warpsky.surfaces.plane import Ground

MARCH_STEPS = wp.constant(64)


@wp.struct
class LayerGeometry:
    """A thickness map over [x0, x0 + sx] x [z0, z0 + sz] (camera-relative), base at y = base."""

    base: float
    x0: float
    z0: float
    sx: float
    sz: float
    top: float  # base + max thickness


@wp.func
def map_coord(x: float, origin: float, size: float, n: int) -> float:
    """Continuous texel coordinate (centres at integers) of world coordinate x on an n-texel axis."""
    return (x - origin) / size * float(n) - 0.5


@wp.func
def thickness_at(thickness: wp.array2d(dtype=float), g: LayerGeometry, x: float, z: float) -> float:
    """Thickness [m] at camera-relative (x, z) from a :func:`~warpsky.media.stratiform.signed_thickness` map:
    bilinear between texel centres, clamped at 0 (a hole's edge lies where the signed values cross 0), the edge
    texels' values out to the map's border and 0 beyond it."""
    if x < g.x0 or z < g.z0 or x > g.x0 + g.sx or z > g.z0 + g.sz:
        return 0.0
    nu = thickness.shape[0]
    nv = thickness.shape[1]
    u = wp.clamp(map_coord(x, g.x0, g.sx, nu), 0.0, float(nu - 1))
    v = wp.clamp(map_coord(z, g.z0, g.sz, nv), 0.0, float(nv - 1))
    i0 = wp.min(int(u), nu - 2)
    j0 = wp.min(int(v), nv - 2)
    fu = u - float(i0)
    fv = v - float(j0)
    return wp.max((thickness[i0, j0] * (1.0 - fu) + thickness[i0 + 1, j0] * fu) * (1.0 - fv) + (
        thickness[i0, j0 + 1] * (1.0 - fu) + thickness[i0 + 1, j0 + 1] * fu) * fv, 0.0)


@wp.func
def grid_lookup(buffer: wp.array2d(dtype=wp.vec3), x: float, z: float, x0: float, z0: float, sx: float,
                sz: float) -> wp.vec3:
    return bilinear(buffer, map_coord(x, x0, sx, buffer.shape[0]), map_coord(z, z0, sz, buffer.shape[1]))


@wp.kernel
def stratiform_kernel(
    cam: PinholeCamera,
    thickness: wp.array2d(dtype=float),
    geometry: LayerGeometry,
    tables: wp.array(dtype=float),
    params: wp.array(dtype=float),
    optics: SlabOptics,
    sun_light: Sun,
    sky_radiance: wp.vec3,
    has_ground: int,
    ground: Ground,
    albedo: wp.array2d(dtype=wp.vec3),
    albedo_box: wp.vec4,  # x0, z0, sx, sz of the albedo map
    radiosity_g: wp.array2d(dtype=wp.vec3),
    radiosity_c: wp.array2d(dtype=wp.vec3),
    grid_box: wp.vec4,  # x0, z0, sx, sz of the radiosity buffers
    radiance: wp.array2d(dtype=wp.vec3),
    transmittance: wp.array2d(dtype=wp.vec3),
    depth: wp.array2d(dtype=float),
    row_offset: int,
):
    r, col = wp.tid()
    row = r + row_offset
    ray = primary_ray(cam, row, col, 0.5, 0.5)
    d = ray.direction
    o = ray.origin  # the ray is o + t d
    cos_axis = ray.cos_axis
    sun = sun_light.direction
    sun_irradiance = sun_light.irradiance
    ground_y = ground.offset
    out = wp.vec3(0.0)
    tr = wp.vec3(1.0)
    z_depth = cam.far
    lit = sun_light.lit != 0  # the horizon is folded into sun_light on the host
    kappa_ref_s = optics.kappa_s[1] / optics.to_reference
    mu_sun = wp.max(sun[1], MU_MIN)
    # ---- the cloud layer
    t_hit = float(-1.0)
    h = float(0.0)
    normal = wp.vec3(0.0, -1.0, 0.0)
    below = geometry.base > o[1]
    if below and d[1] > 0.0:
        t_hit = (geometry.base - o[1]) / d[1]
        p = o + t_hit * d
        h = thickness_at(thickness, geometry, p[0], p[2])
    elif (not below) and d[1] < 0.0:
        # march from the top plane (or the camera) down to the base plane
        t0 = wp.max((geometry.top - o[1]) / d[1], 0.0)
        t1 = (geometry.base - o[1]) / d[1]
        if geometry.top > o[1]:
            t0 = 0.0
        dt = (t1 - t0) / float(MARCH_STEPS)
        prev = t0
        for step in range(MARCH_STEPS):
            t = t0 + float(step + 1) * dt
            p = o + t * d
            if t_hit < 0.0 and p[1] <= geometry.base + thickness_at(thickness, geometry, p[0], p[2]) + 1.0e-3:
                lo = prev
                hi = t
                for _ in range(6):
                    mid = 0.5 * (lo + hi)
                    q = o + mid * d
                    if q[1] <= geometry.base + thickness_at(thickness, geometry, q[0], q[2]):
                        hi = mid
                    else:
                        lo = mid
                t_hit = hi
            prev = t
        if t_hit >= 0.0:
            p = o + t_hit * d
            h = thickness_at(thickness, geometry, p[0], p[2])
            eps = 0.5 * wp.min(geometry.sx / float(thickness.shape[0]), geometry.sz / float(thickness.shape[1]))
            gx = (thickness_at(thickness, geometry, p[0] + eps, p[2]) - thickness_at(thickness, geometry, p[0] - eps,
                                                                                 p[2])) / (2.0 * eps)
            gz = (thickness_at(thickness, geometry, p[0], p[2] + eps) - thickness_at(thickness, geometry, p[0],
                                                                                 p[2] - eps)) / (2.0 * eps)
            normal = wp.normalize(wp.vec3(-gx, 1.0, -gz))
    if t_hit >= 0.0 and h > 0.0:
        p = o + t_hit * d
        shade = slab_radiance(tables, params, optics, h, normal, sun, d)
        mu_v = wp.max(wp.abs(d[1]), MU_MIN)
        e = order_energies(params, h * optics.to_reference, mu_sun, kappa_ref_s)
        t_ms = e.t_ms
        r_ms = 1.0 - t_ms
        unscattered = wp.exp(-optics.kappa * h / mu_v)
        # T_ms counts the unscattered light too, which reaches the eye from behind the layer through its
        # transmittance; only the scattered rest is added here, so a thinning edge fades into what lies behind
        t_scattered = wp.max(t_ms - unscattered, 0.0)
        c_ground = grid_lookup(radiosity_c, p[0], p[2], grid_box[0], grid_box[1], grid_box[2], grid_box[3]) * INV_PI
        sun_part = wp.vec3(0.0)
        if lit:
            sun_part = wp.cw_mul(shade.i0 + shade.i1 + shade.i2 + shade.i3, sun_irradiance)
        if below:
            out = sun_part + sky_radiance * t_scattered + c_ground * r_ms
        else:
            out = sun_part + sky_radiance * r_ms + c_ground * t_scattered
        tr = wp.vec3(unscattered)
        z_depth = t_hit * cos_axis
    # ---- the ground, seen through the cloud
    if has_ground != 0 and d[1] < 0.0 and ground_y < o[1]:
        t_g = (ground_y - o[1]) / d[1]
        if t_g * cos_axis < cam.far:
            q = o + t_g * d
            rho = grid_lookup(albedo, q[0], q[2], albedo_box[0], albedo_box[1], albedo_box[2], albedo_box[3])
            direct = wp.vec3(0.0)
            if lit:
                # the sun ray from q crosses the cloud base h tan θ_l towards the sun
                c = q + sun * ((geometry.base - q[1]) / mu_sun)
                hc = thickness_at(thickness, geometry, c[0], c[2])
                ec = order_energies(params, hc * optics.to_reference, mu_sun, kappa_ref_s)
                direct = sun_irradiance * (mu_sun * (ec.t0 + ec.t1 + ec.t2))
            received = grid_lookup(radiosity_g, q[0], q[2], grid_box[0], grid_box[1], grid_box[2], grid_box[3])
            out += wp.cw_mul(tr, wp.cw_mul(rho, direct + received) * INV_PI)
            tr = wp.vec3(0.0)
            if z_depth >= cam.far:
                z_depth = t_g * cos_axis
    radiance[row, col] = out
    transmittance[row, col] = tr
    depth[row, col] = z_depth
