"""Lights from ``UsdLux`` prims: every visible ``DistantLight`` as a :class:`~warpsky.model.scene.Sun` (the first is
the scene's sun, the others its ``extra_suns``) and the first visible ``DomeLight`` as the
:class:`~warpsky.model.scene.Dome`, with its optional lat-long EXR texture.

A light's colour is ``inputs:color`` x ``inputs:intensity`` x 2^``inputs:exposure``, times the blackbody colour of
``inputs:colorTemperature`` when ``inputs:enableColorTemperature`` is set. pxr and OpenEXR are imported inside the
methods (heavy imports).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.scene import Dome, Sun
from warpsky.usd.prims import StagePrims

#: ``inputs:texture:format`` values read as a latitude-longitude map.
LATLONG_FORMATS = ("automatic", "latlong")


#: The first bytes of an OpenEXR file.
EXR_MAGIC = b"\x76\x2f\x31\x01"


def read_latlong(path: Path, where: str) -> np.ndarray:
    """(H, W, 3) float32 RGB of the lat-long image at ``path``: an EXR through OpenEXR (a missing Y/A is fine;
    missing R, G or B is an error), any other format through OpenImageIO (Radiance .hdr, TIFF/.tx, PNG, ...),
    the first three channels as RGB. A format neither reads is refused by name, not as an unreadable file."""
    if not path.is_file():
        raise SceneError(f"{where}: texture file {path} does not exist")
    with open(path, "rb") as f:
        head = f.read(4)
    if head == EXR_MAGIC:
        return read_latlong_exr(path, where)
    try:
        import OpenImageIO as oiio
    except ImportError:
        raise SceneError(f"{where}: texture file {path} is not an EXR; other formats (Radiance .hdr, TIFF/.tx, "
                         "...) are read through OpenImageIO: pip install 'warpsky[textures]'") from None
    image = oiio.ImageInput.open(str(path))
    if image is None:
        reason = oiio.geterror().split("?")[0].strip() or "unknown format"
        raise SceneError(f"{where}: texture file {path} is in a format warpsky cannot read ({reason}); expected a "
                         "lat-long EXR, Radiance .hdr or another format OpenImageIO reads (RenderMan .tex: convert "
                         "it with txmake or maketx to .exr/.tx)")
    try:
        spec = image.spec()
        pixels = image.read_image(format="float")
    finally:
        image.close()
    if pixels is None or spec.nchannels < 3:
        raise SceneError(f"{where}: texture file {path} has {spec.nchannels} channel(s); expected RGB")
    return np.ascontiguousarray(np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, -1)[..., :3])


def read_latlong_exr(path: Path, where: str) -> np.ndarray:
    """(H, W, 3) float32 RGB of the EXR at ``path`` (a missing Y/A is fine; missing R, G or B is an error)."""
    import OpenEXR

    if not path.is_file():
        raise SceneError(f"{where}: texture file {path} does not exist")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.asarray(ch.pixels, dtype=np.float32) for name, ch in exr.channels().items()}
    except Exception as exc:  # the bindings raise RuntimeError, but also other types on damaged data
        raise SceneError(f"{where}: cannot read texture file {path}: {exc}") from None
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise SceneError(f"{where}: texture file {path} has no {', '.join(missing)} channel(s); expected RGB, "
                         f"found {', '.join(sorted(channels)) or 'none'}")
    return np.stack([channels[c] for c in "RGB"], axis=-1)


def _mtime(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


class LightReading(StagePrims):
    """The stage reader's lights."""

    def _light_color(self, light, prim, tc) -> np.ndarray:
        """color x intensity x 2^exposure (x blackbody), checked finite and >= 0."""
        from pxr import UsdLux

        intensity = float(light.GetIntensityAttr().Get(tc))
        exposure = float(light.GetExposureAttr().Get(tc))
        color = np.array(light.GetColorAttr().Get(tc), dtype=np.float64)
        if light.GetEnableColorTemperatureAttr().Get(tc):
            color = color * np.array(UsdLux.BlackbodyTemperatureAsRgb(light.GetColorTemperatureAttr().Get(tc)))
        value = intensity * 2.0**exposure * color
        if not np.all(np.isfinite(value)) or np.any(value < 0.0):
            raise SceneError(
                f"light {prim.GetPath()}: intensity x 2^exposure x color must be finite and >= 0, got {value.tolist()}"
            )
        return value

    def read_suns(self, time=None) -> tuple[Sun, ...]:
        """Every visible DistantLight, in stage order."""
        from pxr import UsdLux

        tc = self._time(time)
        suns = []
        for prim in self._prims_of(UsdLux.DistantLight):
            if not self._visible(prim, tc):
                continue
            light = UsdLux.DistantLight(prim)
            world = self._world(prim, tc)
            # Light travels along the light's local -Z, so the sun lies along +Z.
            direction = world[:3, :3] @ np.array([0.0, 0.0, 1.0])
            if np.linalg.norm(direction) == 0.0:
                raise SceneError(f"light {prim.GetPath()}: its transform collapses the light direction")
            angle = float(light.GetAngleAttr().Get(tc))
            if not (0.0 <= angle < 180.0):
                raise SceneError(f"light {prim.GetPath()}: inputs:angle must lie in [0, 180) degrees, got {angle}")
            irradiance = self._light_color(light, prim, tc)
            suns.append(Sun(direction, irradiance, math.radians(angle), str(prim.GetPath())))
        return tuple(suns)

    def read_sun(self, time=None) -> Sun | None:
        """The first visible DistantLight: the scene's sun."""
        suns = self.read_suns(time)
        return suns[0] if suns else None

    def read_dome(self, time=None) -> Dome | None:
        """The first visible DomeLight (None without one, or when it is black)."""
        from pxr import UsdLux

        tc = self._time(time)
        for prim in self._prims_of(UsdLux.DomeLight):
            if not self._visible(prim, tc):
                continue
            light = UsdLux.DomeLight(prim)
            where = f"DomeLight {prim.GetPath()}"
            color = self._light_color(light, prim, tc)
            world = self._world(prim, tc)
            u, _, vt = np.linalg.svd(world[:3, :3])
            rotation = u @ vt
            if np.linalg.det(rotation) < 0.0:
                raise SceneError(f"{where}: its transform mirrors space (negative determinant)")
            texture, source = None, ""
            asset = light.GetTextureFileAttr().Get(tc)
            if asset is not None and asset.path:
                fmt = str(light.GetTextureFormatAttr().Get(tc) or "automatic")
                if fmt not in LATLONG_FORMATS:
                    raise SceneError(f"{where}: inputs:texture:format {fmt!r} is not supported; expected "
                                     f"{' or '.join(repr(f) for f in LATLONG_FORMATS)} (a lat-long image)")
                resolved = asset.resolvedPath or str(Path(prim.GetStage().GetRootLayer().realPath).parent / asset.path)
                source = str(resolved)
                key = ("dome", source, _mtime(Path(source)))
                if key not in self._map_cache:  # read (and clamped) once for all the frames that show it
                    texture = read_latlong(Path(source), f"{where}.inputs:texture:file")
                    negative = int(np.count_nonzero(texture < 0.0))
                    if negative:  # filtered HDRIs ring below zero around the sun
                        self._warn(f"{where}.inputs:texture:file: {negative} negative texel value(s) in {source} "
                                   "(filter ringing) clamped to 0")
                        texture = np.maximum(texture, 0.0)
                    self._map_cache[key] = texture
                texture = self._map_cache[key]
            dome = Dome(color, texture, rotation, str(prim.GetPath()), source)
            return dome if dome.active else None
        return None
