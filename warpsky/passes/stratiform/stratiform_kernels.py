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

from warpsky.light.sun import Sun
from warpsky.model.camera_rays import PinholeCamera, primary_ray
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
    """Thickness [m] at camera-relative (x, z) from a :func:`~warpsky.media.stratiform.thickness.signed_thickness` map:
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


@wp.struct
class LayerHit:
    """Where an eye ray meets the layer."""

    t: float  # [m] along the ray; < 0: it misses the layer
    thickness: float  # the layer's thickness there [m]
    normal: wp.vec3  # the surface's normal there (the base's, facing down, from below)
    below: int  # 1: the ray starts below the cloud base


@wp.func
def top_crossing(thickness: wp.array2d(dtype=float), g: LayerGeometry, o: wp.vec3, d: wp.vec3) -> float:
    """First t [m] at which the descending ray ``o + t d``, started above the base, reaches the top surface
    base + thickness(x, z): marched in MARCH_STEPS steps from the top plane (or the eye) down to the base plane and
    refined by 6 bisections; -1 when it does not."""
    t_hit = float(-1.0)
    t0 = wp.max((g.top - o[1]) / d[1], 0.0)
    t1 = (g.base - o[1]) / d[1]
    if g.top > o[1]:
        t0 = 0.0
    dt = (t1 - t0) / float(MARCH_STEPS)
    prev = t0
    for step in range(MARCH_STEPS):
        t = t0 + float(step + 1) * dt
        p = o + t * d
        if t_hit < 0.0 and p[1] <= g.base + thickness_at(thickness, g, p[0], p[2]) + 1.0e-3:
            lo = prev
            hi = t
            for _ in range(6):
                mid = 0.5 * (lo + hi)
                q = o + mid * d
                if q[1] <= g.base + thickness_at(thickness, g, q[0], q[2]):
                    hi = mid
                else:
                    lo = mid
            t_hit = hi
        prev = t
    return t_hit


@wp.func
def top_normal(thickness: wp.array2d(dtype=float), g: LayerGeometry, p: wp.vec3) -> wp.vec3:
    """Unit normal of the top surface at ``p`` from the thickness map's central differences half a texel apart."""
    eps = 0.5 * wp.min(g.sx / float(thickness.shape[0]), g.sz / float(thickness.shape[1]))
    gx = (thickness_at(thickness, g, p[0] + eps, p[2]) - thickness_at(thickness, g, p[0] - eps, p[2])) / (2.0 * eps)
    gz = (thickness_at(thickness, g, p[0], p[2] + eps) - thickness_at(thickness, g, p[0], p[2] - eps)) / (2.0 * eps)
    return wp.normalize(wp.vec3(-gx, 1.0, -gz))


@wp.func
def layer_hit(thickness: wp.array2d(dtype=float), g: LayerGeometry, o: wp.vec3, d: wp.vec3) -> LayerHit:
    """Where the eye ray ``o + t d`` meets the layer: from below the flat base, from above the top surface."""
    out = LayerHit()
    out.t = -1.0
    out.thickness = 0.0
    out.normal = wp.vec3(0.0, -1.0, 0.0)
    out.below = wp.where(g.base > o[1], 1, 0)
    if out.below != 0 and d[1] > 0.0:
        out.t = (g.base - o[1]) / d[1]
        p = o + out.t * d
        out.thickness = thickness_at(thickness, g, p[0], p[2])
    elif out.below == 0 and d[1] < 0.0:
        out.t = top_crossing(thickness, g, o, d)
        if out.t >= 0.0:
            p = o + out.t * d
            out.thickness = thickness_at(thickness, g, p[0], p[2])
            out.normal = top_normal(thickness, g, p)
    return out


