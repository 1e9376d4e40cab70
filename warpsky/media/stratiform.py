"""Stratiform cloud layers (Bouthors 2006): a thickness map at a base altitude over a horizontal extent, optionally
advected by wind and curl noise (Neyret 2003, :mod:`warpsky.media.advection`), and the ground's albedo texture that
the radiosity paints on the cloud base.

The USD prims are read by :mod:`warpsky.scene.usd` (attribute tables on :class:`StratiformLayer`,
:class:`ThicknessAdvection` and :class:`GroundTexture`). Any 2-D numpy array works as a thickness map.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.errors import SceneError

#: Texels per side of the procedural map a layer prim without ``thicknessMap`` gets.
PROCEDURAL_RESOLUTION = 256


@dataclass(frozen=True)
class ThicknessAdvection:
    """How a layer's thickness map moves: a uniform wind plus seeded divergence-free curl noise, applied with
    Neyret's advected textures (3 staggered layers; frame t is computed on its own, see
    :mod:`warpsky.media.advection`). The map is treated as periodic over the layer's extent.

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
        thickness: (nx, nz) float32 thickness [m] >= 0, axis 0 along world x, axis 1 along world z; sampled
            bilinearly between texel centres. With ``advection``, the map at time 0 (the advected source).
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


def procedural_thickness(resolution: int, *, cover: float = 0.5, max_thickness: float = 500.0, seed: int = 0,
                         feature_texels: float = 24.0) -> np.ndarray:
    """Stratocumulus-like thickness map: band-limited noise, thresholded so that ``cover`` of the texels are
    cloudy, rising smoothly from 0 at the cloud edges to ``max_thickness`` [m]."""
    if not 0.0 <= cover <= 1.0:
        raise SceneError(f"cover must lie in [0, 1], got {cover}")
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((resolution, resolution))
    k = np.fft.fftfreq(resolution)
    kk = np.sqrt(k[:, None] ** 2 + k[None, :] ** 2)
    spectrum = np.exp(-(kk * feature_texels) ** 2) + 0.35 * np.exp(-(kk * feature_texels / 4) ** 2)
    field = np.real(np.fft.ifft2(np.fft.fft2(noise) * spectrum))
    field = (field - field.mean()) / (field.std() + 1e-30)
    if cover <= 0.0:
        return np.zeros((resolution, resolution), np.float32)
    if cover >= 1.0:
        shifted = field - field.min()
        return (max_thickness * (0.2 + 0.8 * shifted / max(shifted.max(), 1e-30))).astype(np.float32)
    level = np.quantile(field, 1.0 - cover)
    above = np.maximum(field - level, 0.0)
    return (max_thickness * np.tanh(above / max(above.max(), 1e-30) * 2.0) / np.tanh(2.0)).astype(np.float32)


def load_map(path: str | Path, *, channels: int = 1) -> np.ndarray:
    """Read a ``.npy``, ``.exr`` or ``.png`` map as float32 (nx, nz) or (nx, nz, 3) with axis 0 = world x."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"map file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        data = np.load(path)
    elif suffix == ".exr":
        from warpsky.output.exr import read_exr

        image = read_exr(path)
        names = ("R", "G", "B") if channels == 3 else ("R" if "R" in image.channels else "Y",)
        data = np.stack([image.channels[n] for n in names], axis=-1).swapaxes(0, 1)
        data = data[..., 0] if channels == 1 else data
    elif suffix == ".png":
        from PIL import Image

        image = np.asarray(Image.open(path).convert("RGB" if channels == 3 else "L"), dtype=np.float32) / 255.0
        data = image.swapaxes(0, 1)
    else:
        raise SceneError(f"map {path}: expected .npy, .exr or .png, got {suffix!r}")
    data = np.asarray(data, dtype=np.float32)
    if channels == 1 and data.ndim != 2 or channels == 3 and (data.ndim != 3 or data.shape[2] != 3):
        raise SceneError(f"map {path}: expected {'(nx, nz)' if channels == 1 else '(nx, nz, 3)'}, got {data.shape}")
    return data


# ---------------------------------------------------------------------------------------------- advected maps
#: Advected textures kept between frames (sequential playback reuses their whole steps; pixels are the same either
#: way): key -> AdvectedTexture, least recently used first.
_ADVECTED: OrderedDict = OrderedDict()
_ADVECTED_MAX = 4


def _advected_texture(layer: StratiformLayer, device: str):
    from warpsky.media.advection import AdvectedTexture, Flow2D

    adv = layer.advection
    digest = hashlib.sha1(layer.thickness.tobytes()).hexdigest()
    key = (layer.name, digest, layer.thickness.shape, tuple(layer.size), adv, str(device))
    texture = _ADVECTED.get(key)
    if texture is not None:
        _ADVECTED.move_to_end(key)
        return texture
    extent = (float(layer.size[0]), float(layer.size[1]))
    try:
        if adv.curl_speed_m_s == 0.0:
            flow = Flow2D.still(extent, wind_m_s=adv.wind_m_s)
        else:
            flow = Flow2D.procedural(extent, wind_m_s=adv.wind_m_s, speed_m_s=adv.curl_speed_m_s,
                                     scale_m=adv.curl_scale_m, octaves=3, resolution=(64, 64), seed=int(adv.seed))
        # the advection module's textures are (ny, nx) with x along columns: world z is its y
        texture = AdvectedTexture(layer.thickness.T, extent, flow, layers=3, period_s=adv.period_s, device=device)
    except ValueError as exc:
        raise SceneError(f"stratiform layer {layer.name}: advection: {exc}") from None
    _ADVECTED[key] = texture
    while len(_ADVECTED) > _ADVECTED_MAX:
        _ADVECTED.popitem(last=False)
    return texture


def thickness_at_time(layer: StratiformLayer, device: str = "cpu") -> np.ndarray:
    """The layer's (nx, nz) thickness map [m] at ``layer.time_s``: the static map, or the advected one (clamped at
    0 m: the contrast-preserving blend may dip below it next to cloud edges). A fresh array the caller owns."""
    if layer.advection is None:
        return layer.thickness.copy()
    advected = _advected_texture(layer, device).at(layer.time_s)
    return np.ascontiguousarray(np.maximum(advected.numpy().T, 0.0), dtype=np.float32)  # copy: .at reuses it


def at_time(layer: StratiformLayer, device: str = "cpu") -> StratiformLayer:
    """``layer`` with its thickness map resolved at its time and no advection left to apply."""
    import dataclasses

    if layer.advection is None:
        return layer
    return dataclasses.replace(layer, thickness=thickness_at_time(layer, device), advection=None)
