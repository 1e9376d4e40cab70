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

from warpsky.core.kernel_variants import kernel_variants
from warpsky.core.numerics import exp3, exp_lerp_mean3, luminance
from warpsky.light.dome import ambient_ground
from warpsky.light.skylight import AmbientLobes, SkyEnvironment, ambient_inscatter, ambient_lobes, mixed_asymmetry
from warpsky.light.sun import Sun
from warpsky.media.phase_mixture import oriented_correction_function, phase_sum_function
from warpsky.media.voxels.shadow import depth_functions, empty_until
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia, media_functions, media_span
from warpsky.model.camera_rays import PinholeCamera, PrimaryRay, primary_ray
from warpsky.optics.kernels import medium_phase, scattering_angle
from warpsky.optics.oriented_phase import OrientedPhases
from warpsky.surfaces.plane import Ground, ground_end

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


@wp.struct
class EyeMarch:
    """What the eye march carries from step to step."""

    light: wp.vec3  # radiance scattered towards the eye so far, RGB
    tau: wp.vec3  # optical depth from the eye to the current step's start, RGB
    depth_sum: float  # sum over steps of opacity * depth along the view axis [m]
    weight_sum: float  # sum over steps of opacity
    lookups: wp.int64  # grid lookups so far
    tau_sun: wp.vec3  # optical depth from the current step's start to the sun, RGB (when sun_known is 1)
    sun_known: int  # 1: the step before marched tau_sun


@wp.func
def eye_march_start() -> EyeMarch:
    """The march before its first step: nothing gathered, clear, nothing looked up."""
    out = EyeMarch()
    out.light = wp.vec3(0.0)
    out.tau = wp.vec3(0.0)
    out.depth_sum = 0.0
    out.weight_sum = 0.0
    out.lookups = wp.int64(0)
    out.tau_sun = wp.vec3(0.0)
    out.sun_known = 0
    return out


