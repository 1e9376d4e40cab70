"""The dome (``UsdLuxDomeLight``) as kernels see it, and the ambient light the fast techniques take from it.

The path tracer looks the dome up where a path escapes (:func:`dome_radiance`: a constant, or a bilinear lookup of
the lat-long texture in the convention of :class:`~warpsky.model.scene.Dome`), so it integrates the dome exactly.
The marching techniques (single_scatter, slicing, the stratiform layers) cannot afford that integral per sample:
they light every point with the mean radiance L_mean arriving there (:func:`ambient_radiance`: the dome's mean over
the sphere, solid-angle weighted; with a ground plane its lower half is the ground lit by the dome) as an ambient
light. The phase function integrates to 1, so the in-scattered radiance is sigma_s L_mean, times an occlusion
factor (the technique's docstring says which: the transmittance towards the zenith, or none); a Lambertian ground
of albedo a reflects a E / pi, E the irradiance from the dome's upper hemisphere, under the same occlusion. This
is exact for a uniform dome seen through optically thin media and leaves out the dome light scattered more than
once and the directional structure of a textured dome.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core.numerics import exp3


@wp.struct
class DomeLight:
    """A dome: ``color`` times, when ``textured``, the lat-long texture's bilinear value in the direction."""

    color: wp.vec3  # RGB radiance scale [irradiance/sr]
    dome_from_world: wp.mat33  # rotation
    texture: wp.array2d(dtype=wp.vec3)  # (H, W) lat-long, row 0 latitude +pi/2, column 0 longitude +pi
    textured: int
    enabled: int  # 1: the scene has a dome (a runtime test, uniform over a launch); 0: black, untextured


def dome_struct(dome, device) -> DomeLight:
    """Kernel view of a :class:`~warpsky.model.scene.Dome` (None: black, untextured); the texture is uploaded."""
    out = DomeLight()
    out.color = wp.vec3(*(dome.color if dome is not None else np.zeros(3)).tolist())
    rotation = dome.rotation if dome is not None else np.eye(3)
    out.dome_from_world = wp.mat33(*np.asarray(rotation, dtype=np.float64).T.reshape(-1).tolist())
    texture = dome.texture if dome is not None and dome.texture is not None else np.zeros((1, 1, 3), np.float32)
    out.texture = wp.array(np.ascontiguousarray(texture, dtype=np.float32), dtype=wp.vec3, device=device)
    out.textured = int(dome is not None and dome.texture is not None)
    out.enabled = int(dome is not None)
    return out


@wp.func
def dome_radiance(dome: DomeLight, d: wp.vec3) -> wp.vec3:
    """Radiance arriving from world direction ``d`` (unit)."""
    if dome.textured == 0:
        return dome.color
    local = dome.dome_from_world * d
    height = dome.texture.shape[0]
    width = dome.texture.shape[1]
    lat = wp.asin(wp.clamp(local[1], -1.0, 1.0))
    lon = wp.atan2(local[0], local[2])
    x = wp.clamp(0.5 * float(width - 1) - lon * float(width - 1) / (2.0 * wp.pi), 0.0, float(width - 1))
    y = wp.clamp(0.5 * float(height - 1) - lat * float(height - 1) / wp.pi, 0.0, float(height - 1))
    x0 = wp.min(int(wp.floor(x)), width - 1)
    y0 = wp.min(int(wp.floor(y)), height - 1)
    x1 = wp.min(x0 + 1, width - 1)
    y1 = wp.min(y0 + 1, height - 1)
    fx = x - float(x0)
    fy = y - float(y0)
    top = dome.texture[y0, x0] * (1.0 - fx) + dome.texture[y0, x1] * fx
    bottom = dome.texture[y1, x0] * (1.0 - fx) + dome.texture[y1, x1] * fx
    return wp.cw_mul(dome.color, top * (1.0 - fy) + bottom * fy)


