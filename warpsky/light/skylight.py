"""The light of the whole sky on the media: the analytic sky, the dome and the ground they light, as the marching
techniques (single_scatter, slicing) take it (Riley et al. 2004, §8: "skylight as a light source on the volume").

**The environment.** A point of the media receives radiance L(w) from every direction w (the direction the light
comes from, world axes, Y up):

* upper hemisphere (w_y > 0): the dome, and with a sky pass (an atmosphere the technique does not trace, a lit
  sun) Riley's single-scattering air to infinity seen from the media's altitude h,
  L_sky(w) = E_sun P_R(w . l) inscatter(h, w_y) plus the multiple-scattering table's light
  (:func:`~warpsky.media.air.multiple_kernels.air_radiance`, what the sky pass draws and
  :func:`~warpsky.light.sky.sky_hemisphere` averages), from the sun as it
  arrives at the top of the air (the technique receives it reddened by the air above the media and
  :func:`~warpsky.light.sun.above_air` leaves that out). With an atmosphere the dome lies
  beyond the air and is seen through its transmittance exp(-beta(h) / (gamma w_y)).
* lower hemisphere (w_y < 0): without air, a Lambertian ground lit by the upper hemisphere (radiance a E / pi,
  a the ground plane's albedo, else the meshes' mean albedo), else the dome's lower half. With air, the air's
  in-scattering down to the ground plane or to sea level, plus the ground (black sea level without one) seen
  through the air between; E / pi is then taken at the ground's altitude.

Each hemisphere h is projected on the first two spherical-harmonic bands on an equal-area grid (cells of equal
solid angle 2 pi / N):

    m_h = (1 / 4 pi) int_h L dw = mean(L) / 2,      M_h = (1 / 4 pi) int_h L w dw = mean(L w) / 2,

per RGB channel (M_h a 3-vector per channel). A uniform dome of radiance L gives m = L / 2 and M_up = (0, L/4, 0).

**In-scattering.** Light from w travels along -w; scattered towards the eye it travels along -v, v the view ray
from the eye into the scene, so the scattering angle has cos theta = w . v. By Funk-Hecke, a phase of asymmetry g
(its first Legendre moment, p = (1 + 3 g cos theta + ...) / 4 pi) scatters

    S(v) = T_up max(0, m_up + 3 g M_up . v) + T_down max(0, m_down + 3 g M_down . v)

per unit scattering coefficient towards the eye: looking up at a cloud under a bright sky (v . M_up > 0) sees the
sky's light scattered forward. Each hemisphere is occluded by the media's transmittance T_up / T_down towards the
zenith / nadir (1 where a technique leaves occlusion out); the clamp keeps the truncated expansion non-negative
(it cuts in for g > 1/3 under a uniform hemisphere seen from behind). g is the medium's HG g, or the mean cosine of
a species' tabulated phase (per channel), mixed over the media at a point by scattering weight. Left out: the
bands above the first (the sky's sharp structure near the sun, a strongly forward phase's peak), light scattered
more than once, and the sunlit ground's own light on the media.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.light.dome import ambient_radiance, hemisphere_directions, upper_hemisphere
from warpsky.light.frame import media_altitude
from warpsky.light.sun import above_air, lights_air, sunlight
from warpsky.media.air.mixture import transmittance as air_transmittance
from warpsky.media.air.multiple_kernels import air_radiance
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia
from warpsky.optics.tables import mean_cosine

#: Cells of the equal-area grid per hemisphere: SAMPLES x 2 SAMPLES.
SAMPLES = 64


@dataclass(frozen=True)
class Environment:
    """The media's environment on two spherical-harmonic bands per hemisphere (see the module docstring).

    Attributes:
        upper_mean: m_up, RGB [radiance].
        upper_moment: M_up, (3 channels, 3 axes) [radiance].
        lower_mean: m_down, RGB [radiance].
        lower_moment: M_down, (3 channels, 3 axes) [radiance].
        ground_sky: E / pi of the sky at the ground: the radiance a white Lambertian ground reflects, RGB.
        lower_lit: Whether the lower hemisphere holds any light (else the kernels skip its occlusion march).
    """

    upper_mean: np.ndarray
    upper_moment: np.ndarray
    lower_mean: np.ndarray
    lower_moment: np.ndarray
    ground_sky: np.ndarray
    lower_lit: bool


def has_sky_light(scene, *, traces_air: bool = False) -> bool:
    """Whether the frame has a sky pass whose air lights the media: an atmosphere the technique does not trace and
    a sun above the horizon."""
    if scene.atmosphere is None or traces_air:
        return False
    return lights_air(scene.atmosphere, sunlight(above_air(scene)))


def projection(radiance: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, M) of one hemisphere: ``radiance`` (N, 3) on the equal-area cells with unit ``directions`` (N, 3);
    m = mean(L) / 2 RGB, M = mean(L w) / 2 as (3 channels, 3 axes)."""
    radiance = np.asarray(radiance, dtype=np.float64)
    mean = 0.5 * radiance.mean(axis=0)
    moment = 0.5 * np.einsum("nc,na->ca", radiance, directions) / len(directions)
    return mean, moment