@functools.cache
def light_functions(has_detail: bool):
    """``(sun_step, sky_step, ground_light)``, the light one step of the eye march and the ground gather through
    the media's shadow marches, specialised on animated detail."""

    sun_optical_depth, vertical_optical_depth = depth_functions(has_detail)

    @wp.func
    def sun_step(media: VoxelMedia, sun: Sun, march: MarchSettings, ray: PrimaryRay, state: EyeMarch, ta: float,
                 dt: float, scatter: wp.vec3, tau_b: wp.vec3) -> EyeMarch:
        """``state`` with the sunlight of the step [ta, ta + dt] [m] added: ``scatter`` the scattering-weighted
        phase sum at its midpoint [1/(m sr)], ``tau_b`` the eye's optical depth at its end; the depth to the sun is
        marched at both ends (the start's reused from the step before when it was marched)."""
        out = state
        if sun.lit != 0 and wp.max(scatter) > 0.0:
            if out.sun_known == 0:
                shadow = sun_optical_depth(media, ray.origin, ta, ray.direction, sun.direction, march.shadow_step)
                out.tau_sun = wp.vec3(shadow[0], shadow[1], shadow[2])
                out.lookups += wp.int64(shadow[3])
            shadow_b = sun_optical_depth(media, ray.origin, ta + dt, ray.direction, sun.direction, march.shadow_step)
            tau_sun_b = wp.vec3(shadow_b[0], shadow_b[1], shadow_b[2])
            out.lookups += wp.int64(shadow_b[3])
            mean = exp_lerp_mean3(out.tau + out.tau_sun, tau_b + tau_sun_b)
            out.light += wp.cw_mul(wp.cw_mul(scatter, sun.irradiance), mean) * dt
            out.tau_sun = tau_sun_b
            out.sun_known = 1
        else:
            out.sun_known = 0
        return out

    @wp.func
    def sky_step(media: VoxelMedia, march: MarchSettings, lobes: AmbientLobes, ray: PrimaryRay, state: EyeMarch,
                 here: MediaPoint, tm: float, dt: float, tau_b: wp.vec3) -> EyeMarch:
        """``state`` with the sky's light of the step of length ``dt`` [m] around ``tm`` added (the media ``here``
        at its midpoint, ``tau_b`` the eye's optical depth at its end), occluded towards the zenith (and the nadir
        when the lower hemisphere holds light) from the midpoint."""
        out = state
        if march.ambient_on != 0 and wp.max(here.scattering) > 0.0:
            up = vertical_optical_depth(media, ray.origin, tm, ray.direction, 0, march.shadow_step)
            out.lookups += wp.int64(up[3])
            t_down = wp.vec3(0.0)
            if march.environment.lower_lit != 0:
                down = vertical_optical_depth(media, ray.origin, tm, ray.direction, 1, march.shadow_step)
                out.lookups += wp.int64(down[3])
                t_down = exp3(wp.vec3(down[0], down[1], down[2]))
            g = mixed_asymmetry(media, here, march.environment.asymmetry)
            sky = ambient_inscatter(lobes, g, exp3(wp.vec3(up[0], up[1], up[2])), t_down)
            out.light += wp.cw_mul(wp.cw_mul(here.scattering, sky), exp_lerp_mean3(out.tau, tau_b)) * dt
        return out

    @wp.func
    def ground_light(media: VoxelMedia, sun: Sun, ground: Ground, march: MarchSettings, ray: PrimaryRay,
                     state: EyeMarch, t_end: float, trans: wp.vec3) -> EyeMarch:
        """``state`` with the Lambertian ground at ``t_end`` [m] added, lit by the sun and the sky (occluded
        towards the zenith) through the media and seen through ``trans``; its depth weighted by ``trans``."""
        out = state
        if sun.lit != 0:
            shadow = sun_optical_depth(media, ray.origin, t_end, ray.direction, sun.direction, march.shadow_step)
            out.lookups += wp.int64(shadow[3])
            lit_ground = wp.cw_mul(ground.albedo, sun.irradiance) * (wp.max(sun.direction[1], 0.0) / wp.pi)
            out.light += wp.cw_mul(wp.cw_mul(lit_ground, exp3(wp.vec3(shadow[0], shadow[1], shadow[2]))), trans)
        if march.ambient_on != 0:
            up = vertical_optical_depth(media, ray.origin, t_end, ray.direction, 0, march.shadow_step)
            out.lookups += wp.int64(up[3])
            shown = ambient_ground(ground.albedo, march.ground_ambient, wp.vec3(up[0], up[1], up[2]))
            out.light += wp.cw_mul(shown, trans)
        out.depth_sum += luminance(trans) * t_end * ray.cos_axis
        out.weight_sum += luminance(trans)
        return out

    return sun_step, sky_step, ground_light