def hemisphere_directions(samples: int, *, upper: bool) -> np.ndarray:
    """World directions [samples, 2 samples, 3] at the centres of an equal-area grid of a hemisphere (uniform in
    the cosine of the zenith angle and in azimuth)."""
    cos_theta = (np.arange(samples) + 0.5) / samples * (1.0 if upper else -1.0)
    phi = (np.arange(2 * samples) + 0.5) * (np.pi / samples)
    cos_grid, phi_grid = np.meshgrid(cos_theta, phi, indexing="ij")
    sin_grid = np.sqrt(1.0 - cos_grid**2)
    return np.stack([sin_grid * np.cos(phi_grid), cos_grid, sin_grid * np.sin(phi_grid)], axis=-1)


def upper_hemisphere(dome, samples: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(mean radiance, cosine-weighted mean radiance) [RGB] of the dome's upper hemisphere (bilinear texture on an
    equal-area grid of ``samples`` x ``2 samples`` cells). The second is E / pi, the uniform radiance that gives a
    horizontal surface the irradiance E the hemisphere gives it."""
    if dome.texture is None:
        return dome.color.copy(), dome.color.copy()
    directions = hemisphere_directions(samples, upper=True)
    radiance = dome.radiance(directions)
    cosine = directions[..., 1:2]
    return radiance.reshape(-1, 3).mean(axis=0), 2.0 * (radiance * cosine).reshape(-1, 3).mean(axis=0)


def mean_radiance(dome, samples: int = 256) -> np.ndarray:
    """The dome's mean radiance over the sphere, solid-angle weighted [RGB] (exactly ``color`` when uniform)."""
    if dome.texture is None:
        return dome.color.copy()
    lower = dome.radiance(hemisphere_directions(samples, upper=False)).reshape(-1, 3).mean(axis=0)
    return 0.5 * (upper_hemisphere(dome, samples)[0] + lower)


def ambient_radiance(scene) -> np.ndarray:
    """The mean radiance [RGB] arriving at a point of the media from all directions: the dome's mean L_mean, or
    with a ground plane the upper half of the sphere from the dome and the lower half from the ground it lights
    (albedo E / pi); zeros without a dome. The fast techniques' ambient light."""
    if scene.dome is None:
        return np.zeros(3)
    if scene.ground is None:
        return mean_radiance(scene.dome)
    return isotropic_ambient(scene, upper_hemisphere(scene.dome))


def isotropic_ambient(scene, sky: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The mean radiance [RGB] reaching a point from all directions under ``sky`` = (mean, E / pi) of the upper
    hemisphere: half the sky's mean, plus half the light of a Lambertian ground below it that the sky lights
    (albedo E / pi; the ground plane's albedo, else the meshes' mean albedo, else none)."""
    mean, cosine = sky
    albedo = np.zeros(3)
    if scene.ground is not None:
        albedo = scene.ground.albedo
    elif scene.meshes:
        albedo = np.mean([m.albedo for m in scene.meshes], axis=0)
    return 0.5 * (mean + albedo * cosine)


def ambient_vec(scene) -> wp.vec3:
    """:func:`ambient_radiance` as a kernel argument."""
    return wp.vec3(*ambient_radiance(scene).tolist())


def ground_ambient_vec(scene) -> wp.vec3:
    """The radiance a Lambertian ground of albedo 1 reflects under the dome's upper hemisphere (its E / pi; zeros
    without a dome), as a kernel argument: kernels multiply it by the ground's albedo and occlusion."""
    return wp.vec3(*(np.zeros(3) if scene.dome is None else upper_hemisphere(scene.dome)[1]).tolist())


@wp.func
def ambient_scattered(scattering: wp.vec3, ambient: wp.vec3, tau_up: wp.vec3) -> wp.vec3:
    """Ambient dome light scattered towards the eye per metre [radiance/m]: sigma_s L_mean (the phase integrates to
    1) times the transmittance exp(-tau_up) towards the zenith (the occlusion factor)."""
    return wp.cw_mul(wp.cw_mul(scattering, ambient), exp3(tau_up))


@wp.func
def ambient_ground(albedo: wp.vec3, sky: wp.vec3, tau_up: wp.vec3) -> wp.vec3:
    """Radiance of a Lambertian ground of ``albedo`` under the dome: albedo E / pi with ``sky`` = E / pi of the
    dome's upper hemisphere (:func:`upper_hemisphere`), occluded by exp(-tau_up) towards the zenith."""
    return ambient_scattered(albedo, sky, tau_up)
