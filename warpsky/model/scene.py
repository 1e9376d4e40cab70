"""What is in the world at one time code: plain dataclasses in SI units, world Y-up metres, no pxr types.

The camera lives in :mod:`warpsky.model.camera`, the sun and the dome in :mod:`warpsky.model.lights`; both are
imported here, so ``warpsky.model.scene`` names every part of a :class:`Scene`.

Everything here can be built by hand (tests, notebooks) or read from USD by :mod:`warpsky.usd.stage`.
Constructors validate their inputs and say what is wrong.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.camera import Camera, Projection, as_imath_rows  # noqa: F401 - part of the model's names
from warpsky.model.checks import _vec3
from warpsky.model.lights import Dome, Sun
from warpsky.model.stratiform import GroundTexture, StratiformLayer

#: The particle species warpsky has optics for (:mod:`warpsky.optics.species`).
SPECIES_NAMES = ("air", "cloud", "rain", "ice", "snow", "stratus")
#: Species a Volume field can name (``field:cloud`` ...); ``stratus`` is the stratiform layers' droplet model.
FIELD_SPECIES = ("cloud", "rain", "ice", "snow")

class PhaseKind(enum.IntEnum):
    """Analytic phase models a medium can use; values are the codes the kernels switch on."""

    ISOTROPIC = 0
    HG = 1
    RAYLEIGH = 2


@dataclass(frozen=True)
class PhaseModel:
    """A phase function, normalised so that its integral over the sphere is 1.

    ============ ====== ======== ============ ====================================
    name         unit   default  valid range  USD
    ============ ====== ======== ============ ====================================
    kind         --     HG       enum         ``token warpsky:phase`` on the Volume
    g            --     0.85     (-1, 1)      ``float warpsky:phase:g`` (HG only)
    ============ ====== ======== ============ ====================================
    """

    kind: PhaseKind = PhaseKind.HG
    g: float = 0.85

    def __post_init__(self):
        object.__setattr__(self, "kind", PhaseKind(self.kind))
        if not (math.isfinite(self.g) and -1.0 < self.g < 1.0):
            raise SceneError(f"asymmetry g must lie in (-1, 1), got {self.g}")

    def __repr__(self) -> str:
        if self.kind == PhaseKind.HG:
            return f"PhaseModel(hg, g={self.g:g})"
        return f"PhaseModel({self.kind.name.lower()})"


@dataclass(frozen=True)
class DetailSpec:
    """Animated density detail of a voxel medium: the coarse field times an advected noise factor,
    evaluated at each sample inside the kernels (the grid is never rewritten).

    The factor is ``max(0, 1 + amplitude * clamp(z, -3, 3))`` with ``z`` a periodic 3D noise of unit standard
    deviation (features about ``scale`` across), advected by ``wind`` plus divergence-free curl noise (eddies of
    8 ``scale`` and 4 ``scale``, rms speed ``curl_speed``) in Neyret's staggered layers of life ``period``
    (:mod:`warpsky.media.advection.advection`). The factor never exceeds ``1 + 3 amplitude``. The noise is anchored in
    world space and tiles it with a period of 32 ``scale``; time is ``time_code / timeCodesPerSecond``, and every
    frame is computed on its own (random access). Attributes on the ``Volume`` prim (all its fields share them):

    ==================================  ========== ======= =========== ================================================
    USD attribute                       unit       default range       meaning
    ==================================  ========== ======= =========== ================================================
    ``float warpsky:detail:amplitude``  --         0       [0, 1]      strength; 0 turns detail off (no kernel cost)
    ``float warpsky:detail:scale``      m          100     > 0         size of the detail features
    ``float3 warpsky:detail:wind``      m/s        (0,0,0) finite      uniform wind, along the stage's axes (metres
                                                                       per second whatever metersPerUnit says)
    ``float warpsky:detail:curlSpeed``  m/s        2       >= 0        rms speed of the turbulent (curl) part
    ``float warpsky:detail:period``     s          60      > 0         life of one advection layer (best about one
                                                                       or two eddy turnover times, 8 scale / speed)
    ``int warpsky:detail:seed``         --         0       >= 0        seed of the noise and of the curl flow
    ==================================  ========== ======= =========== ================================================

    One attribute sits on a field prim (``OpenVDBAsset``) instead, because the species differ:

    ==================================  ========== ======= =========== ================================================
    ``float warpsky:detail:edge``       1/m        0       >= 0        extinction taken off the detailed field,
                                                                       floored at zero: ``max(0, beta f - edge)``
    ==================================  ========== ======= =========== ================================================

    A coarse grid blurs a liquid cloud's boundary over a voxel (a 500 m cell ramps from clear to cloudy), where real
    droplets evaporate within seconds of leaving saturated air and the boundary is sharp. ``edge`` clears the thin
    fringe below it, so the boundary becomes the level set ``beta f = edge``, which the noise moves in and out:
    crisp, lumpy edges (turrets on a convective tower), the interior (``beta >> edge``) barely changed. Rain, whose
    shafts have soft sides, keeps 0. It only lowers the density, so the bound ``1 + 3 amplitude`` holds.
    """

    amplitude: float = 0.0
    scale: float = 100.0
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0)
    curl_speed: float = 2.0
    period: float = 60.0
    seed: int = 0
    edge: float = 0.0
    name: str = "detail"

    def __post_init__(self):
        where = f"{self.name}: warpsky:detail"
        if not (math.isfinite(self.amplitude) and 0.0 <= self.amplitude <= 1.0):
            raise SceneError(f"{where}:amplitude must lie in [0, 1], got {self.amplitude}")
        if not (math.isfinite(self.scale) and self.scale > 0.0):
            raise SceneError(f"{where}:scale must be a positive length [m], got {self.scale}")
        wind = tuple(float(w) for w in _vec3(self.wind, f"{where}:wind (float3 [m/s])"))
        object.__setattr__(self, "wind", wind)
        if not (math.isfinite(self.curl_speed) and self.curl_speed >= 0.0):
            raise SceneError(f"{where}:curlSpeed must be a finite speed >= 0 [m/s], got {self.curl_speed}")
        if not (math.isfinite(self.period) and self.period > 0.0):
            raise SceneError(f"{where}:period must be a positive duration [s], got {self.period}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise SceneError(f"{where}:seed must be an integer >= 0, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))
        if not (math.isfinite(self.edge) and self.edge >= 0.0):
            raise SceneError(f"{where}:edge must be a finite extinction >= 0 [1/m], got {self.edge}")

    @property
    def active(self) -> bool:
        """Whether the detail changes anything (amplitude > 0)."""
        return self.amplitude > 0.0


@dataclass(frozen=True)
class IceCrystals:
    """How the crystals of an ice field fall (``warpsky:ice:*`` on its field prim).

    ============================== ====== ======== ========== ==================================================
    attribute                      unit   default  range      meaning
    ============================== ====== ======== ========== ==================================================
    ``token warpsky:ice:orientation`` -   random   random,    orientation law: horizontal plates (sundogs, the
                                                   plate,     circumzenithal arc), horizontal columns (tangent
                                                   column,    arcs), Parry columns (Parry arcs)
                                                   parry
    ``token warpsky:ice:habit``    -      (law)    column,    crystal shape; default plate for ``plate``, column
                                                   plate      otherwise
    ``float warpsky:ice:tilt``     deg    1        0 - 90     standard deviation of the crystals' flutter
    ``float warpsky:ice:fraction`` -      1        0 - 1      number fraction of crystals that follow the law; the
                                                              rest are randomly oriented columns
    ============================== ====== ======== ========== ==================================================
    """

    orientation: str = "random"
    habit: str = ""
    tilt_deg: float = 1.0
    fraction: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.fraction) and 0.0 <= self.fraction <= 1.0):
            raise SceneError(f"warpsky:ice:fraction must be a number fraction in [0, 1], got {self.fraction!r}")


@dataclass(frozen=True)
class VoxelMedium:
    """A participating medium given by a dense grid of field values.

    Extinction at a point is ``extinction_scale * field(p)`` [1/m], with ``field`` interpolated trilinearly
    between voxel centres. Voxel centres sit at integer index coordinates ``0..n-1``; the medium occupies the
    index box ``[-0.5, n-0.5]`` on each axis and is zero outside it. Inside the box, lookups beyond the outer
    voxel centres clamp to the edge value (so a constant grid is an exactly homogeneous box).

    Attributes:
        name: Prim path of the Volume (and field) this came from.
        density: Field values, float32 array indexed ``[x, y, z]`` [field units].
        world_from_index: 4x4 affine matrix (float64, column vectors) from index coordinates to world metres.
        extinction_scale: Extinction per unit field value [1/m], RGB.
        albedo: Single-scattering albedo, RGB in [0, 1].
        phase: Phase function of the scatterers (analytic; used when ``species`` is None).
        source: File the field was read from, for messages and ``warpsky info``.
        species: Particle species (``cloud``, ``rain``, ``ice``, ``snow``, ``air``) whose tabulated phase
            function is used, or None for the analytic ``phase``.
        slicing_xi: Riley's back-scatter term ξ [1/sr] for this medium in half-angle slicing (``float
            warpsky:slicing:xi`` on the Volume), or None for the technique's ``xi`` setting.
        detail: Animated density detail (:class:`DetailSpec`, ``warpsky:detail:*`` on the Volume), or None.
        ice: How an ice field's crystals are oriented (:class:`IceCrystals`), or None (random orientation).
        velocity_source: The file of the Volume's velocity field ("" without one), which moves the density within
            a motion-blurred frame; a batch's resume hash includes it.
        water: (peak water content [kg/m³], total water [kg]) of the field at this time as its writer recorded it
            (``float warpsky:water:peak`` and ``double warpsky:water:total`` on the field, which ``warpsky simulate``
            and ``warpsky import-weather`` author), or None; ``warpsky info`` prints it.
    """

    name: str
    density: np.ndarray
    world_from_index: np.ndarray
    extinction_scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    phase: PhaseModel = field(default_factory=PhaseModel)
    source: str = ""
    species: str | None = None
    slicing_xi: float | None = None
    detail: DetailSpec | None = None
    ice: IceCrystals | None = None
    velocity_source: str = ""
    water: tuple[float, float] | None = None

    def __post_init__(self):
        if self.ice is not None and self.species != "ice":
            raise SceneError(f"medium {self.name}: warpsky:ice:* orients ice crystals; this field is "
                             f"{self.species or 'not a species field'}, not field:ice")
        if self.detail is not None and not isinstance(self.detail, DetailSpec):
            raise SceneError(f"medium {self.name}: detail must be a DetailSpec or None, got {self.detail!r}")
        if self.slicing_xi is not None and not (math.isfinite(self.slicing_xi) and self.slicing_xi >= 0.0):
            raise SceneError(f"medium {self.name}: warpsky:slicing:xi must be a finite phase value >= 0 [1/sr], "
                             f"got {self.slicing_xi}")
        if self.species is not None and self.species not in SPECIES_NAMES:
            raise SceneError(f"unknown species {self.species!r}; known: {', '.join(SPECIES_NAMES)}")
        dens = np.asarray(self.density)
        if dens.ndim != 3 or min(dens.shape) < 1:
            raise SceneError(f"medium {self.name}: density must be a non-empty 3-D grid, got shape {dens.shape}")
        dens = np.ascontiguousarray(dens, dtype=np.float32)
        low, high = float(dens.min()), float(dens.max())
        if not (low >= 0.0 and math.isfinite(high)):  # a NaN makes both false: count what is wrong only then
            bad = int(np.count_nonzero(~np.isfinite(dens)))
            neg = int(np.count_nonzero(dens < 0.0))
            raise SceneError(
                f"medium {self.name}: field {self.source or '(in memory)'} has {bad} NaN/Inf and {neg} negative "
                "values; expected finite values >= 0"
            )
        object.__setattr__(self, "density", dens)
        xf = np.asarray(self.world_from_index, dtype=np.float64)
        if xf.shape != (4, 4) or not np.all(np.isfinite(xf)) or abs(np.linalg.det(xf[:3, :3])) < 1e-300:
            raise SceneError(f"medium {self.name}: world_from_index must be an invertible finite 4x4 affine matrix")
        object.__setattr__(self, "world_from_index", xf)
        scale = _vec3(self.extinction_scale, f"medium {self.name}: extinction scale")
        if np.any(scale < 0.0):
            raise SceneError(f"medium {self.name}: extinction scale must be >= 0 1/m, got {scale.tolist()}")
        object.__setattr__(self, "extinction_scale", scale)
        albedo = _vec3(self.albedo, f"medium {self.name}: albedo")
        if np.any(albedo < 0.0) or np.any(albedo > 1.0):
            raise SceneError(f"medium {self.name}: albedo must lie in [0, 1], got {albedo.tolist()}")
        object.__setattr__(self, "albedo", albedo)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(n) for n in self.density.shape)

    @property
    def has_detail(self) -> bool:
        """Whether animated detail changes this medium's density (a :class:`DetailSpec` with amplitude > 0)."""
        return self.detail is not None and self.detail.active

    @property
    def voxel_size(self) -> np.ndarray:
        """Length in metres of one index step along each index axis."""
        return np.linalg.norm(self.world_from_index[:3, :3], axis=0)

    def world_corners(self) -> np.ndarray:
        """The 8 world-space corners [m] of the index box ``[-0.5, n-0.5]^3``, shape (8, 3)."""
        lo, hi = -0.5, np.array(self.shape) - 0.5
        corners = np.array([[x, y, z, 1.0] for x in (lo, hi[0]) for y in (lo, hi[1]) for z in (lo, hi[2])])
        return (corners @ self.world_from_index.T)[:, :3]

    def __repr__(self) -> str:
        return (
            f"VoxelMedium({self.name!r}, shape={self.shape}, voxel_size={np.round(self.voxel_size, 4).tolist()} m, "
            f"extinction_scale={self.extinction_scale.tolist()} 1/m, albedo={self.albedo.tolist()}, "
            f"{self.species if self.species else repr(self.phase)})"
        )