@functools.cache
def march_functions(has_tables: bool, has_detail: bool):
    """``eye_march(media, phase_tables, oriented, sun, march, lobes, ray, theta, t0, t1) -> EyeMarch``, specialised
    on tabulated species and animated detail: the march of the view ray ``ray`` from t0 to t1 [m], ``theta`` the
    scattering angle of the sunlight towards the eye, ``lobes`` the sky seen along the ray."""

    sample_media = media_functions(has_detail)
    scattered_phase = phase_sum_function(has_tables)
    sun_step, sky_step = light_functions(has_detail)[:2]

    @wp.func
    def march_step(media: VoxelMedia, phase_tables: wp.array(dtype=float), oriented: OrientedPhases, sun: Sun,
                   march: MarchSettings, lobes: AmbientLobes, ray: PrimaryRay, theta: float, state: EyeMarch,
                   ta: float, dt: float) -> EyeMarch:
        """``state`` after the step [ta, ta + dt] [m]: the media at its midpoint, the sun's and the sky's light it
        scatters towards the eye, its opacity-weighted depth, the eye's optical depth at its end."""
        tm = ta + 0.5 * dt
        here = sample_media(media, ray.origin + tm * ray.direction)
        scatter = scattered_phase(media, here, phase_tables, wp.vec3(0.0), theta)
        if wp.static(has_tables):  # oriented crystals are ice, a tabulated species
            scatter += oriented_correction(media, here, phase_tables, oriented, ray.direction, theta)
        out = state
        out.lookups += wp.int64(media.count)
        tau_b = out.tau + here.extinction * dt
        out = sun_step(media, sun, march, ray, out, ta, dt, scatter, tau_b)
        out = sky_step(media, march, lobes, ray, out, here, tm, dt, tau_b)
        opacity = luminance(exp3(out.tau)) - luminance(exp3(tau_b))
        out.depth_sum += opacity * tm * ray.cos_axis
        out.weight_sum += opacity
        out.tau = tau_b
        return out

    @wp.func
    def eye_march(media: VoxelMedia, phase_tables: wp.array(dtype=float), oriented: OrientedPhases, sun: Sun,
                  march: MarchSettings, lobes: AmbientLobes, ray: PrimaryRay, theta: float, t0: float,
                  t1: float) -> EyeMarch:
        """The march of ``ray`` from t0 to t1 [m] in equal steps of at most ``march.step``, until the eye's
        luminance transmittance falls below ``march.min_transmittance``. After a step whose midpoint held no
        medium, the steps whose midpoints lie in empty cells (:func:`empty_until`) are skipped: each would add
        exactly nothing."""
        out = eye_march_start()
        if t1 > t0:
            count = wp.max(int(wp.ceil((t1 - t0) / march.step)), 1)
            dt = (t1 - t0) / float(count)
            i = int(0)
            clear = int(1)  # the step before held no medium (the march starts outside the media)
            while i < count:
                if clear != 0:
                    tm = t0 + (float(i) + 0.5) * dt
                    until = empty_until(media, ray.origin, ray.direction, tm)
                    if until >= t1:
                        break
                    if until > tm:  # on to the first step whose midpoint is at or past ``until``
                        i = wp.max(i + 1, int(wp.ceil((until - t0) / dt - 0.5)))
                        out.sun_known = 0
                        continue
                before = out.tau
                out = march_step(media, phase_tables, oriented, sun, march, lobes, ray, theta, out,
                                 t0 + float(i) * dt, dt)
                clear = wp.where(wp.max(out.tau - before) == 0.0, 1, 0)
                if luminance(exp3(out.tau)) < march.min_transmittance:
                    break
                i += 1
        return out

    return eye_march


@kernel_variants(has_tables=(False, True), has_detail=(False, True))
@functools.cache
def single_scatter_kernel(has_tables: bool, has_detail: bool = False) -> wp.Kernel:
    """The per-pixel march, specialised on tabulated species and animated detail: a scene without them pays nothing
    for those branches. The ground plane is a runtime test (``ground.enabled``, once per pixel)."""

    eye_march = march_functions(has_tables, has_detail)
    ground_light = light_functions(has_detail)[2]

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
        # Light travels along -sun.direction and leaves towards the eye along -ray.direction.
        theta = scattering_angle(sun.direction, ray.direction)
        t_end = ray.t_far
        hit_ground = int(0)
        if ground.enabled != 0:
            t_end, hit_ground = ground_end(ground, ray.origin, ray.direction, ray.t_near, t_end)
        lobes = ambient_lobes(march.environment, ray.direction)
        span = media_span(media, ray.origin, ray.direction, ray.t_near, t_end)
        state = eye_march(media, phase_tables, oriented, sun, march, lobes, ray, theta, span[0], span[1])
        trans = exp3(state.tau)
        if hit_ground != 0:
            state = ground_light(media, sun, ground, march, ray, state, t_end, trans)
            trans = wp.vec3(0.0)
        radiance[row, col] = state.light
        transmittance[row, col] = trans
        if state.weight_sum > 1.0e-6:
            depth[row, col] = state.depth_sum / state.weight_sum
        else:
            depth[row, col] = cam.far
        samples[row, col] = state.lookups

    return single_scatter
