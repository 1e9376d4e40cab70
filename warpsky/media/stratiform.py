"""Stratiform cloud layers (Bouthors 2006): a thickness map at a base altitude over a horizontal extent, and the
ground's albedo texture that the radiosity paints on the cloud base.

=========================================== ===== =============== ==============================================
USD attribute (on an ``Xform`` with          unit  default         meaning
``uniform token warpsky:kind =
"stratiformLayer"``)
=========================================== ===== =============== ==============================================
``asset warpsky:stratiform:thicknessMap``    --    (procedural)    ``.npy`` (2-D, axis 0 = world x, axis 1 =
                                                                   world z), ``.exr`` (channel R or Y) or
                                                                   ``.png`` (rows = z, columns = x, 0..1)
``float warpsky:stratiform:thicknessScale``  m     1               map value -> thickness [m] (``.png``: the
                                                                   thickness of a white pixel)
``float2 warpsky:stratiform:size``           stage (1e4, 1e4)      extent along x and z, centred on the prim
``float warpsky:stratiform:cover``           --    0.5             procedural map only: covered fraction [0, 1]
``float warpsky:stratiform:maxThickness``    m     500             procedural map only
``int warpsky:stratiform:seed``              --    0               procedural map only
``float warpsky:stratiform:numberDensity``   1/m³  3e8             droplets N0 (extinction κ = N0 π r_e²)
``float warpsky:stratiform:effectiveRadius`` m     7e-6            r_e; the phase function stays the ``stratus``
                                                                   species' (γ = 2, r_e = 7 µm)
=========================================== ===== =============== ==============================================

The base altitude is the prim's world translation (y after the stage's up-axis conversion); rotation is ignored.
The ground texture sits on the ``UsdGeomPlane``: ``asset warpsky:albedoMap`` (``.npy`` (nx, nz, 3) or ``.png``) over
``float2 warpsky:albedoMapSize`` (stage units, centred on the plane's origin); outside it the plane's
``warpsky:albedo``.

Any 2-D numpy array works as a thickness map (e.g. an advected texture's state at time t, copied to the host).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.errors import SceneError


@dataclass(frozen=True)
class StratiformLayer:
    """A stratiform cloud layer.

    Attributes:
        thickness: (nx, nz) float32 thickness [m] >= 0, axis 0 along world x, axis 1 along world z; sampled
            bilinearly between texel centres.
        base_altitude: World y of the cloud base [m].
        origin: World (x, z) of the map's corner at texel (0, 0)'s outer edge [m].
        size: Extent (x, z) [m].
        number_density: N0 [1/m³].
        effective_radius: r_e [m].
        name: Prim path or label.
    """

    thickness: np.ndarray
    base_altitude: float
    origin: tuple[float, float]
    size: tuple[float, float]
    number_density: float = 3.0e8
    effective_radius: float = 7.0e-6
    name: str = "stratiform"

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
        if not all(math.isfinite(s) and s > 0 for s in self.size):
            raise SceneError(f"stratiform layer {self.name}: size must be positive, got {self.size}")
        if not (self.number_density > 0 and self.effective_radius > 0):
            raise SceneError(f"stratiform layer {self.name}: numberDensity and effectiveRadius must be positive")

    @property
    def extinction(self) -> float:
        """κ = N0 π r_e² [1/m]."""
        return self.number_density * math.pi * self.effective_radius**2

    @property
    def cover(self) -> float:
        """Fraction of texels with thickness > 0."""
        return float(np.mean(self.thickness > 0.0))

    def __repr__(self) -> str:
        return (f"StratiformLayer({self.name!r}, map={self.thickness.shape}, base={self.base_altitude:g} m, "
                f"size={tuple(self.size)} m, cover={self.cover:.2f}, max={float(self.thickness.max()):g} m)")


@dataclass(frozen=True)
class GroundTexture:
    """A ground albedo texture: (nx, nz, 3) reflectances in [0, 1] over ``size`` (x, z) [m] from ``origin``."""

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


def read_stratiform(reader, time=None) -> tuple[list[StratiformLayer], GroundTexture | None]:
    """Stratiform layers and the ground albedo texture on ``reader``'s stage (a :class:`StageReader`).

    Reads the prims documented in this module's docstring (kept here, next to the dataclasses, until the scene
    reader grows them).
    """
    from pxr import Usd, UsdGeom

    tc = _time_code(time)
    mpu = reader.meters_per_unit
    layers, texture = [], None
    for prim in Usd.PrimRange(reader.stage.GetPseudoRoot()):
        kind = prim.GetAttribute("warpsky:kind")
        world = reader._world(prim, tc) if prim.IsA(UsdGeom.Xformable) else None
        if kind and kind.Get(tc) == "stratiformLayer":
            def attr(name, default, prim=prim):
                a = prim.GetAttribute(f"warpsky:stratiform:{name}")
                return a.Get(tc) if a and a.HasAuthoredValue() else default

            size = np.asarray(attr("size", (1e4 / mpu, 1e4 / mpu)), dtype=np.float64) * mpu
            asset = attr("thicknessMap", None)
            if asset is not None and asset.resolvedPath:
                thickness = load_map(asset.resolvedPath) * float(attr("thicknessScale", 1.0))
            elif asset is not None and asset.path:
                raise SceneError(f"{prim.GetPath()}.warpsky:stratiform:thicknessMap: cannot find {asset.path}")
            else:
                thickness = procedural_thickness(256, cover=float(attr("cover", 0.5)),
                                                 max_thickness=float(attr("maxThickness", 500.0)),
                                                 seed=int(attr("seed", 0)))
            centre = world[:3, 3]
            layers.append(StratiformLayer(
                thickness, float(centre[1]), (float(centre[0] - size[0] / 2), float(centre[2] - size[1] / 2)),
                (float(size[0]), float(size[1])), float(attr("numberDensity", 3e8)),
                float(attr("effectiveRadius", 7e-6)), str(prim.GetPath())))
        elif prim.IsA(UsdGeom.Plane):
            a = prim.GetAttribute("warpsky:albedoMap")
            if a and a.HasAuthoredValue():
                asset = a.Get(tc)
                if not asset.resolvedPath:
                    raise SceneError(f"{prim.GetPath()}.warpsky:albedoMap: cannot find {asset.path}")
                s = prim.GetAttribute("warpsky:albedoMapSize")
                size = np.asarray(s.Get(tc) if s else (1e4 / mpu, 1e4 / mpu), dtype=np.float64) * mpu
                centre = world[:3, 3]
                texture = GroundTexture(np.clip(load_map(asset.resolvedPath, channels=3), 0.0, 1.0),
                                        (float(centre[0] - size[0] / 2), float(centre[2] - size[1] / 2)),
                                        (float(size[0]), float(size[1])))
    return layers, texture


def _time_code(time):
    from pxr import Usd

    return Usd.TimeCode.EarliestTime() if time is None else Usd.TimeCode(float(time))
