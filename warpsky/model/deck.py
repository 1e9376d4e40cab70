"""Height-field clouds and the haze below them (Max 1986, "Light diffusion through clouds and haze") as plain data.

A cloud deck of constant extinction fills the space between a top surface y = H + g and a bottom surface
y = H + h about a mean plane y = H. Both come from one horizontal pattern f(x, z, t) [m]: a large-scale quadratic
polynomial plus long-crested sine waves (Max §2),

    f = c0 + cx X + cz Z + cxx X^2 + cxz X Z + czz Z^2 + sum_i a_i sin(k_i . (X, Z) + phi_i - w_i t),

with (X, Z) = (x - x0, z - z0) measured from the prim's world translation, and (Max's formulas, with the bottom
scaled to a depth D):

    g = sign(f) sqrt(f^2 + 2 c |f|),    h = -D g / sqrt((|f| + c)^2 + c^2).

Where f > 0 the cloud spans h < y - H < g; where f <= 0 there is none. g and h meet the mean plane with a vertical
tangent (dg/df = (f + c) / g is infinite at f = 0) and the bottom flattens, h -> -D as f -> infinity. The
polynomial must be bounded above (a dome, a ridge or a constant: its quadratic part negative semi-definite), so the
deck lies in a band of finite height [H + h(f_max), H + g(f_max)] with f_max = sup(polynomial) + sum |a_i|.

The haze is a horizontal slab of constant extinction between ``floor`` and ``top`` (default: the lowest cloud base
H + h(f_max)); the clouds above it throw shafts of light into it (Max §5).

USD: an ``Xform`` prim with ``uniform token warpsky:kind = "heightFieldClouds"``, read by
:func:`read_decks`. Lengths are in scene units (times metersPerUnit); extinctions are in 1/m whatever
metersPerUnit says. The prim's world translation moves the pattern's origin (x0, z0) and adds to the mean
altitude; its rotation and scale are ignored. Wave vectors are along world x and world z (a Z-up stage: x and -y).

=========================================== ========== ============ =========== =====================================
USD attribute                               unit       default      range       meaning
=========================================== ========== ============ =========== =====================================
``float warpsky:hf:meanAltitude``           scene      0            finite      H, added to the prim's world y
``float[] warpsky:hf:polynomial``           see right  [0]          bounded     1, 3 or 6 coefficients c0 [scene],
                                                                    above       cx, cz [--], cxx, cxz, czz
                                                                                [1/scene] of the quadratic in (X, Z)
``float2[] warpsky:hf:waveVectors``         rad/scene  []           finite      k_i along world (x, z)
``float[] warpsky:hf:amplitudes``           scene      []           finite      a_i, one per wave vector
``float[] warpsky:hf:phases``               rad        zeros        finite      phi_i
``float[] warpsky:hf:waveSpeeds``           rad/s      zeros        finite      w_i: wave i moves along +k_i at
                                                                                w_i / |k_i|; time = timeCode / tcps
``float warpsky:hf:maxHeight``             scene      (none)       > 0         G: caps the tops (f <= f_cap); needed
                                                                                when the polynomial is unbounded
``float warpsky:hf:equatorRounding``        scene      100 m        > 0         c: radius of the rounded equator
``float warpsky:hf:bottomDepth``            scene      200 m        >= 0        D: depth of the flattened bottoms
``float warpsky:hf:density``                1/m        0.02         >= 0        rho: extinction of the cloud
``color3f warpsky:hf:extinctionScale``      --         (1, 1, 1)    >= 0        per-channel factor on rho
``color3f warpsky:hf:albedo``               --         (1, 1, 1)    [0, 1]      single-scattering albedo
``float warpsky:hf:g``                      --         0.85         (-1, 1)     Henyey-Greenstein asymmetry
``color3f warpsky:haze:density``            1/m        (no haze)    >= 0        haze extinction per channel; haze
                                                                                exists when this is authored
``color3f warpsky:haze:albedo``             --         (1, 1, 1)    [0, 1]      haze single-scattering albedo
``float warpsky:haze:g``                    --         0.7          (-1, 1)     haze Henyey-Greenstein asymmetry
``float warpsky:haze:floor``                scene      0            finite      world y of the haze's bottom
``float warpsky:haze:top``                  scene      cloud base   > floor     world y of the haze's top (default
                                                                                H + h(f_max), the lowest cloud base)
=========================================== ========== ============ =========== =====================================

Defaults marked "m" are metres converted to scene units. Arrays of waves must have equal lengths (phases and
speeds may be left out: zeros).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.checks import float_array_attr

#: ``warpsky:kind`` of a height-field cloud prim.
DECK_KIND = "heightFieldClouds"
#: Attributes such a prim may carry.
DECK_ATTRIBUTES = frozenset(
    [f"warpsky:hf:{n}" for n in ("meanAltitude", "polynomial", "maxHeight", "waveVectors", "amplitudes", "phases",
                                 "waveSpeeds", "equatorRounding", "bottomDepth", "density", "extinctionScale",
                                 "albedo", "g")]
    + [f"warpsky:haze:{n}" for n in ("density", "albedo", "g", "floor", "top")]
)


def _rgb(value, where: str, *, low: float = 0.0, high: float = math.inf) -> np.ndarray:
    rgb = np.asarray(value, dtype=np.float64)
    rgb = np.full(3, float(rgb)) if rgb.ndim == 0 else rgb.reshape(-1)
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)) or np.any(rgb < low) or np.any(rgb > high):
        raise SceneError(f"{where} must be 3 finite values in [{low}, {high}], got {np.asarray(value).tolist()}")
    return rgb


def _asymmetry(value: float, where: str) -> float:
    if not (math.isfinite(value) and -1.0 < value < 1.0):
        raise SceneError(f"{where}: asymmetry g must lie in (-1, 1), got {value}")
    return float(value)


def surface_heights(f, rounding: float, bottom_depth: float) -> tuple[np.ndarray, np.ndarray]:
    """(g, h) [m] of Max's top and bottom surfaces above the mean plane for pattern values ``f`` [m] (float64).

    g = sign(f) sqrt(|f| (|f| + 2c)) and h = -D g / sqrt((|f| + c)^2 + c^2); both are exact products of square
    roots of non-negative terms, so f -> 0 gives g, h -> 0 without cancellation."""
    f = np.asarray(f, dtype=np.float64)
    a = np.abs(f)
    g = np.sign(f) * np.sqrt(a) * np.sqrt(a + 2.0 * rounding)
    h = -bottom_depth * g / np.sqrt((a + rounding) ** 2 + rounding**2)
    return g, h


def polynomial_peak(coefficients) -> float:
    """Supremum [m] of c0 + cx X + cz Z + cxx X^2 + cxz X Z + czz Z^2 over the plane, or +inf when unbounded."""
    c0, cx, cz, cxx, cxz, czz = (float(v) for v in coefficients)
    hessian = np.array([[2.0 * cxx, cxz], [cxz, 2.0 * czz]])
    gradient = np.array([cx, cz])
    eig = np.linalg.eigvalsh(hessian)
    scale = max(float(np.max(np.abs(eig))), 1e-300)
    if np.any(eig > 1e-12 * scale):
        return math.inf
    stationary = -np.linalg.pinv(hessian, rcond=1e-12) @ gradient
    if not np.allclose(hessian @ stationary, -gradient, rtol=1e-9, atol=1e-12 * (1.0 + np.abs(gradient).max())):
        return math.inf
    return c0 + 0.5 * float(gradient @ stationary)


@dataclass(frozen=True)
class HazeSpec:
    """A horizontal slab of homogeneous haze below a height-field cloud deck (Max §5).

    Attributes:
        density: Extinction per RGB channel [1/m], >= 0.
        albedo: Single-scattering albedo per channel, in [0, 1] (its colour).
        g: Henyey-Greenstein asymmetry, in (-1, 1).
        floor: World y of the slab's bottom [m].
        top: World y of the slab's top [m], above ``floor``; None: the cloud deck's lowest base.
    """

    density: np.ndarray
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    g: float = 0.7
    floor: float = 0.0
    top: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "density", _rgb(self.density, "warpsky:haze:density [1/m]"))
        object.__setattr__(self, "albedo", _rgb(self.albedo, "warpsky:haze:albedo", high=1.0))
        object.__setattr__(self, "g", _asymmetry(self.g, "warpsky:haze:g"))
        if not math.isfinite(self.floor):
            raise SceneError(f"warpsky:haze:floor must be a finite height [m], got {self.floor}")
        if self.top is not None and not (math.isfinite(self.top) and self.top > self.floor):
            raise SceneError(f"warpsky:haze:top must be a finite height [m] above the floor {self.floor}, "
                             f"got {self.top}")


@dataclass(frozen=True)
class CloudDeck:
    """Max's clouds between the surfaces H + g and H + h (module docstring: formulas and USD attributes).

    Attributes:
        name: Prim path or label.
        mean_altitude: H, world y of the mean cloud plane [m].
        polynomial: (6,) c0 [m], cx, cz [--], cxx, cxz, czz [1/m] of the large-scale quadratic in (X, Z) (1 or 3
            values are padded with zeros); must be bounded above.
        wave_vectors: (N, 2) k_i along world (x, z) [rad/m].
        amplitudes: (N,) a_i [m].
        phases: (N,) phi_i [rad].
        speeds: (N,) w_i [rad/s]; the pattern at time t has phases phi_i - w_i t.
        rounding: c [m] > 0, the equator's rounding.
        bottom_depth: D [m] >= 0, the flattened bottoms' depth below H.
        density: rho [1/m] >= 0.
        extinction_scale: (3,) per-channel factor: the cloud's extinction is rho * extinction_scale [1/m].
        albedo: (3,) single-scattering albedo in [0, 1].
        g: Henyey-Greenstein asymmetry of the cloud in (-1, 1).
        haze: The haze below, or None.
        origin: World (x0, z0) [m] the pattern is measured from.
        max_height: G [m] > 0 capping the tops (f <= sqrt(c^2 + G^2) - c), or None (the polynomial must then be
            bounded above).
    """

    name: str
    mean_altitude: float
    polynomial: np.ndarray = field(default_factory=lambda: np.zeros(6))
    wave_vectors: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    amplitudes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phases: np.ndarray | None = None
    speeds: np.ndarray | None = None
    rounding: float = 100.0
    bottom_depth: float = 200.0
    density: float = 0.02
    extinction_scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    g: float = 0.85
    haze: HazeSpec | None = None
    origin: tuple[float, float] = (0.0, 0.0)
    max_height: float | None = None

    def __post_init__(self):
        where = f"height-field clouds {self.name}"
        poly = np.asarray(self.polynomial, dtype=np.float64).reshape(-1)
        if poly.size not in (1, 3, 6) or not np.all(np.isfinite(poly)):
            raise SceneError(f"{where}: warpsky:hf:polynomial must hold 1, 3 or 6 finite coefficients, "
                             f"got {poly.tolist()}")
        poly = np.concatenate([poly, np.zeros(6 - poly.size)])
        if self.max_height is not None and not (math.isfinite(self.max_height) and self.max_height > 0.0):
            raise SceneError(f"{where}: warpsky:hf:maxHeight must be a positive length [m], got {self.max_height}")
        if self.max_height is None and not math.isfinite(polynomial_peak(poly)):
            raise SceneError(f"{where}: warpsky:hf:polynomial {poly.tolist()} is unbounded above (clouds would grow "
                             "without limit); make its quadratic part negative semi-definite or author "
                             "warpsky:hf:maxHeight")
        object.__setattr__(self, "polynomial", poly)
        k = np.asarray(self.wave_vectors, dtype=np.float64)
        if k.size == 0:
            k = np.zeros((0, 2))
        if k.ndim != 2 or k.shape[1] != 2 or not np.all(np.isfinite(k)):
            raise SceneError(f"{where}: warpsky:hf:waveVectors must be finite float2 values, got shape {k.shape}")
        object.__setattr__(self, "wave_vectors", k)
        count = k.shape[0]
        for name, attr in (("amplitudes", "amplitudes"), ("phases", "phases"), ("speeds", "waveSpeeds")):
            value = getattr(self, name)
            value = np.zeros(count) if value is None and name != "amplitudes" else np.asarray(value, np.float64)
            value = value.reshape(-1)
            if value.size != count:
                raise SceneError(f"{where}: warpsky:hf:{attr} has {value.size} values but warpsky:hf:waveVectors "
                                 f"has {count}; expected one per wave")
            if not np.all(np.isfinite(value)):
                raise SceneError(f"{where}: warpsky:hf:{attr} must be finite, got {value.tolist()}")
            object.__setattr__(self, name, value)
        if not math.isfinite(self.mean_altitude):
            raise SceneError(f"{where}: warpsky:hf:meanAltitude must be finite [m], got {self.mean_altitude}")
        if not (math.isfinite(self.rounding) and self.rounding > 0.0):
            raise SceneError(f"{where}: warpsky:hf:equatorRounding must be a positive length [m], got {self.rounding}")
        if not (math.isfinite(self.bottom_depth) and self.bottom_depth >= 0.0):
            raise SceneError(f"{where}: warpsky:hf:bottomDepth must be a length >= 0 [m], got {self.bottom_depth}")
        if not (math.isfinite(self.density) and self.density >= 0.0):
            raise SceneError(f"{where}: warpsky:hf:density must be an extinction >= 0 [1/m], got {self.density}")
        scale = _rgb(self.extinction_scale, f"{where}: warpsky:hf:extinctionScale")
        object.__setattr__(self, "extinction_scale", scale)
        object.__setattr__(self, "albedo", _rgb(self.albedo, f"{where}: warpsky:hf:albedo", high=1.0))
        object.__setattr__(self, "g", _asymmetry(self.g, f"{where}: warpsky:hf:g"))
        if self.haze is not None and not isinstance(self.haze, HazeSpec):
            raise SceneError(f"{where}: haze must be a HazeSpec or None, got {self.haze!r}")
        origin = tuple(float(v) for v in np.asarray(self.origin, dtype=np.float64).reshape(-1))
        if len(origin) != 2 or not all(math.isfinite(v) for v in origin):
            raise SceneError(f"{where}: origin must be two finite coordinates (x, z) [m], got {self.origin!r}")
        object.__setattr__(self, "origin", origin)

    # ------------------------------------------------------------------------------------------------- shape
    @property
    def extinction(self) -> np.ndarray:
        """The cloud's extinction rho * extinction_scale [1/m], RGB."""
        return self.density * self.extinction_scale

    @property
    def pattern_cap(self) -> float:
        """f_cap [m]: f is clamped to at most this (sqrt(c^2 + G^2) - c; +inf without ``max_height``)."""
        if self.max_height is None:
            return math.inf
        return self.max_height**2 / (math.sqrt(self.rounding**2 + self.max_height**2) + self.rounding)

    @property
    def pattern_peak(self) -> float:
        """f_max [m]: an upper bound of f everywhere and at every time (polynomial peak + sum |a_i|, or f_cap)."""
        return min(polynomial_peak(self.polynomial) + float(np.sum(np.abs(self.amplitudes))), self.pattern_cap)

    @property
    def band(self) -> tuple[float, float]:
        """(lowest cloud base, highest cloud top), world y [m]: H + h(f_max), H + g(f_max) (H, H when f_max <= 0)."""
        peak = max(self.pattern_peak, 0.0)
        g, h = surface_heights(peak, self.rounding, self.bottom_depth)
        return self.mean_altitude + float(h), self.mean_altitude + float(g)

    @property
    def haze_top(self) -> float | None:
        """World y of the haze's top [m] (the cloud base by default), or None without haze."""
        if self.haze is None:
            return None
        return self.haze.top if self.haze.top is not None else self.band[0]

    def pattern(self, x, z, time_s: float = 0.0) -> np.ndarray:
        """f [m] at world (x, z) [m] and time ``time_s`` [s] (float64, broadcast)."""
        X = np.asarray(x, dtype=np.float64) - self.origin[0]
        Z = np.asarray(z, dtype=np.float64) - self.origin[1]
        c0, cx, cz, cxx, cxz, czz = self.polynomial
        f = c0 + cx * X + cz * Z + cxx * X * X + cxz * X * Z + czz * Z * Z
        for (kx, kz), a, phi, w in zip(self.wave_vectors, self.amplitudes, self.phases, self.speeds, strict=True):
            f = f + a * np.sin(kx * X + kz * Z + phi - w * time_s)
        return np.minimum(f, self.pattern_cap)

    def inside(self, points, time_s: float = 0.0) -> np.ndarray:
        """Whether world ``points`` (..., 3) [m] lie inside the cloud (strictly between the surfaces, f > 0)."""
        p = np.asarray(points, dtype=np.float64)
        f = self.pattern(p[..., 0], p[..., 2], time_s)
        g, h = surface_heights(f, self.rounding, self.bottom_depth)
        y = p[..., 1] - self.mean_altitude
        return (f > 0.0) & (y > h) & (y < g)

    def __repr__(self) -> str:
        haze = "" if self.haze is None else f", haze {self.haze.density.tolist()} 1/m to {self.haze_top:g} m"
        return (f"CloudDeck({self.name!r}, H={self.mean_altitude:g} m, {len(self.amplitudes)} waves, "
                f"band={tuple(round(b, 3) for b in self.band)} m, rho={self.density:g} 1/m{haze})")


