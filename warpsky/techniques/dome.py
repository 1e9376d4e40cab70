"""The dome (``UsdLuxDomeLight``) as kernels see it, and the ambient light the fast techniques take from it.

The path tracer looks the dome up where a path escapes (:func:`dome_radiance`: a constant, or a bilinear lookup of
the lat-long texture in the convention of :class:`~warpsky.scene.model.Dome`), so it integrates the dome exactly.
The marching techniques (single_scatter, slicing, the stratiform layers) cannot afford that integral per sample:
they light every point with the dome's mean radiance L_mean (over the sphere, solid-angle weighted) as an ambient
light. The phase function integrates to 1, so the in-scattered radiance is sigma_s L_mean, times an occlusion
factor (the technique's docstring says which: the transmittance towards the zenith, or none); a Lambertian ground
of albedo a under it reflects a L_mean. This is exact for a uniform dome seen through optically thin media and
leaves out the dome light scattered more than once and the directional structure of a textured dome.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class DomeLight:
    """A dome: ``color`` times, when ``textured``, the lat-long texture's bilinear value in the direction."""

    color: wp.vec3  # RGB radiance scale [irradiance/sr]
    dome_from_world: wp.mat33  # rotation
    texture: wp.array2d(dtype=wp.vec3)  # (H, W) lat-long, row 0 latitude +pi/2, column 0 longitude +pi
    textured: int


def dome_struct(dome, device) -> DomeLight:
    """Kernel view of a :class:`~warpsky.scene.model.Dome` (None: black, untextured); the texture is uploaded."""
    out = DomeLight()
    out.color = wp.vec3(*(dome.color if dome is not None else np.zeros(3)).tolist())
    rotation = dome.rotation if dome is not None else np.eye(3)
    out.dome_from_world = wp.mat33(*np.asarray(rotation, dtype=np.float64).T.reshape(-1).tolist())
    texture = dome.texture if dome is not None and dome.texture is not None else np.zeros((1, 1, 3), np.float32)
    out.texture = wp.array(np.ascontiguousarray(texture, dtype=np.float32), dtype=wp.vec3, device=device)
    out.textured = int(dome is not None and dome.texture is not None)
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


def ambient_radiance(scene) -> np.ndarray:
    """The dome's mean radiance L_mean [RGB] (zeros without a dome): the fast techniques' ambient light."""
    return np.zeros(3) if scene.dome is None else np.asarray(scene.dome.mean_radiance(), dtype=np.float64)


def ambient_vec(scene) -> wp.vec3:
    """:func:`ambient_radiance` as a kernel argument."""
    return wp.vec3(*ambient_radiance(scene).tolist())


@wp.func
def ambient_scattered(scattering: wp.vec3, ambient: wp.vec3, tau_up: wp.vec3) -> wp.vec3:
    """Ambient dome light scattered towards the eye per metre [radiance/m]: sigma_s L_mean (the phase integrates to
    1) times the transmittance exp(-tau_up) towards the zenith (the occlusion factor)."""
    return wp.cw_mul(wp.cw_mul(scattering, ambient), wp.vec3(wp.exp(-tau_up[0]), wp.exp(-tau_up[1]),
                                                              wp.exp(-tau_up[2])))


@wp.func
def ambient_ground(albedo: wp.vec3, ambient: wp.vec3, tau_up: wp.vec3) -> wp.vec3:
    """Radiance of a Lambertian ground of ``albedo`` under the ambient dome light (a L_mean: the cosine-weighted
    irradiance pi L_mean over pi), occluded by exp(-tau_up) towards the zenith."""
    return ambient_scattered(albedo, ambient, tau_up)
