"""The air's single scattering that the scenery's shadows take away in front of the eye.

The sky pass lights the air in front of the frame's layers from the air's own model (Riley's closed form, the
round earth's quadrature and tables), which knows no terrain, fog or cloud deck: air in the shadow of a hill, below
a fog's top or under a deck is lit there as if the sun reached it. Under a low sun a valley lies in its hills'
shadow, and the air between the eye and the valley floor was then the brightest thing in a dim frame (on a
scenery-family stage under a 5 deg sun, the front air's red was the whole 13 % by which the frame exceeded the path
tracer's). This module measures, per pixel whose ray ends on something the passes drew, the sun's single
scattering in the air along that front stretch where the scenery shades it,

    S = E_sun sum_i [sigma_R(h_i) p_R + sigma_M(h_i) p_M] T_eye(t_i) T_air,sun(h_i) (1 - V_i) dt,

over :data:`STEPS` midpoints t_i of the stretch, with V_i the scenery's transmittance towards the sun (the meshes'
occlusion, the fog's and the deck's closed forms: the passes that ``shades_air``; not a stratiform layer, below
which the air is lit by the layer's own diffuse light, which the tables do not hold either), sigma the air's
Rayleigh and aerosol scattering at each point's altitude (the ozone layer, above 10 km, is left out), T_eye the air's
transmittance back to the eye (the midpoint sum of its extinction), T_air,sun the air's towards the sun at that
altitude (:meth:`~warpsky.light.frame.FrameLight.transmittance_at`). The sky pass subtracts it from its front light
(:class:`~warpsky.passes.sky.sky.SkyPass`). The light the air scatters more than once is left as the tables give it.
Pixels of open sky (shafts in the air seen against the sky) are left as they were.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.light.background import pixel_directions
from warpsky.light.sun import sunlight
from warpsky.model.scene import Projection
from warpsky.optics.phase import PhaseKind, phase_numpy
from warpsky.surfaces.mesh import SurfaceMeshes, mesh_occluded

#: Midpoints per pixel along the front stretch of air: 8 and 16 gave the same frame on a family stage under a 5 deg
#: sun (+1.49 % and +1.50 % against the path tracer); 8 costs 6.8 s at 1920 x 1080 on the valley-fog stage (2-core
#: CPU), 16 cost 11.8 s.
STEPS = 8
#: Pixels per batch of points (bounds the host memory: STEPS x this x 3 float64).
BATCH = 65536
#: Altitudes at which the air's transmittance towards the sun is evaluated; log-linear between them.
SUN_ALTITUDES = 17
#: Length [m] of a shadow ray towards the sun through the meshes.
SHADOW_LENGTH = 1.0e7


@wp.kernel
def sun_visible_kernel(surfaces: SurfaceMeshes, points: wp.array(dtype=wp.vec3), sun: wp.vec3,
                       out: wp.array(dtype=float)):
    """1 where the ray from ``points[i]`` (relative to the meshes' camera) towards the sun meets no mesh, else 0."""
    i = wp.tid()
    out[i] = wp.where(mesh_occluded(surfaces, points[i], sun, SHADOW_LENGTH), 0.0, 1.0)


def mesh_visibility(occluders, points: np.ndarray, sun: np.ndarray, device: str) -> np.ndarray:
    """(N,) 1 where ``points`` (relative to the occluders' camera) see the sun past the meshes, else 0."""
    with wp.ScopedDevice(device):
        out = wp.zeros(len(points), dtype=float)
        wp.launch(sun_visible_kernel, dim=len(points), inputs=[
            occluders.surfaces, wp.array(points.astype(np.float32), dtype=wp.vec3),
            wp.vec3(*np.asarray(sun, np.float64).tolist()), out])
        return out.numpy().astype(np.float64)


def sun_air_table(light, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    """(altitudes (K,), log transmittance (K, 3)): the frame light's transmittance of the air towards the sun at
    :data:`SUN_ALTITUDES` stage altitudes [m] from ``low`` to ``high``."""
    nodes = np.linspace(low, max(high, low + 1.0), SUN_ALTITUDES)
    return nodes, np.log(np.maximum(np.stack([light.transmittance_at(float(h)) for h in nodes]), 1e-300))


def sun_air_transmittance(table: tuple[np.ndarray, np.ndarray], altitudes: np.ndarray) -> np.ndarray:
    """(N, 3) the air's transmittance towards the sun at stage altitudes ``altitudes`` (N,) [m], log-linear in
    ``table`` (:func:`sun_air_table`)."""
    nodes, logs = table
    return np.exp(np.stack([np.interp(altitudes, nodes, logs[:, c]) for c in range(3)], axis=-1))


def shadowed_front(frame, air_depth: np.ndarray, shadows: list) -> np.ndarray | None:
    """(H, W, 3) the front air's single scattering of the sun that the scenery shades (module docstring), or None
    where nothing can shade it (no air, no sun, an orthographic camera, no shadow and no meshes)."""
    scene = frame.scene
    atm, light = scene.atmosphere, sunlight(scene)
    occluders = frame.occluders
    camera = scene.camera.conformed(frame.width, frame.height)
    if (atm is None or light is None or not light.lit or camera.projection != Projection.PERSPECTIVE
            or not (shadows or occluders is not None)):
        return None
    rays = pixel_directions(camera, frame.width, frame.height).reshape(-1, 3)
    forward = np.asarray(camera.rotation, np.float64).reshape(3, 3) @ np.array([0.0, 0.0, -1.0])
    depth = np.asarray(air_depth, np.float64).reshape(-1)
    ends = np.flatnonzero(depth < float(camera.far))
    if not len(ends):
        return None
    out = np.zeros((rays.shape[0], 3))
    sun = np.asarray(light.direction, np.float64)
    cos_theta = rays @ sun
    phases = (3.0 / (16.0 * math.pi) * (1.0 + cos_theta**2), phase_numpy(PhaseKind.HG, atm.mie_g, cos_theta))
    lengths = depth[ends] / np.maximum(rays[ends] @ forward, 1e-6)  # along each ray to where it ends [m]
    heights = camera.position[1] + rays[ends, 1] * lengths
    table = sun_air_table(frame.light, min(float(heights.min()), float(camera.position[1])),
                          max(float(heights.max()), float(camera.position[1])))
    for start in range(0, len(ends), BATCH):
        pixels = ends[start:start + BATCH]
        step = lengths[start:start + BATCH] / STEPS
        t = (np.arange(STEPS) + 0.5)[None, :] * step[:, None]  # (P, STEPS)
        relative = rays[pixels, None, :] * t[..., None]
        points = (relative + camera.position).reshape(-1, 3)
        seen = np.ones((len(points), 3))
        if occluders is not None:
            seen *= mesh_visibility(occluders, relative.reshape(-1, 3), sun, frame.device)[:, None]
        for shadow in shadows:
            seen *= np.asarray(shadow(points), np.float64).reshape(-1, 3)
        h = points[:, 1] + atm.altitude
        rayleigh = atm.beta_sea_level[None, :] * np.exp(-h / atm.scale_height)[:, None]
        mie = np.exp(-h / atm.mie_scale_height)[:, None]
        extinction = (rayleigh + mie * (atm.mie_scattering + atm.mie_absorption)[None, :]).reshape(-1, STEPS, 3)
        eye = np.exp(-(np.cumsum(extinction, axis=1) - 0.5 * extinction) * step[:, None, None])
        source = (rayleigh * np.repeat(phases[0][pixels], STEPS)[:, None]
                  + mie * atm.mie_scattering[None, :] * np.repeat(phases[1][pixels], STEPS)[:, None])
        source = source * sun_air_transmittance(table, points[:, 1]) * (1.0 - seen)
        out[pixels] = (source.reshape(-1, STEPS, 3) * eye).sum(axis=1) * step[:, None]
    return (out * np.asarray(light.irradiance, np.float64)).reshape(frame.height, frame.width, 3)