@dataclass(frozen=True)
class Ground:
    """An infinite horizontal Lambertian plane.

    Attributes:
        height: World Y of the plane [m].
        albedo: Diffuse reflectance, RGB in [0, 1].
        name: Prim path or label.
        albedo_map: Optional albedo texture (``warpsky:albedoMap``), used by the stratiform pass; see
            :class:`~warpsky.model.stratiform.GroundTexture`.
    """

    height: float = 0.0
    albedo: np.ndarray = field(default_factory=lambda: np.full(3, 0.3))
    name: str = "ground"
    albedo_map: GroundTexture | None = None

    def __post_init__(self):
        if not math.isfinite(self.height):
            raise SceneError(f"ground {self.name}: height must be finite, got {self.height}")
        albedo = _vec3(self.albedo, f"ground {self.name}: albedo")
        if np.any(albedo < 0.0) or np.any(albedo > 1.0):
            raise SceneError(f"ground {self.name}: albedo must lie in [0, 1], got {albedo.tolist()}")
        object.__setattr__(self, "albedo", albedo)


#: Bruneton's (2017) and Hillaire's (2020) Earth aerosols: sea-level scattering and absorption [1/m], scale height
#: [m], Henyey-Greenstein g; and ozone's peak absorption [1/m] at 680 / 550 / 440 nm with its layer.
EARTH_AEROSOLS = {"mie_scattering": np.full(3, 3.996e-6), "mie_absorption": np.full(3, 4.44e-7),
                  "mie_scale_height": 1200.0, "mie_g": 0.8}
