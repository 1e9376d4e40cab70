"""Pieces every technique's kernels share: the pinhole camera and numerically stable exponential integrals."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.scene.model import Camera


@wp.struct
class PinholeCamera:
    """A conformed pinhole camera; positions are relative to the eye, which sits at the origin."""

    rotation: wp.mat33  # world-from-camera; columns right, up, back
    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    horizontal_offset: float
    vertical_offset: float
    near: float  # [m] along the view axis
    far: float  # [m] along the view axis
    width: int
    height: int


def pinhole_camera(camera: Camera, width: int, height: int) -> PinholeCamera:
    """Kernel view of a camera already conformed to (width, height)."""
    cam = PinholeCamera()
    cam.rotation = wp.mat33(*np.asarray(camera.rotation, dtype=np.float64).reshape(-1).tolist())
    cam.focal_length = float(camera.focal_length)
    cam.horizontal_aperture = float(camera.horizontal_aperture)
    cam.vertical_aperture = float(camera.vertical_aperture)
    cam.horizontal_offset = float(camera.horizontal_aperture_offset)
    cam.vertical_offset = float(camera.vertical_aperture_offset)
    cam.near = float(camera.near)
    cam.far = float(camera.far)
    cam.width = int(width)
    cam.height = int(height)
    return cam


@wp.func
def camera_ray_at(cam: PinholeCamera, row: int, col: int, fx: float, fy: float) -> wp.vec3:
    """Unit world direction through the point (fx, fy) in [0, 1)^2 of pixel (row, col); fx right, fy down."""
    sx = ((float(col) + fx) / float(cam.width) - 0.5) * cam.horizontal_aperture + cam.horizontal_offset
    sy = (0.5 - (float(row) + fy) / float(cam.height)) * cam.vertical_aperture + cam.vertical_offset
    return wp.normalize(cam.rotation * wp.vec3(sx, sy, -cam.focal_length))


@wp.func
def camera_ray(cam: PinholeCamera, row: int, col: int) -> wp.vec3:
    """Unit world direction through the centre of pixel (row, col); row 0 is the top of the image."""
    sx = ((float(col) + 0.5) / float(cam.width) - 0.5) * cam.horizontal_aperture + cam.horizontal_offset
    sy = (0.5 - (float(row) + 0.5) / float(cam.height)) * cam.vertical_aperture + cam.vertical_offset
    return wp.normalize(cam.rotation * wp.vec3(sx, sy, -cam.focal_length))


@wp.func
def one_minus_exp_over_x(x: float) -> float:
    """(1 - exp(-x)) / x for x >= 0, by its Taylor series near 0 (truncation error < x^4/120)."""
    if x < 1.0e-2:
        return 1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0)))
    return (1.0 - wp.exp(-x)) / x


@wp.func
def exp_lerp_mean(tau_a: float, tau_b: float) -> float:
    """Mean of exp(-tau) over a step along which tau goes linearly from tau_a to tau_b (both >= 0).

    Equals (exp(-tau_a) - exp(-tau_b)) / (tau_b - tau_a), taken as exp(-min) * (1 - exp(-d)) / d with
    d = |tau_b - tau_a| so it never divides 0 by 0 and never overflows, from optical depths of 1e-9 to 1e30.
    """
    lo = wp.min(tau_a, tau_b)
    return wp.exp(-lo) * one_minus_exp_over_x(wp.abs(tau_b - tau_a))


@wp.func
def exp_lerp_mean3(tau_a: wp.vec3, tau_b: wp.vec3) -> wp.vec3:
    """:func:`exp_lerp_mean` per RGB channel."""
    return wp.vec3(
        exp_lerp_mean(tau_a[0], tau_b[0]), exp_lerp_mean(tau_a[1], tau_b[1]), exp_lerp_mean(tau_a[2], tau_b[2])
    )


@wp.func
def exp3(tau: wp.vec3) -> wp.vec3:
    """exp(-tau) per channel."""
    return wp.vec3(wp.exp(-tau[0]), wp.exp(-tau[1]), wp.exp(-tau[2]))


@wp.func
def luminance(c: wp.vec3) -> float:
    """Rec. 709 luminance."""
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
