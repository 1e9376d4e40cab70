"""Stratiform cloud layers and the ground's albedo texture as plain data (Bouthors 2006): a thickness map at a
base altitude over a horizontal extent, how it moves (Neyret 2003's advected textures, applied by
:mod:`warpsky.media.stratiform.thickness`), and the albedo map that the radiosity paints on the cloud base.

The USD prims are read by :mod:`warpsky.usd.stage` (attribute tables on :class:`StratiformLayer`,
:class:`ThicknessAdvection` and :class:`GroundTexture`). Any 2-D numpy array works as a thickness map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import SceneError


@dataclass(frozen=True)
class ThicknessAdvection:
    """How a layer's thickness map moves: a uniform wind plus seeded divergence-free curl noise, applied with
    Neyret's advected textures (3 staggered layers; frame t is computed on its own, see
    :mod:`warpsky.media.advection.advection`). The map is treated as periodic over the layer's extent.

    ============================================ ===== ================= ========== ===================================
    USD attribute (on the layer prim)            unit  default           range      meaning
    ============================================ ===== ================= ========== ===================================
    ``float2 warpsky:advection:wind``            m/s   (0, 0)            finite     uniform wind along world x and
                                                                                    world z (Z-up stage: x and -y)
    ``float warpsky:advection:curlSpeed``        m/s   0                 >= 0       rms speed of the curl noise; 0:
                                                                                    wind only
    ``float warpsky:advection:curlScale``        m     half the shorter  > 0,       wavelength of the largest eddies
                                                       side of the layer <= extent  (3 octaves, each half as large)
    ``float warpsky:advection:period``           s     300               > 0        lifetime of one advected layer
                                                                                    (about 1-2 strain times)
    ``int warpsky:advection:seed``               --    0                 any        curl-noise seed
    ============================================ ===== ================= ========== ===================================

    Authoring any ``warpsky:advection:*`` attribute animates the layer; time = timeCode / timeCodesPerSecond.
    Zero wind and zero curl speed show the static map at every time.
    """

    wind_m_s: tuple[float, float] = (0.0, 0.0)
    curl_speed_m_s: float = 0.0
    curl_scale_m: float | None = None
    period_s: float = 300.0
    seed: int = 0

    def __post_init__(self):
        wind = tuple(float(w) for w in np.asarray(self.wind_m_s, dtype=np.float64).reshape(-1))
        if len(wind) != 2 or not all(math.isfinite(w) for w in wind):
            raise SceneError(f"advection wind must be 2 finite speeds [m/s], got {self.wind_m_s!r}")
        object.__setattr__(self, "wind_m_s", wind)
        if not (math.isfinite(self.curl_speed_m_s) and self.curl_speed_m_s >= 0.0):
            raise SceneError(f"advection curlSpeed must be >= 0 m/s, got {self.curl_speed_m_s}")
        if self.curl_scale_m is not None and not (math.isfinite(self.curl_scale_m) and self.curl_scale_m > 0.0):
            raise SceneError(f"advection curlScale must be a positive length [m], got {self.curl_scale_m}")
        if not (math.isfinite(self.period_s) and self.period_s > 0.0):
            raise SceneError(f"advection period must be a positive duration [s], got {self.period_s}")

    @property
    def still(self) -> bool:
        """True when nothing moves (the advected map equals the static one)."""
        return self.curl_speed_m_s == 0.0 and self.wind_m_s == (0.0, 0.0)

    def __repr__(self) -> str:
        scale = "auto" if self.curl_scale_m is None else f"{self.curl_scale_m:g} m"
        return (f"ThicknessAdvection(wind={self.wind_m_s} m/s, curl={self.curl_speed_m_s:g} m/s at {scale}, "
                f"period={self.period_s:g} s, seed={self.seed})")


@dataclass(frozen=True)
class StratiformLayer:
    """A stratiform cloud layer.

    ============================================ ===== =============== ============================================
    USD attribute (on an ``Xform`` with          unit  default         meaning
    ``uniform token warpsky:kind =
    "stratiformLayer"``)
    ============================================ ===== =============== ============================================
    ``asset warpsky:stratiform:thicknessMap``    --    (procedural)    ``.npy`` (2-D, axis 0 = world x, axis 1 =
                                                                       world z), ``.exr`` (channel R or Y) or
                                                                       ``.png`` (rows = z, columns = x, 0..1)
    ``float warpsky:stratiform:thicknessScale``  m     1               map value -> thickness [m] (``.png``: the
                                                                       thickness of a white pixel), >= 0
    ``float2 warpsky:stratiform:size``           stage (1e4, 1e4) m    extent along x and z, centred on the prim
    ``float warpsky:stratiform:cover``           --    0.5             procedural map only: covered fraction [0, 1]
    ``float warpsky:stratiform:maxThickness``    m     500             procedural map only, >= 0
    ``int warpsky:stratiform:seed``              --    0               procedural map only
    ``float warpsky:stratiform:numberDensity``   1/m³  3e8             droplets N0 (extinction κ = N0 π r_e²), > 0
    ``float warpsky:stratiform:effectiveRadius`` m     7e-6            r_e > 0; the phase function stays the
                                                                       ``stratus`` species' (γ = 2, r_e = 7 µm)
    ``bool warpsky:stratiform:radiosity``        --    true            ground <-> cloud-base radiosity (§5) when a
                                                                       ground lies below; ``--set
                                                                       stratiform.radiosity=0|1`` overrides it
    ``warpsky:advection:*``                      --    (static)        see :class:`ThicknessAdvection`
    ============================================ ===== =============== ============================================

    The base altitude is the prim's world translation (y after the stage's up-axis conversion); rotation is
    ignored. A layer prim that is invisible or inactive is not rendered.

    Attributes:
        thickness: (nx, nz) float32 thickness [m] >= 0, axis 0 along world x, axis 1 along world z; texel (i, j)
            is the thickness at its centre, sampled bilinearly between centres, and a hole's edge runs halfway
            between clear and cloudy texel centres (see :mod:`warpsky.media.stratiform.thickness`). With ``advection``,
            the map at time 0 (the advected source).
        base_altitude: World y of the cloud base [m].
        origin: World (x, z) of the map's corner at texel (0, 0)'s outer edge [m].
        size: Extent (x, z) [m].
        number_density: N0 [1/m³].
        effective_radius: r_e [m].
        name: Prim path or label.
        radiosity: Whether the ground <-> cloud exchange runs for this layer.
        advection: How the map moves, or None for a static map.
        time_s: Time [s] at which the advected map is shown.
    """

    thickness: np.ndarray
    base_altitude: float
    origin: tuple[float, float]
    size: tuple[float, float]
    number_density: float = 3.0e8
    effective_radius: float = 7.0e-6
    name: str = "stratiform"
    radiosity: bool = True
    advection: ThicknessAdvection | None = None
    time_s: float = 0.0

    def __post_init__(self):
        t = np.asarray(self.thickness)
        if t.ndim != 2 or min(t.shape) < 2:
            raise SceneError(f"stratiform layer {self.name}: thickness map must be 2-D, at least 2x2, got {t.shape}")
        t = np.ascontiguousarray(t, dtype=np.float32)
        if not np.all(np.isfinite(t)) or t.min() < 0.0:
            raise SceneError(f"stratiform layer {self.name}: thickness must be finite and >= 0 m")
        object.__setattr__(self, "thickness", t)
        if not (math.isfinite(self.base_altitude)):
            raise SceneError(f"stratiform layer {self.name}: base altitude must be finite")
        if len(self.size) != 2 or not all(math.isfinite(s) and s > 0 for s in self.size):
            raise SceneError(f"stratiform layer {self.name}: size must be two positive lengths [m], got {self.size}")
        if not (self.number_density > 0 and self.effective_radius > 0):
            raise SceneError(f"stratiform layer {self.name}: numberDensity and effectiveRadius must be positive")
        if not math.isfinite(self.time_s):
            raise SceneError(f"stratiform layer {self.name}: time must be finite, got {self.time_s}")

    @property
    def extinction(self) -> float:
        """κ = N0 π r_e² [1/m]."""
        return self.number_density * math.pi * self.effective_radius**2

    @property
    def cover(self) -> float:
        """Fraction of texels with thickness > 0."""
        return float(np.mean(self.thickness > 0.0))

    def __repr__(self) -> str:
        moving = f", {self.advection!r} at t={self.time_s:g} s" if self.advection is not None else ""
        return (f"StratiformLayer({self.name!r}, map={self.thickness.shape}, base={self.base_altitude:g} m, "
                f"size={tuple(self.size)} m, cover={self.cover:.2f}, max={float(self.thickness.max()):g} m{moving})")


@dataclass(frozen=True)
class GroundTexture:
    """A ground albedo texture: (nx, nz, 3) reflectances in [0, 1] over ``size`` (x, z) [m] from ``origin``.

    ======================================= ===== ================ =============================================
    USD attribute (on the ``UsdGeomPlane``)  unit  default          meaning
    ======================================= ===== ================ =============================================
    ``asset warpsky:albedoMap``              --    (none)           ``.npy`` (nx, nz, 3), ``.exr`` (R, G, B) or
                                                                    ``.png`` (rows = z), values clipped to [0, 1]
    ``float2 warpsky:albedoMapSize``         stage (1e4, 1e4) m    extent along x and z, centred on the plane
    ======================================= ===== ================ =============================================

    Beyond the map its edge texels continue (clamped lookups). The stratiform pass (the ground under a layer and
    the radiosity) uses the map; the voxel techniques' ground uses the plane's uniform ``warpsky:albedo``.
    """

    albedo: np.ndarray
    origin: tuple[float, float]
    size: tuple[float, float]

    def __post_init__(self):
        a = np.ascontiguousarray(np.asarray(self.albedo, dtype=np.float32))
        if a.ndim != 3 or a.shape[2] != 3 or a.min() < 0 or a.max() > 1:
            raise SceneError(f"ground albedo map must be (nx, nz, 3) in [0, 1], got shape {a.shape}")
        object.__setattr__(self, "albedo", a)
