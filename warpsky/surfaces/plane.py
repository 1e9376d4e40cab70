"""The ground plane as kernels see it."""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class Ground:
    """The ground plane as kernels see it (kernels specialised on having one read it)."""

    offset: float  # plane height relative to the camera [m]
    albedo: wp.vec3  # Lambertian albedo, RGB

def ground_struct(ground, camera_position) -> Ground:
    """Kernel view of a :class:`~warpsky.scene.model.Ground` seen from ``camera_position`` (None: a zero struct)."""
    out = Ground()
    out.offset = float(ground.height - camera_position[1]) if ground is not None else 0.0
    out.albedo = wp.vec3(*(ground.albedo if ground is not None else np.zeros(3)).tolist())
    return out