# ------------------------------------------------------------------------------------------------------ USD
def _read_haze(reader, prim, tc, mpu: float) -> HazeSpec | None:
    path = prim.GetPath()
    density = reader._color_attr(prim, "warpsky:haze:density", tc)
    authored = [n for n in DECK_ATTRIBUTES
                if n.startswith("warpsky:haze:") and prim.GetAttribute(n).HasAuthoredValue()]
    if density is None:
        if authored:
            raise SceneError(f"{path}.warpsky:haze:density is missing: {sorted(authored)[0]} is authored, and haze "
                             "needs its extinction (color3f, 1/m)")
        return None
    albedo = reader._color_attr(prim, "warpsky:haze:albedo", tc)
    top_attr = prim.GetAttribute("warpsky:haze:top")
    top = None
    if top_attr and top_attr.HasAuthoredValue():
        top = reader._float_attr(prim, "warpsky:haze:top", tc, 0.0) * mpu
    floor = reader._float_attr(prim, "warpsky:haze:floor", tc, 0.0) * mpu
    g = reader._float_attr(prim, "warpsky:haze:g", tc, 0.7)
    try:
        return HazeSpec(density, np.ones(3) if albedo is None else albedo, g, floor, top)
    except SceneError as exc:
        raise SceneError(f"{path} (warpsky:haze:*): {exc}") from None


