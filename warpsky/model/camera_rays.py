"""The camera as kernels see it, and the rays every kernel starts from: pinhole or orthographic, conformed to the
image, positions relative to the eye (which sits at the origin of every kernel's coordinates)."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.model.scene import Camera, Projection


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
    opaque: wp.array2d(dtype=float)  # per pixel, the depth [m along the view axis] of the nearest opaque surface
    has_opaque: int  # 1: camera rays end at ``opaque`` (a surface another pass draws), 0: at the far clip

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
    opaque = camera.opaque_depth
    if opaque is not None and tuple(opaque.shape) == (int(height), int(width)):
        cam.opaque = opaque
        cam.has_opaque = 1
    return cam


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

@wp.struct
class PrimaryRay:
    """A camera ray within the clipping range: ``origin + t * direction`` for t_near <= t <= t_far [m]; the point
    at t lies at depth t * cos_axis along the view axis."""

    direction: wp.vec3  # unit, world
    origin: wp.vec3  # eye-relative start [m]: zero for a pinhole, the view window's point for an orthographic camera
    cos_axis: float  # cosine between the direction and the view axis
    t_near: float  # [m] along the ray to the near clipping plane
    t_far: float  # [m] along the ray to the far clipping plane


@wp.func
def primary_ray(cam: PinholeCamera, row: int, col: int, fx: float, fy: float) -> PrimaryRay:
    """The ray through the point (fx, fy) in [0, 1)^2 of pixel (row, col) (fx right, fy down; 0.5, 0.5 is its
    centre) and the distances along it to the clipping planes."""
    out = PrimaryRay()
    out.direction = camera_ray_at(cam, row, col, fx, fy)
    out.origin = camera_ray_origin(cam, row, col, fx, fy)
    out.cos_axis = wp.dot(out.direction, camera_forward(cam))
    out.t_near = cam.near / out.cos_axis
    out.t_far = cam.far / out.cos_axis
    if cam.has_opaque != 0:
        out.t_far = wp.max(wp.min(cam.far, cam.opaque[row, col]), cam.near) / out.cos_axis
    return out
