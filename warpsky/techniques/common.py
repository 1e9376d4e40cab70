"""Pieces every technique's kernels share: the pinhole camera and numerically stable exponential integrals."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpsky.scene.model import Camera, Projection
from warpsky.techniques.sunlight import Sunlight


@wp.struct
class PinholeCamera:
    """A conformed camera, pinhole or orthographic; positions are relative to the eye, which sits at the origin.

    An orthographic camera's apertures and offsets are its view window's size and shift [m] in the plane through
    the eye across the view axis; its rays start there (:func:`camera_ray_origin`) and run along the axis."""

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
    orthographic: int  # 1: parallel rays from the view window, 0: rays from the eye


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
    cam.orthographic = int(camera.projection is Projection.ORTHOGRAPHIC)
    return cam


@wp.struct
class Sun:
    """The sunlight as kernels see it (:class:`~warpsky.techniques.sunlight.Sunlight`; ``lit`` 0: none arrives).

    Kernels light with ``irradiance`` along ``direction`` wherever ``lit`` is set, whatever the elevation: the
    horizon has already been folded in on the host."""

    direction: wp.vec3  # unit vector towards the light: the centroid of the disk's visible part (world axes)
    irradiance: wp.vec3  # of the visible part, at normal incidence, RGB
    air_sine: float  # the air's optical depth towards the sun is its vertical column / air_sine (finite air mass)
    disk_direction: wp.vec3  # unit vector towards the disk's centre
    disk_radiance: wp.vec3  # of the disk where it is seen, RGB [irradiance/sr] (0 for a sun without a disk)
    cos_radius: float  # cosine of the disk's angular radius (2: no disk)
    lit: int


@wp.struct
class Ground:
    """The ground plane as kernels see it (kernels specialised on having one read it)."""

    offset: float  # plane height relative to the camera [m]
    albedo: wp.vec3  # Lambertian albedo, RGB


def sun_disk(angular_diameter: float) -> tuple[float, float]:
    """(cos of the angular radius, solid angle [sr]) of a sun disk of ``angular_diameter`` [rad]; (2, 1) for none."""
    radius = 0.5 * angular_diameter
    if radius <= 0.0:
        return 2.0, 1.0
    return math.cos(radius), 2.0 * math.pi * (1.0 - math.cos(radius))


def sun_struct(light: Sunlight | None, unlit_direction: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> Sun:
    """Kernel view of a :class:`~warpsky.techniques.sunlight.Sunlight` (or None: unlit, pointing along
    ``unlit_direction``)."""
    out = Sun()
    unlit = np.asarray(unlit_direction, dtype=np.float64)
    direction = light.direction if light is not None else unlit
    irradiance = light.irradiance if light is not None else np.zeros(3)
    out.direction = wp.vec3(*np.asarray(direction, dtype=np.float64).tolist())
    out.irradiance = wp.vec3(*np.asarray(irradiance, dtype=np.float64).tolist())
    out.air_sine = float(light.air_sine) if light is not None else float(unlit[1])
    out.disk_direction = wp.vec3(*np.asarray(light.disk_direction if light is not None else unlit).tolist())
    out.cos_radius, solid_angle = sun_disk(light.angular_diameter if light is not None else 0.0)
    disk = light.disk_irradiance / solid_angle if light is not None and out.cos_radius <= 1.0 else np.zeros(3)
    out.disk_radiance = wp.vec3(*np.asarray(disk, dtype=np.float64).tolist())
    out.lit = int(light is not None and light.lit)
    return out


def ground_struct(ground, camera_position) -> Ground:
    """Kernel view of a :class:`~warpsky.scene.model.Ground` seen from ``camera_position`` (None: a zero struct)."""
    out = Ground()
    out.offset = float(ground.height - camera_position[1]) if ground is not None else 0.0
    out.albedo = wp.vec3(*(ground.albedo if ground is not None else np.zeros(3)).tolist())
    return out


@wp.func
def camera_forward(cam: PinholeCamera) -> wp.vec3:
    """Unit world direction of the camera's view axis (its -Z)."""
    return wp.vec3(-cam.rotation[0, 2], -cam.rotation[1, 2], -cam.rotation[2, 2])


@wp.func
def camera_film_point(cam: PinholeCamera, row: int, col: int, fx: float, fy: float) -> wp.vec2:
    """Film-back (pinhole) or view-window (orthographic) position of the point (fx, fy) of pixel (row, col)."""
    sx = ((float(col) + fx) / float(cam.width) - 0.5) * cam.horizontal_aperture + cam.horizontal_offset
    sy = (0.5 - (float(row) + fy) / float(cam.height)) * cam.vertical_aperture + cam.vertical_offset
    return wp.vec2(sx, sy)


@wp.func
def camera_ray_at(cam: PinholeCamera, row: int, col: int, fx: float, fy: float) -> wp.vec3:
    """Unit world direction through the point (fx, fy) in [0, 1)^2 of pixel (row, col); fx right, fy down. An
    orthographic camera's rays all run along its view axis."""
    if cam.orthographic != 0:
        return camera_forward(cam)
    s = camera_film_point(cam, row, col, fx, fy)
    return wp.normalize(cam.rotation * wp.vec3(s[0], s[1], -cam.focal_length))


@wp.func
def camera_ray_origin(cam: PinholeCamera, row: int, col: int, fx: float, fy: float) -> wp.vec3:
    """Eye-relative start of the ray through the point (fx, fy) of pixel (row, col), in the plane through the eye
    across the view axis: the eye (zero) for a pinhole, the pixel's point of the view window for an orthographic
    camera. The ray is ``origin + t * camera_ray_at(...)``; it enters the clipping range at t = near / cos_axis
    and its depth is t * cos_axis in both projections."""
    if cam.orthographic == 0:
        return wp.vec3(0.0)
    s = camera_film_point(cam, row, col, fx, fy)
    return cam.rotation * wp.vec3(s[0], s[1], 0.0)


@wp.func
def camera_ray(cam: PinholeCamera, row: int, col: int) -> wp.vec3:
    """Unit world direction through the centre of pixel (row, col); row 0 is the top of the image."""
    return camera_ray_at(cam, row, col, 0.5, 0.5)


@wp.func
def one_minus_exp_over_x(x: float) -> float:
    """(1 - exp(-x)) / x, limit 1 at 0, by its Taylor series for |x| < 0.01 (truncation error < x^4/120, where the
    quotient would lose up to 1e-4 of its value to cancellation in float32). Negative x is fine: the air's optical
    depth along a descending ray grows as e^{-x} with x < 0."""
    if wp.abs(x) < 1.0e-2:
        return 1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0)))
    return (1.0 - wp.exp(-x)) / x


@wp.func
def one_minus_exp(tau: float) -> float:
    """1 - e^{-tau} for tau >= 0 without cancellation for tiny tau (float32 would lose it below ~1e-6)."""
    return tau * one_minus_exp_over_x(tau)


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