EARTH_OZONE = {"ozone_absorption": np.array([6.5e-7, 1.881e-6, 8.5e-8]), "ozone_altitude": 25000.0,
               "ozone_width": 15000.0}
#: Bruneton's (2017) Earth radius at sea level [m].
EARTH_RADIUS = 6_360_000.0
#: The Earth's air as USD attributes (``warpsky:atmosphere:NAME``: value, in metres): Bruneton's and Hillaire's
#: aerosols and ozone over a round earth, what the shipped stages author.
EARTH_AIR_ATTRIBUTES = {
    "planetRadius": EARTH_RADIUS,
    "mieScattering": tuple(EARTH_AEROSOLS["mie_scattering"].tolist()),
    "mieAbsorption": tuple(EARTH_AEROSOLS["mie_absorption"].tolist()),
    "mieScaleHeight": EARTH_AEROSOLS["mie_scale_height"],
    "mieAnisotropy": EARTH_AEROSOLS["mie_g"],
    "ozoneAbsorption": tuple(EARTH_OZONE["ozone_absorption"].tolist()),
    "ozoneAltitude": EARTH_OZONE["ozone_altitude"],
    "ozoneWidth": EARTH_OZONE["ozone_width"],
}
#: The smallest round planet [m]: its air (tens of km thick) must stay thin beside its radius.
MIN_PLANET_RADIUS = 1.0e6