@wp.func
def layer_radiance(tables: wp.array(dtype=float), params: wp.array(dtype=float), optics: SlabOptics, sun_light: Sun,
                   sky_radiance: wp.vec3, radiosity_c: wp.array2d(dtype=wp.vec3), grid_box: wp.vec4, hit: LayerHit,
                   o: wp.vec3, d: wp.vec3):
    """(radiance the layer sends along -d at ``hit``, its unscattered transmittance along d): the sun's orders,
    the sky through the layer (below) or reflected (above), and the ground's radiosity reflected (below) or
    through the layer (above)."""
    p = o + hit.t * d
    sun = sun_light.direction
    h = hit.thickness
    kappa_ref_s = optics.kappa_s[1] / optics.to_reference
    mu_sun = wp.max(sun[1], MU_MIN)
    shade = slab_radiance(tables, params, optics, h, hit.normal, sun, d)
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
    if sun_light.lit != 0:  # the horizon is folded into sun_light on the host
        sun_part = wp.cw_mul(shade.i0 + shade.i1 + shade.i2 + shade.i3, sun_light.irradiance)
    if hit.below != 0:
        return sun_part + sky_radiance * t_scattered + c_ground * r_ms, unscattered
    return sun_part + sky_radiance * r_ms + c_ground * t_scattered, unscattered


@wp.func
def ground_radiance(thickness: wp.array2d(dtype=float), geometry: LayerGeometry, params: wp.array(dtype=float),
                    optics: SlabOptics, sun_light: Sun, albedo: wp.array2d(dtype=wp.vec3), albedo_box: wp.vec4,
                    radiosity_g: wp.array2d(dtype=wp.vec3), grid_box: wp.vec4, q: wp.vec3) -> wp.vec3:
    """Radiance of the ground at ``q``, rho (S_G^d + R_G) / pi: the sun through the layer's unscattered and first
    two orders where its ray crosses the cloud base, and the ground's received radiosity."""
    sun = sun_light.direction
    mu_sun = wp.max(sun[1], MU_MIN)
    rho = grid_lookup(albedo, q[0], q[2], albedo_box[0], albedo_box[1], albedo_box[2], albedo_box[3])
    direct = wp.vec3(0.0)
    if sun_light.lit != 0:
        # the sun ray from q crosses the cloud base h tan θ_l towards the sun
        c = q + sun * ((geometry.base - q[1]) / mu_sun)
        hc = thickness_at(thickness, geometry, c[0], c[2])
        ec = order_energies(params, hc * optics.to_reference, mu_sun, optics.kappa_s[1] / optics.to_reference)
        direct = sun_light.irradiance * (mu_sun * (ec.t0 + ec.t1 + ec.t2))
    received = grid_lookup(radiosity_g, q[0], q[2], grid_box[0], grid_box[1], grid_box[2], grid_box[3])
    return wp.cw_mul(rho, direct + received) * INV_PI


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
    out = wp.vec3(0.0)
    tr = wp.vec3(1.0)
    z_depth = cam.far
    hit = layer_hit(thickness, geometry, o, d)
    if hit.t >= 0.0 and hit.thickness > 0.0:
        shown, unscattered = layer_radiance(tables, params, optics, sun_light, sky_radiance, radiosity_c, grid_box,
                                            hit, o, d)
        out = shown
        tr = wp.vec3(unscattered)
        z_depth = hit.t * ray.cos_axis
    # the ground, seen through the cloud
    if has_ground != 0 and d[1] < 0.0 and ground.offset < o[1]:
        t_g = (ground.offset - o[1]) / d[1]
        if t_g * ray.cos_axis < cam.far:
            out += wp.cw_mul(tr, ground_radiance(thickness, geometry, params, optics, sun_light, albedo, albedo_box,
                                                 radiosity_g, grid_box, o + t_g * d))
            tr = wp.vec3(0.0)
            if z_depth >= cam.far:
                z_depth = t_g * ray.cos_axis
    radiance[row, col] = out
    transmittance[row, col] = tr
    depth[row, col] = z_depth
