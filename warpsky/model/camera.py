"""The camera: pinhole or orthographic, conformed to the image, and the matrices EXR headers carry.

World space is warpsky's: Y up, metres (the stage's up axis and units already converted).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.checks import _vec3


class Projection(enum.Enum):
    """How a camera maps the world onto its image; values are USD's ``projection`` tokens."""

    PERSPECTIVE = "perspective"
    ORTHOGRAPHIC = "orthographic"


@dataclass(frozen=True)
class Camera:
    """A camera looking down its local -Z with +Y up; image row 0 is the top.

    A perspective camera is a pinhole at ``position``. An orthographic camera sends every ray along its view axis,
    from the pixel's point of a view window centred on ``position`` across that axis; its apertures and offsets are
    the window's size and shift in metres (USD's apertures, in tenths of a scene unit, are the view's extent).

    Attributes:
        name: Prim path or label, used in messages and metadata.
        position: Eye position in world metres, float64 (kept exact for scenes far from the origin).
        rotation: 3x3 world-from-camera rotation; columns are the camera's right, up and back axes.
        focal_length: Focal length [m of film-back units; only ratios to the apertures matter; unused when
            orthographic].
        horizontal_aperture: Film-back width, same units as ``focal_length`` (orthographic: view width [m]).
        vertical_aperture: Film-back height, same units as ``focal_length`` (orthographic: view height [m]).
        horizontal_aperture_offset: Film-back shift to the right, same units.
        vertical_aperture_offset: Film-back shift up, same units.
        near: Near clipping distance along the view axis [m].
        far: Far clipping distance along the view axis [m].
        projection: :class:`Projection`, perspective by default (USD ``token projection``).
        pixel_aspect: Width / height of an image pixel as displayed (RenderSettings ``pixelAspectRatio``): the
            film back is conformed to ``width * pixel_aspect / height``.
        shutter: (open, close) of the shutter in frames relative to the frame's time code (USD's
            ``shutter:open`` / ``shutter:close``; equal: no motion blur).
        opaque_depth: None, or a Warp (height, width) array of the depth [m along the view axis] of the nearest
            opaque surface per pixel, which a pass in front of the media drew: camera rays of the kernels end there
            (:func:`~warpsky.model.camera_rays.primary_ray`). Set for one frame by the media pass; not compared.
    """

    name: str
    position: np.ndarray
    rotation: np.ndarray
    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    horizontal_aperture_offset: float = 0.0
    vertical_aperture_offset: float = 0.0
    near: float = 0.1
    far: float = 1.0e6
    projection: Projection = Projection.PERSPECTIVE
    pixel_aspect: float = 1.0
    shutter: tuple[float, float] = (0.0, 0.0)
    opaque_depth: object = dataclasses.field(default=None, compare=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec3(self.position, f"camera {self.name}: position"))
        try:
            object.__setattr__(self, "projection", Projection(self.projection))
        except ValueError:
            raise SceneError(f"camera {self.name}: projection must be 'perspective' or 'orthographic', "
                             f"got {self.projection!r}") from None
        rot = np.asarray(self.rotation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
            raise SceneError(f"camera {self.name}: rotation must be a finite 3x3 matrix")
        if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise SceneError(f"camera {self.name}: rotation must be orthonormal and right-handed")
        object.__setattr__(self, "rotation", rot)
        for attr in ("focal_length", "horizontal_aperture", "vertical_aperture", "pixel_aspect"):
            value = getattr(self, attr)
            if not (math.isfinite(value) and value > 0.0):
                raise SceneError(f"camera {self.name}: {attr} must be positive, got {value}")
        if not (math.isfinite(self.near) and self.near > 0.0):
            raise SceneError(f"camera {self.name}: near clipping distance must be positive, got {self.near}")
        if not (self.far > self.near):
            raise SceneError(
                f"camera {self.name}: clipping range must have near < far, got near={self.near}, far={self.far}"
            )

    @property
    def forward(self) -> np.ndarray:
        """Unit view direction (the camera's -Z) in world space."""
        return -self.rotation[:, 2]

    def conformed(self, width: int, height: int) -> Camera:
        """Return this camera with its film back grown to the image aspect ratio (CameraUtil's "fit" policy).

        The authored window stays entirely in view; one aperture is enlarged so that
        ``horizontal_aperture / vertical_aperture == width * pixel_aspect / height``.
        """
        aspect = width * self.pixel_aspect / height
        h_ap, v_ap = self.horizontal_aperture, self.vertical_aperture
        if h_ap / v_ap > aspect:
            v_ap = h_ap / aspect
        else:
            h_ap = v_ap * aspect
        return dataclasses.replace(self, horizontal_aperture=h_ap, vertical_aperture=v_ap)

    def pixel_direction(self, x: float, y: float, width: int, height: int) -> np.ndarray:
        """World-space unit ray direction through image position (x, y) in pixels (row 0 at the top).

        Pixel centres sit at half-integers. The camera should already be conformed to (width, height). An
        orthographic camera's rays all run along :attr:`forward`.
        """
        if self.projection is Projection.ORTHOGRAPHIC:
            return self.forward
        sx = (x / width - 0.5) * self.horizontal_aperture + self.horizontal_aperture_offset
        sy = (0.5 - y / height) * self.vertical_aperture + self.vertical_aperture_offset
        d = self.rotation @ np.array([sx, sy, -self.focal_length])
        return d / np.linalg.norm(d)

    def world_to_camera(self, *, left_handed: bool = False) -> np.ndarray:
        """4x4 float64 matrix from warpsky world space (Y up, metres: the stage's up axis and units already
        converted) to camera space, for column vectors: ``p_cam = M @ (x, y, z, 1)``.

        Camera space has the eye at the origin, +X right and +Y up in the image and, right-handed, the view along
        -Z (USD's, Arnold's and Cycles' camera space). ``left_handed=True`` gives the space of OpenEXR's
        ``worldToCamera`` standard attribute instead, RenderMan's: the same with z negated, so that points in front
        of the camera have z > 0. Headers store Imath's row-vector transpose (:func:`as_imath_rows`) in float32,
        which keeps a translation 100 km long to about 1 cm.
        """
        m = np.eye(4)
        m[:3, :3] = self.rotation.T
        m[:3, 3] = -(self.rotation.T @ self.position)
        if left_handed:
            m[2] = -m[2]
        return m

    def world_to_ndc(self, width: int, height: int) -> np.ndarray:
        """4x4 float64 projective matrix from warpsky world space (as :meth:`world_to_camera`) to the normalised
        device coordinates of a ``width`` x ``height`` image, for column vectors, before the homogeneous divide.

        NDC is OpenEXR's ``worldToNDC`` standard attribute's (RenderMan's): after dividing by w, x runs right and y
        down, with (0, 0) the top-left and (1, 1) the bottom-right corner of the image (the display window; this
        camera conformed to it), so pixel (row, col)'s centre is ((col + 0.5) / width, (row + 0.5) / height).
        OpenEXR discards z; here z / w is 0 on the near and 1 on the far clipping plane. w is the distance along
        the view axis (perspective) or 1 (orthographic).
        """
        cam = self.conformed(width, height)
        h_ap, v_ap = cam.horizontal_aperture, cam.vertical_aperture
        h_shift, v_shift = cam.horizontal_aperture_offset / h_ap, cam.vertical_aperture_offset / v_ap
        near, far = cam.near, cam.far
        if cam.projection is Projection.ORTHOGRAPHIC:
            projection = np.array([
                [1.0 / h_ap, 0.0, 0.0, 0.5 - h_shift],
                [0.0, -1.0 / v_ap, 0.0, 0.5 + v_shift],
                [0.0, 0.0, -1.0 / (far - near), -near / (far - near)],
                [0.0, 0.0, 0.0, 1.0],
            ])
        else:
            focal = cam.focal_length
            projection = np.array([
                [focal / h_ap, 0.0, h_shift - 0.5, 0.0],
                [0.0, -focal / v_ap, -0.5 - v_shift, 0.0],
                [0.0, 0.0, -far / (far - near), -far * near / (far - near)],
                [0.0, 0.0, -1.0, 0.0],
            ])
        return projection @ self.world_to_camera()


def as_imath_rows(matrix: np.ndarray) -> np.ndarray:
    """The 4x4 transpose of a column-vector matrix (:meth:`Camera.world_to_camera`, :meth:`Camera.world_to_ndc`):
    Imath's M44f multiplies row vectors (``p' = p M``), so this is what an EXR header's M44f attribute holds, row
    by row (flattened, the 16 values in Imath's ``x[i][j]`` order)."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"expected a 4x4 matrix, got shape {m.shape}")
    return m.T.copy()