def read_decks(reader, prim, time_code) -> CloudDeck:
    """The :class:`CloudDeck` of ``prim`` (``warpsky:kind = "heightFieldClouds"``) at USD ``time_code``.

    ``reader`` is a :class:`~warpsky.usd.stage.StageReader` (its attribute helpers, world transform and
    metersPerUnit). Errors name the prim and the attribute. The waves' motion is applied at render time."""
    path = str(prim.GetPath())
    names = {a.GetName() for a in prim.GetAttributes()}
    unknown = sorted(n for n in names if n.startswith(("warpsky:hf:", "warpsky:haze:")) and
                     n not in DECK_ATTRIBUTES)
    if unknown:
        raise SceneError(f"height-field clouds {path}: unknown attribute(s) {', '.join(unknown)}; "
                         f"known: {', '.join(sorted(DECK_ATTRIBUTES))}")
    mpu = float(reader.meters_per_unit)
    world = reader._world(prim, time_code)
    translation = world[:3, 3]
    hf = "warpsky:hf:"
    poly = float_array_attr(prim, hf + "polynomial", time_code, 1)
    poly = np.zeros(1) if poly is None else poly
    if poly.size not in (1, 3, 6):
        raise SceneError(f"{path}.{hf}polynomial must hold 1, 3 or 6 coefficients, got {poly.size}")
    poly = np.concatenate([poly, np.zeros(6 - poly.size)]) * np.array([mpu, 1.0, 1.0, 1 / mpu, 1 / mpu, 1 / mpu])
    waves = float_array_attr(prim, hf + "waveVectors", time_code, 2)
    waves = np.zeros((0, 2)) if waves is None else waves / mpu
    arrays = {}
    for attr, scale in (("amplitudes", mpu), ("phases", 1.0), ("waveSpeeds", 1.0)):
        value = float_array_attr(prim, hf + attr, time_code, 1)
        if value is None and attr == "amplitudes" and len(waves):
            raise SceneError(f"{path}.{hf}amplitudes is missing: {hf}waveVectors has {len(waves)} waves")
        if value is not None and value.size != len(waves):
            raise SceneError(f"{path}.{hf}{attr} has {value.size} values but {hf}waveVectors has {len(waves)}; "
                             "expected one per wave")
        arrays[attr] = None if value is None else value * scale
    numbers = {}
    cap = prim.GetAttribute(hf + "maxHeight")
    max_height = reader._float_attr(prim, hf + "maxHeight", time_code, 0.0) * mpu if cap.HasAuthoredValue() else None
    for attr, default, scale in (("meanAltitude", 0.0, mpu), ("equatorRounding", 100.0 / mpu, mpu),
                                 ("bottomDepth", 200.0 / mpu, mpu), ("density", 0.02, 1.0), ("g", 0.85, 1.0)):
        numbers[attr] = reader._float_attr(prim, hf + attr, time_code, default) * scale
    scale = reader._color_attr(prim, hf + "extinctionScale", time_code)
    albedo = reader._color_attr(prim, hf + "albedo", time_code)
    try:
        return CloudDeck(
            path, float(translation[1]) + numbers["meanAltitude"], poly, waves,
            np.zeros(0) if arrays["amplitudes"] is None else arrays["amplitudes"], arrays["phases"],
            arrays["waveSpeeds"], numbers["equatorRounding"], numbers["bottomDepth"], numbers["density"],
            np.ones(3) if scale is None else scale, np.ones(3) if albedo is None else albedo, numbers["g"],
            _read_haze(reader, prim, time_code, mpu), (float(translation[0]), float(translation[2])), max_height)
    except SceneError as exc:
        message = str(exc)
        raise SceneError(message if path in message else f"{path}: {message}") from None
