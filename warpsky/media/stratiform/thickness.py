"""Stratiform cloud layers at work (Bouthors 2006): procedural and file thickness maps, how a map is sampled, and
the map at a time, advected by wind and curl noise (Neyret 2003, :mod:`warpsky.media.advection.advection`).

Texel footprint: texel (i, j) of an (nx, nz) map over ``size`` from ``origin`` is the thickness at its centre,
``origin + ((i + 0.5) sx / nx, (j + 0.5) sz / nz)``; between centres the thickness is bilinear, the outer half
texel keeps the edge texel's value and outside the map it is 0. A clear texel (0 m) next to cloudy ones first
takes minus their mean (:func:`signed_thickness`) and the bilinear value is clamped at 0, so a hole's outline
runs halfway between clear and cloudy texel centres, crossing texels diagonally where the field does, instead of
along the edges of the clear texels' squares.

The layers themselves (:class:`StratiformLayer`, :class:`ThicknessAdvection`, :class:`GroundTexture`) are plain
data in :mod:`warpsky.model.stratiform`, re-exported here; :mod:`warpsky.usd.stage` reads them from USD prims.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.stratiform import GroundTexture, StratiformLayer, ThicknessAdvection
from warpsky.output.exr import read_exr

__all__ = ["PROCEDURAL_RESOLUTION", "GroundTexture", "StratiformLayer", "ThicknessAdvection", "at_time",
           "load_map", "procedural_thickness", "sample_thickness", "signed_thickness", "thickness_at_time"]

#: Texels per side of the procedural map a layer prim without ``thicknessMap`` gets.
PROCEDURAL_RESOLUTION = 256


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
        image = read_exr(path)
        names = ("R", "G", "B") if channels == 3 else ("R" if "R" in image.channels else "Y",)
        data = np.stack([image.channels[n] for n in names], axis=-1).swapaxes(0, 1)
        data = data[..., 0] if channels == 1 else data
    elif suffix == ".png":
        from PIL import Image  # Pillow loads only when a .png map is read

        image = np.asarray(Image.open(path).convert("RGB" if channels == 3 else "L"), dtype=np.float32) / 255.0
        data = image.swapaxes(0, 1)
    else:
        raise SceneError(f"map {path}: expected .npy, .exr or .png, got {suffix!r}")
    data = np.asarray(data, dtype=np.float32)
    if channels == 1 and data.ndim != 2 or channels == 3 and (data.ndim != 3 or data.shape[2] != 3):
        raise SceneError(f"map {path}: expected {'(nx, nz)' if channels == 1 else '(nx, nz, 3)'}, got {data.shape}")
    return data


# ------------------------------------------------------------------------------------------------- sampling
def signed_thickness(thickness: np.ndarray) -> np.ndarray:
    """The (nx, nz) map [m] extended into its holes for bilinear sampling: every clear texel with cloudy neighbours
    along the axes takes minus their mean thickness (with cloudy neighbours only diagonally, minus theirs), so the
    interpolated thickness crosses 0 halfway between a cloudy and a clear texel centre. Cloudy texels and clear
    texels away from any cloud keep their values."""
    cloudy = thickness > 0.0
    values = np.where(cloudy, thickness, 0.0).astype(np.float64)
    padded, weights = np.pad(values, 1), np.pad(cloudy.astype(np.float64), 1)
    nx, nz = values.shape

    def neighbours(offsets):
        total, count = np.zeros_like(values), np.zeros_like(values)
        for di, dj in offsets:
            total += padded[1 + di:1 + di + nx, 1 + dj:1 + dj + nz]
            count += weights[1 + di:1 + di + nx, 1 + dj:1 + dj + nz]
        return total, count

    side_total, side_count = neighbours(((1, 0), (-1, 0), (0, 1), (0, -1)))
    corner_total, corner_count = neighbours(((1, 1), (1, -1), (-1, 1), (-1, -1)))
    out = values.copy()
    side = ~cloudy & (side_count > 0)
    out[side] = -side_total[side] / side_count[side]
    corner = ~cloudy & (side_count == 0) & (corner_count > 0)
    out[corner] = -corner_total[corner] / corner_count[corner]
    return out.astype(np.float32)


def sample_thickness(signed: np.ndarray, origin, size, xs: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """Thickness [m] at world points (``xs``, ``zs``) from a :func:`signed_thickness` map placed at ``origin`` with
    extent ``size``: bilinear between texel centres, clamped at 0, 0 outside the map (as the kernels sample it)."""
    nx, nz = signed.shape
    u = np.clip((xs - origin[0]) / size[0] * nx - 0.5, 0.0, nx - 1)
    v = np.clip((zs - origin[1]) / size[1] * nz - 0.5, 0.0, nz - 1)
    i0 = np.minimum(u.astype(int), nx - 2)
    j0 = np.minimum(v.astype(int), nz - 2)
    fu, fv = u - i0, v - j0
    value = ((signed[i0, j0] * (1 - fu) + signed[i0 + 1, j0] * fu) * (1 - fv)
             + (signed[i0, j0 + 1] * (1 - fu) + signed[i0 + 1, j0 + 1] * fu) * fv)
    inside = (xs >= origin[0]) & (xs <= origin[0] + size[0]) & (zs >= origin[1]) & (zs <= origin[1] + size[1])
    return np.where(inside, np.maximum(value, 0.0), 0.0)


# ---------------------------------------------------------------------------------------------- advected maps
#: Advected textures kept between frames (sequential playback reuses their whole steps; pixels are the same either
#: way): key -> AdvectedTexture, least recently used first.
_ADVECTED: OrderedDict = OrderedDict()
_ADVECTED_MAX = 4


def _advected_texture(layer: StratiformLayer, device: str):
    from warpsky.media.advection.advection import AdvectedTexture, Flow2D  # its kernels load for advected maps only

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
    if layer.advection is None:
        return layer
    return dataclasses.replace(layer, thickness=thickness_at_time(layer, device), advection=None)


def layer_sun_transmittance(layer: StratiformLayer, points: np.ndarray, sun_direction, device: str = "cpu"
                            ) -> np.ndarray:
    """(N, 3) transmittance of the direct sunlight through ``layer`` at world ``points`` (N, 3) [m] below its
    base: exp(-kappa t / sin e), t the thickness where the ray towards the sun pierces the cloud base (a locally
    flat slab crossed at the sun's elevation e; Max 1986's shadow rule with the slant path). Points above the base,
    and a sun at or below the horizon, are not dimmed; the light the layer scatters down is not included."""
    points = np.asarray(points, dtype=np.float64)
    out = np.ones((len(points), 3))
    sun = np.asarray(sun_direction, dtype=np.float64)
    if sun[1] <= 0.0 or not len(points):
        return out
    resolved = at_time(layer, device)
    below = points[:, 1] < layer.base_altitude
    reach = (layer.base_altitude - points[below, 1]) / sun[1]
    pierce = points[below] + reach[:, None] * sun
    thickness = sample_thickness(signed_thickness(resolved.thickness), layer.origin, layer.size,
                                 pierce[:, 0], pierce[:, 2])
    out[below] = np.exp(-layer.extinction * thickness / sun[1])[:, None]
    return out
