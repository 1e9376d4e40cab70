"""Analytic fog (Biri, Michelin and Arquès 2002, "Real-time animation of realistic fog") as plain data.

The fog's extinction is a weighted sum of functions whose integrals along a straight segment have closed forms
(Biri Eq. 7-8), so the transmittance along any ray is exact whatever its length:

    K(x, t) = extinction_scale * D(x - wind t)   [1/m, per RGB channel],   D = sum of the terms below,

inside the horizontal slab ``floor <= y <= top`` (moved by the wind too) and zero outside it. The slab keeps the
optical depth towards the sun finite. Families (each term is one dataclass):

* :class:`ConstantTerm`  ``c0``;
* :class:`CosineTerm`    ``c cos(k . x + phi)``, a plane wave (Biri §3.2.1, the projection on a direction);
* :class:`PolynomialTerm` ``P(u)``, ``u = axis . (x - origin)``, on ``lo <= u <= hi`` and zero outside, or repeated
  with period ``hi - lo`` (Biri §3.2.2, Fig. 3);
* :class:`BlobTerm`      ``c / (1 + r^2 / R^2)``: Biri's equipotential 1 / (a + b r^2) (Eq. 9) with a = 1/c and
  b = 1/(c R^2), so ``c`` is the peak value [1/m] and ``R`` the distance at which it halves; ``r`` is the distance
  to a point (point blob) or to a line (line blob, ``direction`` set).

Nothing here can go negative: constants and blob strengths are >= 0, the cosines obey Biri's bound
``sum of constants >= sum |c_i|``, and each polynomial is checked to be >= 0 on its interval (at its end points
and at the real roots of its derivative). A fog that fails raises :class:`~warpsky.core.errors.SceneError` naming the
prim and the attribute.

USD: any prim (``Xform``, ``UsdVolVolume`` ...) with ``uniform token warpsky:kind = "analyticFog"``. Its world
transform places the terms (cosine phases and wave vectors, the polynomial's axis, origin and interval, blob centres
and directions: exactly, for any invertible affine transform; blob radii and the slab heights scale by the cube
root of its determinant); the slab stays horizontal, ``floor`` and ``top`` counting up from the prim's origin.
Every attribute may be time-sampled; lengths are in stage units (converted with metersPerUnit), extinctions in
1/m whatever the stage's unit.

=============================================== ========= ======= ========== ===========================================
USD attribute                                   unit      default range      meaning
=============================================== ========= ======= ========== ===========================================
``float warpsky:fog:constant``                  1/m       0       >= 0       c0, everywhere in the slab
``float[] warpsky:fog:cosine:amplitudes``       1/m       []      sum|c|<=c0 c_i of c_i cos(k_i . x + phi_i), x in the
                                                                             prim's local frame [stage units]
``float3[] warpsky:fog:cosine:waveVectors``     rad/unit  []      finite     k_i (one per amplitude)
``float[] warpsky:fog:cosine:phases``           rad       zeros   finite     phi_i (one per amplitude, or unauthored)
``float[] warpsky:fog:polynomial:coefficients`` 1/m/unitⁿ []      P >= 0     c_n of P(u) = sum c_n u^n, ascending
                                                                             powers; [] or unauthored: no polynomial
``float3 warpsky:fog:polynomial:axis``          --        up axis != 0       local direction of u (normalised); u = 0 at
                                                                             the prim's origin
``float2 warpsky:fog:polynomial:interval``      unit      (0, 1)  lo < hi    where P applies (zero outside)
``bool warpsky:fog:polynomial:repeat``          --        false              repeat P with period hi - lo instead
``point3f[] warpsky:fog:blob:centers``          unit      []      finite     blob centres (local frame)
``float[] warpsky:fog:blob:strengths``          1/m       []      >= 0       peak value c at the centre or on the line
``float[] warpsky:fog:blob:radii``              unit      []      > 0        R: c / (1 + r^2/R^2) halves at r = R
``float3[] warpsky:fog:blob:directions``        --        zeros   finite     (0,0,0): point blob; else a line blob along
                                                                             this direction through the centre
``float warpsky:fog:floor``                     unit      0       < top      slab bottom above the prim's origin
``float warpsky:fog:top``                       unit      100     > floor    slab top above the prim's origin
``color3f warpsky:fog:extinctionScale``         --        (1,1,1) >= 0       multiplies D per RGB channel
``color3f warpsky:fog:albedo``                  --        (1,1,1) [0, 1]     single-scattering albedo
``float warpsky:fog:g``                         --        0.85    (-1, 1)    Henyey-Greenstein asymmetry
``vector3f warpsky:fog:wind``                   m/s       (0,0,0) finite     along the stage's axes, in m/s whatever
                                                                             metersPerUnit; moves every term and the
                                                                             slab
=============================================== ========= ======= ========== ===========================================

Arrays of one family must have equal lengths (the phases and directions may be left unauthored).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.checks import _vec3, float_array_attr

#: ``warpsky:kind`` of an analytic fog prim.
FOG_KIND = "analyticFog"
#: The attributes an analytic fog prim may carry.
FOG_ATTRIBUTES = frozenset("warpsky:fog:" + n for n in (
    "constant", "cosine:amplitudes", "cosine:waveVectors", "cosine:phases", "polynomial:coefficients",
    "polynomial:axis", "polynomial:interval", "polynomial:repeat", "blob:centers", "blob:strengths", "blob:radii",
    "blob:directions", "floor", "top", "extinctionScale", "albedo", "g", "wind"))


def _finite(value, what: str) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{what} must be finite, got {value}")
    return value


@dataclass(frozen=True)
class ConstantTerm:
    """``value`` [1/m] everywhere in the slab (>= 0)."""

    value: float

    def __post_init__(self):
        if not (_finite(self.value, "warpsky:fog:constant") >= 0.0):
            raise SceneError(f"warpsky:fog:constant must be >= 0 [1/m], got {self.value}")

    def density(self, x: np.ndarray) -> np.ndarray:
        return np.full(x.shape[:-1], float(self.value))


@dataclass(frozen=True)
class CosineTerm:
    """``amplitude cos(wave_vector . x + phase)``: amplitude [1/m], wave vector [rad/m] (world), phase [rad]."""

    amplitude: float
    wave_vector: np.ndarray
    phase: float = 0.0

    def __post_init__(self):
        _finite(self.amplitude, "warpsky:fog:cosine:amplitudes")
        _finite(self.phase, "warpsky:fog:cosine:phases")
        object.__setattr__(self, "wave_vector", _vec3(self.wave_vector, "warpsky:fog:cosine:waveVectors"))

    def density(self, x: np.ndarray) -> np.ndarray:
        return self.amplitude * np.cos(x @ self.wave_vector + self.phase)


@dataclass(frozen=True)
class PolynomialTerm:
    """``sum_n coefficients[n] u^n`` with ``u = axis . (x - origin)`` [m] on ``interval`` = (lo, hi) [m]; zero
    outside it, or with ``repeat`` the same values repeated with period hi - lo (Biri Fig. 3).

    ``coefficients[n]`` is in [1/m per m^n]; ``axis`` is normalised. The constructor checks P >= 0 on the interval.
    """

    coefficients: tuple
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    interval: tuple = (0.0, 1.0)
    repeat: bool = False

    def __post_init__(self):
        what = "warpsky:fog:polynomial:coefficients"
        coefficients = np.asarray(self.coefficients, dtype=np.float64).reshape(-1)
        if coefficients.size == 0 or not np.all(np.isfinite(coefficients)):
            raise SceneError(f"{what} must be one or more finite numbers, got {self.coefficients!r}")
        object.__setattr__(self, "coefficients", tuple(coefficients.tolist()))
        object.__setattr__(self, "axis", _vec3(self.axis, "warpsky:fog:polynomial:axis", unit=True))
        object.__setattr__(self, "origin", _vec3(self.origin, "polynomial origin"))
        lo, hi = (float(v) for v in np.asarray(self.interval, dtype=np.float64).reshape(2))
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise SceneError(f"warpsky:fog:polynomial:interval must be (lo, hi) with lo < hi, got {self.interval!r}")
        object.__setattr__(self, "interval", (lo, hi))
        object.__setattr__(self, "repeat", bool(self.repeat))
        lowest = self.minimum()
        # the size of the terms at the interval's far end: float32 authoring rounds a minimum of 0 to about 1e-7 of it
        reach = max(abs(lo), abs(hi))
        scale = float(np.sum(np.abs(coefficients) * reach ** np.arange(coefficients.size)))
        if lowest < -1e-6 * scale:
            raise SceneError(f"{what}: the polynomial goes negative on its interval [{lo:g}, {hi:g}] (minimum "
                             f"{lowest:.6g}); the fog's extinction must be >= 0 everywhere")
        if lowest < 0.0:  # a rounded zero: lift P by it so that it is >= 0 exactly
            coefficients[0] -= lowest
            object.__setattr__(self, "coefficients", tuple(coefficients.tolist()))

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """P(u) (no interval applied)."""
        return np.polynomial.polynomial.polyval(np.asarray(u, dtype=np.float64), self.coefficients)

    def minimum(self) -> float:
        """The least value of P on the interval: at its ends or where P' vanishes inside it."""
        lo, hi = self.interval
        candidates = [lo, hi]
        derivative = np.polynomial.polynomial.polyder(self.coefficients)
        if np.any(derivative != 0.0):
            roots = np.polynomial.polynomial.polyroots(derivative) if derivative.size > 1 else np.array([])
            candidates += [r.real for r in roots if abs(r.imag) <= 1e-9 * max(1.0, abs(r)) and lo < r.real < hi]
        return float(self(np.array(candidates)).min())

    def local(self, x: np.ndarray) -> np.ndarray:
        """u [m] of points x, folded into the interval when repeated (NaN outside it when not)."""
        lo, hi = self.interval
        u = (x - self.origin) @ self.axis
        if self.repeat:
            return lo + np.mod(u - lo, hi - lo)
        return np.where((u >= lo) & (u <= hi), u, np.nan)

    def density(self, x: np.ndarray) -> np.ndarray:
        u = self.local(x)
        return np.where(np.isnan(u), 0.0, self(np.nan_to_num(u)))


