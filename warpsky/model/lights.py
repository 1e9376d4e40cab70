"""Lights: the sun (a distant light with a disk) and the dome (light from all around, uniform or a lat-long map)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.checks import _vec3


@dataclass(frozen=True)
class Sun:
    """A distant light source.

    Attributes:
        direction: Unit vector in world space pointing **towards** the sun.
        irradiance: RGB irradiance at normal incidence [W/m^2 per channel, or the stage's light units].
        angular_diameter: Angular diameter of the disk [rad] (USD ``inputs:angle`` is in degrees).
        name: Prim path or label.
        transmittance: RGB transmittance of the air between the top of the atmosphere and what the sun lights,
            in [0, 1]: ones as read from a stage; a frame whose air is drawn by a pass sets it once for its media
            (:class:`~warpsky.light.frame.FrameLight`), so ``irradiance`` always stays the light above the air.
    """

    direction: np.ndarray
    irradiance: np.ndarray
    angular_diameter: float = math.radians(0.53)
    name: str = "sun"
    transmittance: np.ndarray = field(default_factory=lambda: np.ones(3))

    def __post_init__(self):
        object.__setattr__(self, "direction", _vec3(self.direction, f"sun {self.name}: direction", unit=True))
        irr = _vec3(self.irradiance, f"sun {self.name}: irradiance")
        if np.any(irr < 0.0):
            raise SceneError(f"sun {self.name}: irradiance must be non-negative, got {irr.tolist()}")
        object.__setattr__(self, "irradiance", irr)
        through = _vec3(self.transmittance, f"sun {self.name}: transmittance")
        if np.any(through < 0.0) or np.any(through > 1.0):
            raise SceneError(f"sun {self.name}: transmittance must lie in [0, 1], got {through.tolist()}")
        object.__setattr__(self, "transmittance", through)
        if not (math.isfinite(self.angular_diameter) and 0.0 <= self.angular_diameter < math.pi):
            raise SceneError(f"sun {self.name}: angular diameter must lie in [0, pi) rad, got {self.angular_diameter}")

    @property
    def elevation(self) -> float:
        """Angle of the sun above the horizon [rad]; negative below it."""
        return math.asin(max(-1.0, min(1.0, float(self.direction[1]))))


@dataclass(frozen=True)
class Dome:
    """Light from a distant environment all around the scene (``UsdLuxDomeLight``): radiance per direction.

    The radiance towards world direction ``d`` is ``color`` times, with a texture, the texture's bilinear value
    there. The texture is a latitude-longitude map in OpenEXR's convention (which UsdLux adopts for DomeLight): in
    the dome's own frame +Y is the upper pole, the image's top row latitude +pi/2 and bottom row -pi/2, its left
    column longitude +pi and right column -pi, longitude 0 (the image centre) along +Z and +pi/2 along +X. Pixel
    centres sit exactly at those extremes (x = (W-1)/2 - lon (W-1)/(2 pi), y = (H-1)/2 - lat (H-1)/pi).

    Attributes:
        color: RGB radiance scale [the sun's irradiance units per sr]: ``inputs:color`` x ``inputs:intensity`` x
            2^``inputs:exposure`` (x the blackbody colour with ``inputs:enableColorTemperature``).
        texture: (H, W, 3) float32 lat-long image (``inputs:texture:file``), or None for a uniform dome.
        rotation: 3x3 world-from-dome rotation (the prim's transform and the stage's up axis, scale removed).
        name: Prim path or label.
        source: The texture file, for messages.
    """

    color: np.ndarray
    texture: np.ndarray | None = None
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = "dome"
    source: str = ""

    def __post_init__(self):
        color = _vec3(self.color, f"dome {self.name}: color")
        if np.any(color < 0.0):
            raise SceneError(f"dome {self.name}: color x intensity x 2^exposure must be >= 0, got {color.tolist()}")
        object.__setattr__(self, "color", color)
        rot = np.asarray(self.rotation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise SceneError(f"dome {self.name}: rotation must be an orthonormal right-handed 3x3 matrix")
        object.__setattr__(self, "rotation", rot)
        if self.texture is not None:
            tex = np.ascontiguousarray(self.texture, dtype=np.float32)
            if tex.ndim != 3 or tex.shape[2] != 3 or min(tex.shape[:2]) < 1:
                raise SceneError(f"dome {self.name}: texture {self.source} must be an (H, W, RGB) image, "
                                 f"got shape {tex.shape}")
            if not np.all(np.isfinite(tex)) or np.any(tex < 0.0):
                raise SceneError(f"dome {self.name}: texture {self.source} must hold finite values >= 0")
            object.__setattr__(self, "texture", tex)

    @property
    def active(self) -> bool:
        """Whether the dome gives any light (a black dome is treated as no dome)."""
        lit = float(np.max(self.color)) > 0.0
        return lit and (self.texture is None or float(np.max(self.texture)) > 0.0)

    def radiance(self, direction) -> np.ndarray:
        """Radiance [.., 3] arriving from world ``direction`` [.., 3] (unit vectors; any leading shape)."""
        d = np.asarray(direction, dtype=np.float64)
        if self.texture is None:
            return np.broadcast_to(self.color, d.shape).copy()
        local = d @ self.rotation  # dome-from-world applied to row vectors
        height, width = self.texture.shape[:2]
        lat = np.arcsin(np.clip(local[..., 1], -1.0, 1.0))
        lon = np.arctan2(local[..., 0], local[..., 2])
        x = np.clip(0.5 * (width - 1) - lon * (width - 1) / (2.0 * math.pi), 0.0, width - 1)
        y = np.clip(0.5 * (height - 1) - lat * (height - 1) / math.pi, 0.0, height - 1)
        x0, y0 = np.minimum(np.floor(x).astype(int), width - 1), np.minimum(np.floor(y).astype(int), height - 1)
        x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
        fx, fy = (x - x0)[..., None], (y - y0)[..., None]
        tex = self.texture  # gathered texels become float64 in the weighting (no copy of the whole map)
        top = tex[y0, x0] * (1.0 - fx) + tex[y0, x1] * fx
        bottom = tex[y1, x0] * (1.0 - fx) + tex[y1, x1] * fx
        return self.color * (top * (1.0 - fy) + bottom * fy)