def _upper_radiance(scene, atmosphere, light, directions: np.ndarray, altitude: float) -> np.ndarray:
    """(N, 3) radiance from the upper-hemisphere ``directions`` at ``altitude`` above sea level [m]: ``scene``'s
    dome (beyond the ``atmosphere``'s transmittance when there is one) plus, with the sunlight ``light``, the air as
    the sky pass draws it (:func:`~warpsky.media.air.multiple_kernels.air_radiance`)."""
    out = np.zeros((len(directions), 3))
    up = directions[:, 1:2]
    dome = scene.dome
    if dome is not None:
        dome = dome.radiance(directions)
        if atmosphere is not None and atmosphere.round:
            from warpsky.media.air import round_earth as air_round_host

            dome = dome * air_round_host.space_transmittance(atmosphere, air_round_host.scene_floor(scene), altitude,
                                                             directions)
        elif atmosphere is not None:
            dome = dome * air_transmittance(atmosphere, altitude, up[:, 0], np.inf)
        out = out + dome
    if light is not None:
        out = out + air_radiance(scene, light, altitude, directions)
    return out


def ground_albedo(scene) -> np.ndarray | None:
    """The albedo of what lies below: the ground plane's, else the meshes' mean, else None."""
    if scene.ground is not None:
        return np.asarray(scene.ground.albedo, dtype=np.float64)
    if scene.meshes:
        return np.mean([m.albedo for m in scene.meshes], axis=0)
    return None


def media_environment(scene, *, traces_air: bool = False, samples: int = SAMPLES) -> Environment | None:
    """The environment of ``scene``'s media (see the module docstring), for a technique that receives the scene as
    the media see it (the sun reddened when the frame has a sky pass); None without a dome and without sky light
    (the kernels then run exactly as without either)."""
    sky = has_sky_light(scene, traces_air=traces_air)
    if scene.dome is None and not sky:
        return None
    light = sunlight(above_air(scene)) if sky else None
    atmosphere = None if traces_air else scene.atmosphere
    up = hemisphere_directions(samples, upper=True).reshape(-1, 3)
    down = hemisphere_directions(samples, upper=False).reshape(-1, 3)
    albedo = ground_albedo(scene)
    if atmosphere is None:
        upper = _upper_radiance(scene, None, None, up, 0.0)
        ground_sky = 2.0 * (upper * up[:, 1:2]).mean(axis=0)
        lower = np.broadcast_to(albedo * ground_sky, (len(down), 3)) if albedo is not None else scene.dome.radiance(
            down)
    else:
        altitude = media_altitude(scene)
        floor = scene.ground.height + atmosphere.altitude if scene.ground is not None else 0.0
        upper = _upper_radiance(scene, atmosphere, light, up, altitude)
        ground_sky = 2.0 * (_upper_radiance(scene, atmosphere, light, up, floor) * up[:, 1:2]).mean(axis=0)
        distance = max(altitude - floor, 0.0) / -down[:, 1]
        lower = np.zeros((len(down), 3))
        if albedo is not None and atmosphere.round:
            from warpsky.media.air import round_earth as air_round_host

            lower = lower + albedo * ground_sky * air_round_host.floor_transmittance(
                atmosphere, air_round_host.scene_floor(scene), altitude, down)
        elif albedo is not None:
            lower = lower + albedo * ground_sky * air_transmittance(atmosphere, altitude, down[:, 1], distance)
        if light is not None:
            # a round earth's air ends at the floor's sphere, or beyond the horizon at the top of the air
            lower = lower + air_radiance(scene, light, altitude, down, np.inf if atmosphere.round else distance)
    upper_mean, upper_moment = projection(upper, up)
    lower_mean, lower_moment = projection(lower, down)
    return Environment(upper_mean, upper_moment, lower_mean, lower_moment, ground_sky,
                       bool(np.max(lower_mean) > 0.0))


def isotropic_environment(scene) -> Environment | None:
    """The fast techniques' ambient light before skylight (the ``skylight = 0`` setting): the dome's mean radiance
    L_mean (:func:`~warpsky.light.dome.ambient_radiance`) from the upper hemisphere only, occluded towards the
    zenith, which with m_up = L_mean and no moments makes S(v) = T_up L_mean for every phase; None without a
    dome."""
    if scene.dome is None:
        return None
    zero = np.zeros(3)
    ground_sky = upper_hemisphere(scene.dome)[1]
    return Environment(ambient_radiance(scene), np.zeros((3, 3)), zero, np.zeros((3, 3)), ground_sky, False)


# ---- on the device -----------------------------------------------------------------------------------------


