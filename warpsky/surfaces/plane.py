"""The ground plane as kernels see it."""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class Ground:
    """The ground plane as kernels see it (``enabled`` = 0: the scene has none, the other fields are zeros)."""

    offset: float  # plane height relative to the camera [m]
    albedo: wp.vec3  # Lambertian albedo, RGB
    enabled: int  # 1: the scene has a ground plane (a runtime test, uniform over a launch)

def ground_struct(ground, camera_position) -> Ground:
    """Kernel view of a :class:`~warpsky.model.scene.Ground` seen from ``camera_position`` (None: a zero struct)."""
    out = Ground()
    out.offset = float(ground.height - camera_position[1]) if ground is not None else 0.0
    out.albedo = wp.vec3(*(ground.albedo if ground is not None else np.zeros(3)).tolist())
    out.enabled = int(ground is not None)
    return out


@wp.func
def ground_end(ground: Ground, origin: wp.vec3, view: wp.vec3, t_near: float, t_end: float):
    """(where the ray ``origin + t * view`` ends [m], 1 when the ground plane ends it): the plane is opaque, so it
    ends the ray where it lies between ``t_near`` and ``t_end`` (the part of the sun below it is already out of
    sun.irradiance)."""
    if view[1] != 0.0:
        t_ground = (ground.offset - origin[1]) / view[1]
        if t_ground > t_near and t_ground < t_end:
            return t_ground, 1
    return t_end, 0