@dataclass(frozen=True)
class Atmosphere:
    """Air as Riley 2004 §4.1 models it: Rayleigh scattering, density falling exponentially with altitude.

    ========================= ============================= ====== ======================= ========================
    attribute (USD)           field                         unit   default                 meaning
    ========================= ============================= ====== ======================= ========================
    ``warpsky:atmosphere:``   ``beta_sea_level``            1/m    Riley Table 3:          scattering (= extinction)
    ``betaSeaLevel`` color3f                                       5.8e-6, 1.35e-5,        coefficient at sea level
                                                                   3.31e-5                 per channel
    ``...:scaleHeight`` float ``scale_height``              m      8000                    1/γ of Eq. 10
    ``...:altitude`` float    ``altitude``                  m      0                       altitude above sea level
                                                                                           of the stage's y = 0
    ``...:multiple            ``multiple_scattering``       --     true                    add the light the air
    Scattering`` bool                                                                      scatters more than once
                                                                                           (Hillaire 2020 table);
                                                                                           false: Riley's single-
                                                                                           scattering sky exactly
    ``...:mieScattering``     ``mie_scattering``            1/m    0 (none)                aerosols' scattering
    color3f                                                        (Earth: 3.996e-6)       coefficient at sea level
    ``...:mieAbsorption``     ``mie_absorption``            1/m    0                       aerosols' absorption at
    color3f                                                        (Earth: 4.44e-7)        sea level
    ``...:mieScaleHeight``    ``mie_scale_height``          m      1200                    aerosols' scale height
    ``...:mieAnisotropy``     ``mie_g``                     --     0.8                     Henyey-Greenstein g of
                                                                                           the aerosols' phase
    ``...:ozoneAbsorption``   ``ozone_absorption``          1/m    0 (none)                ozone's absorption at its
    color3f                                                        (Earth: 6.5e-7,         peak altitude
                                                                   1.881e-6, 8.5e-8)
    ``...:ozoneAltitude``     ``ozone_altitude``            m      25000                   the layer's peak; its
    ``...:ozoneWidth``        ``ozone_width``               m      15000                   density falls linearly
                                                                                           to 0 this far above and
                                                                                           below
    ``...:planetRadius``      ``planet_radius``             m      0 (flat earth)          radius of sea level; > 0:
    float                                                          (Earth: 6.36e6)         a round earth (air mass
                                                                                           and horizon of a sphere,
                                                                                           twilight after sunset)
    ========================= ============================= ====== ======================= ========================

    The Earth values are Bruneton's (2017) and Hillaire's (2020) reference atmosphere; the defaults keep Riley's
    pure Rayleigh air. The sun's irradiance is the DistantLight's, taken as outside the atmosphere.
    """

    beta_sea_level: np.ndarray = field(default_factory=lambda: np.array([5.8e-6, 1.35e-5, 3.31e-5]))
    scale_height: float = 8000.0
    altitude: float = 0.0
    name: str = "atmosphere"
    multiple_scattering: bool = True
    mie_scattering: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mie_absorption: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mie_scale_height: float = 1200.0
    mie_g: float = 0.8
    ozone_absorption: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ozone_altitude: float = 25000.0
    ozone_width: float = 15000.0
    planet_radius: float = 0.0

    def __post_init__(self):
        beta = _vec3(self.beta_sea_level, f"atmosphere {self.name}: betaSeaLevel")
        if np.any(beta < 0.0):
            raise SceneError(f"atmosphere {self.name}: betaSeaLevel must be >= 0 [1/m], got {beta.tolist()}")
        object.__setattr__(self, "beta_sea_level", beta)
        if not (math.isfinite(self.scale_height) and self.scale_height > 0.0):
            raise SceneError(f"atmosphere {self.name}: scaleHeight must be a positive length [m], "
                             f"got {self.scale_height}")
        if not math.isfinite(self.altitude):
            raise SceneError(f"atmosphere {self.name}: altitude must be finite [m], got {self.altitude}")
        for key, attr in (("mie_scattering", "mieScattering"), ("mie_absorption", "mieAbsorption"),
                          ("ozone_absorption", "ozoneAbsorption")):
            value = _vec3(getattr(self, key), f"atmosphere {self.name}: {attr}")
            if np.any(value < 0.0) or not np.all(np.isfinite(value)):
                raise SceneError(f"atmosphere {self.name}: {attr} must be finite and >= 0 [1/m], got {value.tolist()}")
            object.__setattr__(self, key, value)
        for key, attr in (("mie_scale_height", "mieScaleHeight"), ("ozone_width", "ozoneWidth")):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0.0):
                raise SceneError(f"atmosphere {self.name}: {attr} must be a positive length [m], got {value}")
        if not (math.isfinite(self.ozone_altitude) and self.ozone_altitude >= 0.0):
            raise SceneError(f"atmosphere {self.name}: ozoneAltitude must be a length >= 0 [m], "
                             f"got {self.ozone_altitude}")
        if not (math.isfinite(self.mie_g) and -1.0 < self.mie_g < 1.0):
            raise SceneError(f"atmosphere {self.name}: mieAnisotropy must lie in (-1, 1), got {self.mie_g}")
        if not (math.isfinite(self.planet_radius) and (self.planet_radius == 0.0
                                                       or self.planet_radius >= MIN_PLANET_RADIUS)):
            raise SceneError(f"atmosphere {self.name}: planetRadius must be 0 (a flat earth) or a radius >= "
                             f"{MIN_PLANET_RADIUS:g} m, got {self.planet_radius}")

    @property
    def gamma(self) -> float:
        """γ = 1 / scale height [1/m]."""
        return 1.0 / self.scale_height

    @property
    def has_aerosols(self) -> bool:
        return bool(np.any(self.mie_scattering > 0.0) or np.any(self.mie_absorption > 0.0))

    @property
    def has_ozone(self) -> bool:
        return bool(np.any(self.ozone_absorption > 0.0))

    @property
    def round(self) -> bool:
        """Whether the earth is a sphere (``planet_radius`` > 0) rather than Riley's flat earth."""
        return self.planet_radius > 0.0

    @property
    def mixed(self) -> bool:
        """Whether the air holds more than Riley's Rayleigh gas (aerosols or ozone): its sky is then integrated
        numerically instead of in Riley's closed form."""
        return self.has_aerosols or self.has_ozone