@dataclass(frozen=True)
class BlobTerm:
    """Biri's equipotential function ``strength / (1 + r^2 / radius^2)``: strength [1/m] at r = 0, halved at
    r = radius [m]. ``r`` is the distance to ``centre`` [m], or with ``direction`` (a unit vector; None: a point
    blob) the distance to the line through ``centre`` along it."""

    centre: np.ndarray
    strength: float
    radius: float
    direction: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "centre", _vec3(self.centre, "warpsky:fog:blob:centers"))
        if not (_finite(self.strength, "warpsky:fog:blob:strengths") >= 0.0):
            raise SceneError(f"warpsky:fog:blob:strengths must be >= 0 [1/m], got {self.strength}")
        if not (_finite(self.radius, "warpsky:fog:blob:radii") > 0.0):
            raise SceneError(f"warpsky:fog:blob:radii must be > 0, got {self.radius}")
        if self.direction is not None:
            object.__setattr__(self, "direction", _vec3(self.direction, "warpsky:fog:blob:directions", unit=True))

    @property
    def is_line(self) -> bool:
        return self.direction is not None

    def density(self, x: np.ndarray) -> np.ndarray:
        offset = x - self.centre
        if self.direction is not None:
            offset = offset - np.multiply.outer(offset @ self.direction, self.direction)
        r2 = np.sum(offset * offset, axis=-1)
        return self.strength / (1.0 + r2 / (self.radius * self.radius))


