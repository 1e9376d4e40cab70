"""Kernels of the single-scattering ray march (Riley et al. 2004's low-albedo comparison mode, their Fig. 13).

Per pixel, the eye ray is marched through the union of the media boxes in equal steps. Inside a step the
extinction is taken at the step's midpoint, and the total optical depth seen by light scattered there (sun to
sample plus sample to eye) is taken as linear between the step's ends, where shadow rays are marched. The
step's contribution is then integrated exactly (:func:`exp_lerp_mean`), which keeps a homogeneous medium exact
and any optical depth per step from 1e-9 to 1e5 finite and non-negative.

The sky lights the media as an environment on two spherical-harmonic bands per hemisphere
(:mod:`warpsky.light.skylight`: the dome, the analytic sky when the frame has a sky pass, the ground they light):
sigma_s S(v) per metre, S(v) = T_up max(0, m_up + 3 g M_up . v) + T_down max(0, m_down + 3 g M_down . v) with g
mixed over the media at the step's midpoint by scattering weight. T_up is the transmittance towards the zenith,
which a second shadow march per step takes at the step's midpoint; T_down, towards the nadir, a third, only when
the lower hemisphere holds light. The ground reflects albedo E / pi of the sky above it, occluded towards the
zenith. Light of the sky scattered more than once, and the sky's structure beyond the first band, are left out.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.camera_rays import PinholeCamera, primary_ray
from warpsky.kernel_variants import kernel_variants
from warpsky.light.dome import ambient_ground
from warpsky.light.skylight import SkyEnvironment, ambient_inscatter, ambient_lobes, mixed_asymmetry
from warpsky.light.sun import Sun
from warpsky.media.phase_mixture import oriented_correction_function, phase_sum_function
from warpsky.media.shadow import sun_depth_function
from warpsky.media.voxel import VoxelMedia, media_functions, media_span
from warpsky.numerics import exp3, exp_lerp_mean3, luminance
from warpsky.optics.kernels import medium_phase, scattering_angle
from warpsky.optics.oriented_phase import OrientedPhases
from warpsky.surfaces.plane import Ground

oriented_correction = oriented_correction_function(medium_phase)[0]


@wp.struct
class MarchSettings:
    """Step lengths and cut-off of the eye march."""

    step: float  # eye-ray step [m]
    shadow_step: float  # shadow-ray step towards the sun [m]
    min_transmittance: float  # stop once the luminance transmittance falls below this
    environment: SkyEnvironment  # the sky around the media (dome, analytic sky, ground) and the media's asymmetry
    ground_ambient: wp.vec3  # E / pi of the sky above the ground: what a white ground reflects, RGB
    ambient_on: int  # 1: light the media and the ground with them (a dome or sky light)


@kernel_variants(has_ground=(False, True), has_tables=(False, True), has_detail=(False, True))
@functools.cache
def single_scatter_kernel(has_ground: bool, has_tables: bool, has_detail: bool = False) -> wp.Kernel:
    """The per-pixel march, specialised on whether the scene has a ground plane, tabulated species and animated
    detail: a scene without them pays nothing for those branches. One loop over the eye steps, with the shadow
    marches and the step's exact integral inline: splitting it would pass the march state (optical depths, the
    reused shadow depth, depth moments, lookups) through every call."""

    sample_media = media_functions(has_detail)
    scattered_phase = phase_sum_function(has_tables)
    sun_optical_depth = sun_depth_function(has_detail)

    @wp.kernel(module="unique")
    def single_scatter(
        media: VoxelMedia,
        phase_tables: wp.array(dtype=float),
        oriented: OrientedPhases,
        cam: PinholeCamera,
        sun: Sun,
        ground: Ground,
        march: MarchSettings,
        radiance: wp.array2d(dtype=wp.vec3),
        transmittance: wp.array2d(dtype=wp.vec3),
        depth: wp.array2d(dtype=float),
        samples: wp.array2d(dtype=wp.int64),
        row_offset: int,
    ):
        r, col = wp.tid()
        row = r + row_offset
        ray = primary_ray(cam, row, col, 0.5, 0.5)
        view = ray.direction
        origin = ray.origin
        cos_axis = ray.cos_axis
        t_near = ray.t_near
        t_end = ray.t_far
        sun_dir = sun.direction
        lit = sun.lit != 0
        # Light travels along -sun_dir and leaves towards the eye along -view.
        theta = scattering_angle(sun_dir, view)
        hit_ground = bool(False)
        if wp.static(has_ground):
            # The plane is opaque: it ends the ray (the part of the sun below it is already out of sun.irradiance).
            if view[1] != 0.0:
                t_ground = (ground.offset - origin[1]) / view[1]
                if t_ground > t_near and t_ground < t_end:
                    t_end = t_ground
                    hit_ground = True

        lobes = ambient_lobes(march.environment, view)
        span = media_span(media, origin, view, t_near, t_end)
        t0 = span[0]
        t1 = span[1]
        light = wp.vec3(0.0)
        tau_eye = wp.vec3(0.0)
        depth_sum = float(0.0)
        weight_sum = float(0.0)
        lookups = wp.int64(0)
        if t1 > t0:
            count = wp.max(int(wp.ceil((t1 - t0) / march.step)), 1)
            dt = (t1 - t0) / float(count)
            tau_sun_a = wp.vec3(0.0)
            sun_a_known = bool(False)
            for i in range(count):
                ta = t0 + float(i) * dt
                tm = ta + 0.5 * dt
                here = sample_media(media, origin + tm * view)
                scatter = scattered_phase(media, here, phase_tables, wp.vec3(0.0), theta)
                if wp.static(has_tables):  # oriented crystals are ice, a tabulated species
                    scatter += oriented_correction(media, here, phase_tables, oriented, view, theta)
                lookups += wp.int64(media.count)
                tau_eye_b = tau_eye + here.extinction * dt
                if lit and wp.max(scatter) > 0.0:
                    if not sun_a_known:
                        shadow = sun_optical_depth(media, origin, ta, view, sun_dir, march.shadow_step)
                        tau_sun_a = wp.vec3(shadow[0], shadow[1], shadow[2])
                        lookups += wp.int64(shadow[3])
                    shadow = sun_optical_depth(media, origin, ta + dt, view, sun_dir, march.shadow_step)
                    tau_sun_b = wp.vec3(shadow[0], shadow[1], shadow[2])
                    lookups += wp.int64(shadow[3])
                    mean = exp_lerp_mean3(tau_eye + tau_sun_a, tau_eye_b + tau_sun_b)
                    light += wp.cw_mul(wp.cw_mul(scatter, sun.irradiance), mean) * dt
                    tau_sun_a = tau_sun_b
                    sun_a_known = True
                else:
                    sun_a_known = False
                if march.ambient_on != 0 and wp.max(here.scattering) > 0.0:
                    up = sun_optical_depth(media, origin, tm, view, wp.vec3(0.0, 1.0, 0.0), march.shadow_step)
                    lookups += wp.int64(up[3])
                    t_down = wp.vec3(0.0)
                    if march.environment.lower_lit != 0:
                        down = sun_optical_depth(media, origin, tm, view, wp.vec3(0.0, -1.0, 0.0), march.shadow_step)
                        lookups += wp.int64(down[3])
                        t_down = exp3(wp.vec3(down[0], down[1], down[2]))
                    g = mixed_asymmetry(media, here, march.environment.asymmetry)
                    sky = ambient_inscatter(lobes, g, exp3(wp.vec3(up[0], up[1], up[2])), t_down)
                    light += wp.cw_mul(wp.cw_mul(here.scattering, sky), exp_lerp_mean3(tau_eye, tau_eye_b)) * dt
                opacity = luminance(exp3(tau_eye)) - luminance(exp3(tau_eye_b))
                depth_sum += opacity * tm * cos_axis
                weight_sum += opacity
                tau_eye = tau_eye_b
                if luminance(exp3(tau_eye)) < march.min_transmittance:
                    break

        trans = exp3(tau_eye)
        if wp.static(has_ground):
            if hit_ground:
                if lit:
                    shadow = sun_optical_depth(media, origin, t_end, view, sun_dir, march.shadow_step)
                    lookups += wp.int64(shadow[3])
                    lit_ground = wp.cw_mul(ground.albedo, sun.irradiance) * (wp.max(sun_dir[1], 0.0) / wp.pi)
                    light += wp.cw_mul(wp.cw_mul(lit_ground, exp3(wp.vec3(shadow[0], shadow[1], shadow[2]))), trans)
                if march.ambient_on != 0:
                    up = sun_optical_depth(media, origin, t_end, view, wp.vec3(0.0, 1.0, 0.0), march.shadow_step)
                    lookups += wp.int64(up[3])
                    shown = ambient_ground(ground.albedo, march.ground_ambient, wp.vec3(up[0], up[1], up[2]))
                    light += wp.cw_mul(shown, trans)
                depth_sum += luminance(trans) * t_end * cos_axis
                weight_sum += luminance(trans)
                trans = wp.vec3(0.0)

        radiance[row, col] = light
        transmittance[row, col] = trans
        if weight_sum > 1.0e-6:
            depth[row, col] = depth_sum / weight_sum
        else:
            depth[row, col] = cam.far
        samples[row, col] = lookups

    return single_scatter