@dataclass(frozen=True)
class Scene:
    """Everything a renderer needs at one time code.

    Attributes:
        camera: The camera to render from.
        sun: The sun, or None for a scene lit by nothing (renders black).
        media: Participating media; their extinctions add where they overlap.
        stratiform_layers: Stratiform cloud layers (Bouthors 2006), rendered by the stratiform pass and composited
            with the media by depth.
        ground: Optional ground plane.
        atmosphere: Optional air (sky, aerial perspective, reddened sunlight); None: black background.
        time_code: USD time code this scene was read at (``nan`` for the default time).
        source: Stage file path, for metadata.
        resolution: Image size (width, height) authored on the stage's render settings, if any.
        time_codes_per_second: The stage's ``timeCodesPerSecond`` (USD's default 24), for :attr:`time_s`.
        extra_suns: Further DistantLights after the first (e.g. a moon); every pass runs once per light and the
            radiance adds up (light transport is linear in the lights).
        dome: The environment (``UsdLuxDomeLight``), or None (also for a black dome).
        meshes: Opaque Lambertian surfaces (``UsdGeomMesh``, e.g. terrain), ray cast through Warp's BVH
            (:class:`~warpsky.model.terrain.TerrainMesh`).
        decks: Constant-density clouds between two height fields about a mean plane, with the haze
            below them (Max 1986; :class:`~warpsky.model.deck.CloudDeck`).
        fogs: Fog whose extinction is a sum of functions with closed-form line integrals (Biri et al. 2002;
            :class:`~warpsky.model.fog.AnalyticFog`).
    """

    camera: Camera
    sun: Sun | None = None
    media: tuple[VoxelMedium, ...] = ()
    ground: Ground | None = None
    atmosphere: Atmosphere | None = None
    time_code: float = float("nan")
    source: str = ""
    resolution: tuple[int, int] | None = None
    time_codes_per_second: float = 24.0
    stratiform_layers: tuple[StratiformLayer, ...] = ()
    extra_suns: tuple[Sun, ...] = ()
    dome: Dome | None = None
    meshes: tuple = ()
    decks: tuple = ()
    fogs: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "media", tuple(self.media))
        for name in ("meshes", "decks", "fogs"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "extra_suns", tuple(self.extra_suns))
        if self.dome is not None and not self.dome.active:
            object.__setattr__(self, "dome", None)  # a black dome renders exactly as none
        object.__setattr__(self, "stratiform_layers", tuple(self.stratiform_layers))
        if not (math.isfinite(self.time_codes_per_second) and self.time_codes_per_second > 0.0):
            raise SceneError(f"timeCodesPerSecond must be positive, got {self.time_codes_per_second}")

    @property
    def time_s(self) -> float:
        """Scene time [s]: ``time_code / time_codes_per_second`` (0 at the default time code)."""
        return 0.0 if math.isnan(self.time_code) else self.time_code / self.time_codes_per_second

    @property
    def species(self) -> tuple[str, ...]:
        """Species of the voxel media, in first-seen order (the order of their phase tables on the device)."""
        return tuple(dict.fromkeys(m.species for m in self.media if m.species is not None))