TERM_TYPES = (ConstantTerm, CosineTerm, PolynomialTerm, BlobTerm)


@dataclass(frozen=True)
class AnalyticFog:
    """A fog whose extinction is ``extinction_scale * D(x - wind t)`` [1/m] inside the slab (module docstring).

    Attributes:
        name: Prim path or label (errors name it).
        terms: The functions D sums (:class:`ConstantTerm`, :class:`CosineTerm`, :class:`PolynomialTerm`,
            :class:`BlobTerm`), world frame, at time 0.
        floor: World y of the slab's bottom at time 0 [m].
        top: World y of the slab's top at time 0 [m], > floor.
        extinction_scale: Per RGB channel multiplier of D (>= 0).
        albedo: Single-scattering albedo, RGB in [0, 1].
        g: Henyey-Greenstein asymmetry in (-1, 1).
        wind: [m/s] world; the whole fog (terms and slab) moves by wind * t.
        source: Where the fog came from (stage file), for messages.
    """

    name: str
    terms: tuple = ()
    floor: float = 0.0
    top: float = 100.0
    extinction_scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    g: float = 0.85
    wind: np.ndarray = field(default_factory=lambda: np.zeros(3))
    source: str = ""

    def __post_init__(self):
        try:
            self._validate()
        except SceneError as exc:
            raise SceneError(f"{self.name}.{exc}" if str(exc).startswith("warpsky:") else f"{self.name}: {exc}") \
                from None

    def _validate(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        for term in self.terms:
            if not isinstance(term, TERM_TYPES):
                raise SceneError(f"terms must be {', '.join(t.__name__ for t in TERM_TYPES)}, got {term!r}")
        floor = _finite(self.floor, "warpsky:fog:floor")
        top = _finite(self.top, "warpsky:fog:top")
        if not floor < top:
            raise SceneError(f"warpsky:fog:top ({top:g} m) must lie above warpsky:fog:floor ({floor:g} m)")
        object.__setattr__(self, "floor", floor)
        object.__setattr__(self, "top", top)
        scale = _vec3(self.extinction_scale, "warpsky:fog:extinctionScale")
        if np.any(scale < 0.0):
            raise SceneError(f"warpsky:fog:extinctionScale must be >= 0, got {scale.tolist()}")
        albedo = _vec3(self.albedo, "warpsky:fog:albedo")
        if np.any(albedo < 0.0) or np.any(albedo > 1.0):
            raise SceneError(f"warpsky:fog:albedo must lie in [0, 1], got {albedo.tolist()}")
        if not (math.isfinite(self.g) and -1.0 < self.g < 1.0):
            raise SceneError(f"warpsky:fog:g must lie in (-1, 1), got {self.g}")
        object.__setattr__(self, "extinction_scale", scale)
        object.__setattr__(self, "albedo", albedo)
        object.__setattr__(self, "g", float(self.g))
        object.__setattr__(self, "wind", _vec3(self.wind, "warpsky:fog:wind"))
        constant = sum(t.value for t in self.terms if isinstance(t, ConstantTerm))
        swing = sum(abs(t.amplitude) for t in self.terms if isinstance(t, CosineTerm))
        if swing > constant:
            raise SceneError(f"warpsky:fog:cosine:amplitudes: the sum of their magnitudes ({swing:.6g} 1/m) exceeds "
                             f"warpsky:fog:constant ({constant:.6g} 1/m), so the fog could go negative; "
                             "need constant >= sum |amplitude| (Biri's bound)")

    def of_type(self, kind) -> tuple:
        return tuple(t for t in self.terms if isinstance(t, kind))

    def density(self, points, time_s: float = 0.0) -> np.ndarray:
        """D (before ``extinction_scale``) at world ``points`` (..., 3) [m] at time ``time_s`` [s], float64: the
        reference the kernels are tested against."""
        x = np.asarray(points, dtype=np.float64) - self.wind * float(time_s)
        total = np.zeros(x.shape[:-1])
        for term in self.terms:
            total = total + term.density(x)
        inside = (x[..., 1] >= self.floor) & (x[..., 1] <= self.top)
        return np.where(inside, total, 0.0)

    def describe(self) -> str:
        """One line for ``warpsky info``: the terms by family, the slab and the wind."""
        counts = {t.__name__.removesuffix("Term").lower(): len(self.of_type(t)) for t in TERM_TYPES}
        terms = ", ".join(f"{c} {n}" for n, c in counts.items() if c) or "no terms"
        return (f"{terms}; slab {self.floor:g} .. {self.top:g} m, wind {np.round(self.wind, 3).tolist()} m/s, "
                f"albedo {np.round(self.albedo, 3).tolist()}, g {self.g:g}")

    def __repr__(self) -> str:
        counts = {t.__name__: len(self.of_type(t)) for t in TERM_TYPES}
        terms = ", ".join(f"{n}={c}" for n, c in counts.items() if c)
        return (f"AnalyticFog({self.name!r}, {terms or 'empty'}, slab=[{self.floor:g}, {self.top:g}] m, "
                f"scale={self.extinction_scale.tolist()}, albedo={self.albedo.tolist()}, g={self.g:g}, "
                f"wind={self.wind.tolist()} m/s)")


# ------------------------------------------------------------------------------------------------------- USD
def _same_length(prim, arrays: dict) -> int:
    """The common length of the authored arrays in ``arrays`` ({attribute: array or None}); SceneError naming the
    first one that differs from the first authored one."""
    authored = [(name, a) for name, a in arrays.items() if a is not None]
    if not authored:
        return 0
    first, reference = authored[0]
    for name, array in authored[1:]:
        if len(array) != len(reference):
            raise SceneError(f"{prim.GetPath()}.{name} has {len(array)} entries but {first} has {len(reference)}; "
                             "they must have one entry per term")
    return len(reference)


class _Placement:
    """The prim's local frame (stage units) -> warpsky world (Y up, metres): x_world = linear @ x_local + origin."""

    def __init__(self, world: np.ndarray):
        self.linear = world[:3, :3]
        self.origin = world[:3, 3]
        self.inverse_transpose = np.linalg.inv(self.linear).T
        self.scale = abs(float(np.linalg.det(self.linear))) ** (1.0 / 3.0)

    def point(self, p) -> np.ndarray:
        return self.linear @ np.asarray(p, dtype=np.float64) + self.origin

    def covector(self, k) -> np.ndarray:
        """A gradient (wave vector) from local to world: k_local . x_local = (L^-T k_local) . (x_world - origin)."""
        return self.inverse_transpose @ np.asarray(k, dtype=np.float64)


def read_analytic_fog(reader, prim, time_code, time_s: float = 0.0) -> AnalyticFog:
    """The :class:`AnalyticFog` of a prim with ``warpsky:kind = "analyticFog"`` (attribute table in the module
    docstring), read at ``time_code`` (a ``Usd.TimeCode``, a number or None for the earliest time).

    Args:
        reader: The stage reader (:class:`~warpsky.usd.prims.StagePrims`: transforms, typed attributes,
            ``meters_per_unit``, ``world_from_stage``).
        prim: The fog prim.
        time_code: When to read the attributes and the transform.
        time_s: Scene time [s]. Not used here: the wind's displacement is applied at render time
            (:func:`~warpsky.media.fog.fog_struct` with ``Scene.time_s``), so the fog read is the fog at
            time 0 with the attributes' values at ``time_code``; accepted so every kind's reader has one signature.

    Raises:
        SceneError: naming the prim and the attribute: unknown ``warpsky:fog:*`` names, wrong types, arrays of
            one family with different lengths, or a fog that could go negative.
    """
    from pxr import Usd

    tc = time_code if isinstance(time_code, Usd.TimeCode) else reader._time(time_code)
    path = str(prim.GetPath())
    names = {a.GetName() for a in prim.GetAttributes() if a.GetName().startswith("warpsky:fog:")}
    unknown = sorted(names - FOG_ATTRIBUTES)
    if unknown:
        raise SceneError(f"analytic fog {path}: unknown attribute(s) {', '.join(unknown)}; known: "
                         f"{', '.join(sorted(FOG_ATTRIBUTES))}")
    place = _Placement(reader._world(prim, tc))
    terms = _read_terms(reader, prim, tc, place)
    height = {key: reader._float_attr(prim, f"warpsky:fog:{key}", tc, default)
              for key, default in (("floor", 0.0), ("top", 100.0))}
    scale = reader._color_attr(prim, "warpsky:fog:extinctionScale", tc)
    albedo = reader._color_attr(prim, "warpsky:fog:albedo", tc)
    wind = reader._vector_attr(prim, "warpsky:fog:wind", tc, 3, "a vector3f [m/s]", "3 finite speeds [m/s]")
    rotation = reader.world_from_stage[:3, :3] / reader.meters_per_unit  # stage axes -> Y-up axes, m/s kept
    source = str(getattr(reader, "path", ""))
    return AnalyticFog(
        path, terms, floor=float(place.origin[1] + place.scale * height["floor"]),
        top=float(place.origin[1] + place.scale * height["top"]),
        extinction_scale=np.ones(3) if scale is None else scale, albedo=np.ones(3) if albedo is None else albedo,
        g=reader._float_attr(prim, "warpsky:fog:g", tc, 0.85),
        wind=np.zeros(3) if wind is None else rotation @ wind, source=source)


def _read_terms(reader, prim, tc, place: _Placement) -> list:
    """The terms of the fog prim in world space (errors name the prim and the attribute)."""
    path = str(prim.GetPath())
    terms = []
    try:
        constant = reader._float_attr(prim, "warpsky:fog:constant", tc, 0.0)
        if constant != 0.0 or prim.GetAttribute("warpsky:fog:constant").HasAuthoredValue():
            terms.append(ConstantTerm(constant))
        terms += _cosines(prim, tc, place)
        terms += _polynomials(reader, prim, tc, place)
        terms += _blobs(prim, tc, place)
    except SceneError as exc:
        text = str(exc)
        raise SceneError(f"{path}.{text}" if text.startswith("warpsky:") else text) from None
    return terms


def _cosines(prim, tc, place: _Placement) -> list:
    arrays = {"warpsky:fog:cosine:amplitudes": float_array_attr(prim, "warpsky:fog:cosine:amplitudes", tc, 1),
              "warpsky:fog:cosine:waveVectors": float_array_attr(prim, "warpsky:fog:cosine:waveVectors", tc, 3),
              "warpsky:fog:cosine:phases": float_array_attr(prim, "warpsky:fog:cosine:phases", tc, 1)}
    count = _same_length(prim, arrays)
    amplitudes, waves, phases = arrays.values()
    if count and (amplitudes is None or waves is None):
        missing = "amplitudes" if amplitudes is None else "waveVectors"
        raise SceneError(f"{prim.GetPath()}.warpsky:fog:cosine:{missing} is missing (one per cosine term)")
    terms = []
    for i in range(count):
        k = place.covector(waves[i])
        phase = (0.0 if phases is None else float(phases[i])) - float(k @ place.origin)
        terms.append(CosineTerm(float(amplitudes[i]), k, phase))
    return terms


def _polynomials(reader, prim, tc, place: _Placement) -> list:
    coefficients = float_array_attr(prim, "warpsky:fog:polynomial:coefficients", tc, 1)
    if coefficients is None or coefficients.size == 0:
        return []
    up = np.array([0.0, 1.0, 0.0]) if getattr(reader, "up_axis", "Y") == "Y" else np.array([0.0, 0.0, 1.0])
    axis = reader._vector_attr(prim, "warpsky:fog:polynomial:axis", tc, 3, "a float3", "3 finite numbers")
    axis = up if axis is None else axis
    if not np.any(axis != 0.0):
        raise SceneError(f"{prim.GetPath()}.warpsky:fog:polynomial:axis must be a non-zero direction, got (0, 0, 0)")
    interval = reader._vector_attr(prim, "warpsky:fog:polynomial:interval", tc, 2, "a float2 (lo, hi)",
                                   "2 finite numbers")
    interval = np.array([0.0, 1.0]) if interval is None else interval
    # u_local = a . x_local = w . (x_world - origin) with w = L^-T a (a unit): u in metres is u_local / |w|
    w = place.covector(axis / np.linalg.norm(axis))
    stretch = float(np.linalg.norm(w))
    metric = coefficients * stretch ** np.arange(coefficients.size)
    repeat = reader._bool_attr(prim, "warpsky:fog:polynomial:repeat", tc, False)
    return [PolynomialTerm(tuple(metric.tolist()), w / stretch, place.origin, tuple((interval / stretch).tolist()),
                           repeat)]


def _blobs(prim, tc, place: _Placement) -> list:
    arrays = {name: float_array_attr(prim, name, tc, width) for name, width in (
        ("warpsky:fog:blob:centers", 3), ("warpsky:fog:blob:strengths", 1), ("warpsky:fog:blob:radii", 1),
        ("warpsky:fog:blob:directions", 3))}
    count = _same_length(prim, arrays)
    centres, strengths, radii, directions = arrays.values()
    for name, array in list(arrays.items())[:3]:
        if count and array is None:
            raise SceneError(f"{prim.GetPath()}.{name} is missing (one per blob)")
    terms = []
    for i in range(count):
        direction = None
        if directions is not None and np.any(directions[i] != 0.0):
            direction = place.linear @ directions[i]
        terms.append(BlobTerm(place.point(centres[i]), float(strengths[i]), float(radii[i]) * place.scale,
                              direction))
    return terms