@wp.struct
class SkyEnvironment:
    """:class:`Environment` as kernels see it, with each medium's asymmetry."""

    upper_mean: wp.vec3  # m_up, RGB [radiance]
    upper_moment: wp.mat33  # row c: M_up of channel c [radiance]
    lower_mean: wp.vec3  # m_down, RGB
    lower_moment: wp.mat33  # row c: M_down of channel c
    lower_lit: int  # 1: the lower hemisphere holds light (march the nadir for its occlusion)
    asymmetry: wp.array(dtype=wp.vec3)  # g per channel of medium m (VoxelMedia order)


def environment_struct(environment: Environment | None, media, device) -> SkyEnvironment:
    """Kernel view of ``environment`` (None: black) for the scene's ``media`` (their asymmetry uploaded)."""
    out = SkyEnvironment()
    env = environment or Environment(np.zeros(3), np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3)), np.zeros(3),
                                     False)
    out.upper_mean = wp.vec3(*np.asarray(env.upper_mean, np.float64).tolist())
    out.upper_moment = wp.mat33(*np.asarray(env.upper_moment, np.float64).reshape(-1).tolist())
    out.lower_mean = wp.vec3(*np.asarray(env.lower_mean, np.float64).tolist())
    out.lower_moment = wp.mat33(*np.asarray(env.lower_moment, np.float64).reshape(-1).tolist())
    out.lower_lit = int(env.lower_lit)
    g = np.array([mean_cosine(m) for m in media], dtype=np.float32).reshape(-1, 3) if media else np.zeros((1, 3))
    from warpsky.core import device_buffers

    out.asymmetry = device_buffers.upload("skylight:asymmetry", g.astype(np.float32), wp.vec3, device)
    return out


@wp.struct
class AmbientLobes:
    """The environment seen along one view ray v: per hemisphere the mean m and the dipole 3 M . v, RGB."""

    upper_base: wp.vec3
    upper_dipole: wp.vec3
    lower_base: wp.vec3
    lower_dipole: wp.vec3


@wp.func
def ambient_lobes(env: SkyEnvironment, view: wp.vec3) -> AmbientLobes:
    """The lobes of ``env`` for the unit view ray ``view`` (from the eye into the scene): cos theta = w . v."""
    out = AmbientLobes()
    out.upper_base = env.upper_mean
    out.upper_dipole = (env.upper_moment * view) * 3.0
    out.lower_base = env.lower_mean
    out.lower_dipole = (env.lower_moment * view) * 3.0
    return out


@wp.func
def lobe(base: wp.vec3, dipole: wp.vec3, g: wp.vec3) -> wp.vec3:
    """max(0, m + g 3 M . v) per channel."""
    return wp.vec3(wp.max(base[0] + g[0] * dipole[0], 0.0), wp.max(base[1] + g[1] * dipole[1], 0.0),
                   wp.max(base[2] + g[2] * dipole[2], 0.0))


@wp.func
def ambient_inscatter(lobes: AmbientLobes, g: wp.vec3, t_up: wp.vec3, t_down: wp.vec3) -> wp.vec3:
    """S(v): the environment's radiance scattered towards the eye per unit scattering coefficient, RGB
    [radiance], for asymmetry ``g`` and the transmittances towards the zenith and nadir."""
    return (wp.cw_mul(lobe(lobes.upper_base, lobes.upper_dipole, g), t_up)
            + wp.cw_mul(lobe(lobes.lower_base, lobes.lower_dipole, g), t_down))


@wp.func
def mixed_asymmetry(media: VoxelMedia, point: MediaPoint, asymmetry: wp.array(dtype=wp.vec3)) -> wp.vec3:
    """g at a point: sum over media of sigma_s,m g_m over sum of sigma_s,m, per channel (0 without scattering)."""
    num = wp.vec3(0.0)
    for m in range(media.count):
        value = point.density[m]
        if value > 0.0:
            num += wp.cw_mul(media.grids[m].scattering * value, asymmetry[m])
    out = wp.vec3(0.0)
    for c in range(3):
        if point.scattering[c] > 0.0:
            out[c] = num[c] / point.scattering[c]
    return out


def ambient_settings(scene, *, skylight: bool, traces_air: bool, device) -> tuple[SkyEnvironment, wp.vec3, int]:
    """(environment struct, E / pi of the sky at the ground, 1 when either lights anything) for a marching
    technique: with ``skylight`` :func:`media_environment`, else :func:`isotropic_environment`. Without a dome and
    without sky light the struct is black and the flag 0, so the kernels skip every ambient branch."""
    environment = (media_environment(scene, traces_air=traces_air) if skylight else isotropic_environment(scene))
    ground_sky = np.zeros(3) if environment is None else environment.ground_sky
    return (environment_struct(environment, scene.media, device), wp.vec3(*np.asarray(ground_sky).tolist()),
            int(environment is not None))
