"""The scenery family: a seeded set of terrain stages with analytic fog (Biri et al. 2002), a height-field cloud
deck with haze (Max 1986) or a voxel cloud cut by a ridge, so the techniques that leave fog, terrain and decks to
their single-scattering passes can be measured against the path tracer, which traces all of them.

Every decision comes from one ``numpy.random.Generator`` seeded by ``seed`` (same seed: same files). Members
alternate between the halves (even index ``tune``, odd ``test``), kinds and Earth air are dealt from balanced
shuffled lists per half, and sun elevations are spread evenly over the family and dealt to the halves alternately:

============== ===============================================================================================
parameter      values
============== ===============================================================================================
kind           (two fogs of each kind and one of each other kind per six members of a half)
               ``thin_fog`` / ``thick_fog``: valley fog (a constant and a cosine wave of 0.3 x it, in a slab
               from below the valley floor to ``fog_depth_m`` above it) of optical depth 0.3-1.5 / 1.5-5 along
               the vertical from the valley floor to the fog's top, albedo 0.9-1, HG g 0.7-0.9;
               ``deck_haze``: a broken height-field deck 1.1-1.6 km above the valley floor (density 0.02-0.04 /m,
               albedo 1, g 0.85) with haze below it (1.5e-4-4e-4 /m, albedo 0.95, g 0.7), seen looking up;
               ``ridge_cloud``: a cumulus field (peak optical depth 4-30, albedo 1 or 0.9, HG g 0.85) whose base
               lies 150-300 m below the crest of a ridge across the valley, so the terrain cuts it;
               ``layer_fog``: a thin or a thick valley fog (as above) under a broken stratocumulus layer
               (Bouthors 2006; base 700-1200 m above the valley floor, at most 60-260 m thick, N0 1.2e8-2.4e8
               /m^3, so the thickest column's optical depth is 1.1-9.6; cover 45-75 %), appended after the
               other members from a generator of their own (the others stay as they were), alternating between
               the halves
terrain        a 4 km square mesh of 40 x 40 cells (3200 triangles): sine waves and two hills around a valley
               running north-south, and a ridge across it for ``ridge_cloud``; albedo 0.22, 0.24, 0.16. A grey
               plane (albedo 0.08) 20 m below the mesh's lowest point carries the view beyond its edges
sun            elevation 5-60 deg; azimuth 60-150 deg either side of the view (never in frame)
air            Earth air (:data:`~warpsky.model.scene.EARTH_AIR_ATTRIBUTES`, altitude 0) or none
camera         at the valley's south end, 60-200 m above the terrain, looking north along it (24 mm on a 36 x 24
               mm aperture), pitched down 2-6 deg over fog, up 8-14 deg under a deck, up 0-5 deg at a ridge
============== ===============================================================================================

Images are 96 x 64 (the stages' render settings), so path-traced references fit a CPU.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from evaluation.family_shapes import cumulus, peak_column
from evaluation.family_stages import (
    HALVES,
    _attribute,
    _balanced,
    _field,
    _interleaved,
    _set_transform,
    _spread,
    direction,
    rotation_towards,
)

#: Bumped whenever the generator's output changes for a seed.
SCENERY_VERSION = 1
KINDS = ("thin_fog", "thick_fog", "deck_haze", "ridge_cloud", "layer_fog")
#: The kinds each half is dealt from, in turn: six members per half hold two of each fog and one of the others.
KIND_CYCLE = ("thin_fog", "thick_fog", "deck_haze", "ridge_cloud", "thick_fog", "thin_fog")
#: Vertical optical depth from the valley floor to the fog's top, per fog kind.
FOG_OPTICAL_DEPTH = {"thin_fog": (0.3, 1.5), "thick_fog": (1.5, 5.0)}
#: The kinds whose stage holds valley fog (drawn from a fog kind's range).
FOGGY = (*FOG_OPTICAL_DEPTH, "layer_fog")
CLOUD_OPTICAL_DEPTH = (4.0, 30.0)
ELEVATION = (5.0, 60.0)
PITCH = {"thin_fog": (-6.0, -2.0), "thick_fog": (-6.0, -2.0), "deck_haze": (8.0, 14.0), "ridge_cloud": (0.0, 5.0),
         "layer_fog": (-6.0, -2.0)}
TERRAIN_SIZE = 4000.0  # [m]
TERRAIN_CELLS = 40
#: Height [m] the terrain's waves, hills and valley are added to: its lowest point stays above sea level (y = 0).
BASE_LEVEL = 450.0
TERRAIN_ALBEDO = (0.22, 0.24, 0.16)
LAKE_ALBEDO = 0.08
IMAGE_SIZE = (96, 64)
FOCAL_LENGTH, APERTURE = 24.0, (36.0, 24.0)
CLOUD_RESOLUTION = 32
#: Fog-under-a-layer members: the layer's map (texels per side), extent [m] and the ranges drawn.
LAYER_TEXELS = 48
LAYER_SIZE = 12000.0
LAYER_BASE = (700.0, 1200.0)  # above the valley floor [m]
LAYER_THICKNESS = (60.0, 260.0)  # the map's largest thickness [m]
LAYER_NUMBER_DENSITY = (1.2e8, 2.4e8)  # [1/m^3]
LAYER_COVER = (0.45, 0.75)


@dataclass
class SceneryPlan:
    """Everything drawn for one member (angles in degrees, lengths in metres, extinctions in 1/m)."""

    index: int
    half: str
    kind: str
    air: bool
    sun_elevation_deg: float
    sun_azimuth_deg: float  # relative to the view azimuth
    terrain_seed: int
    camera_height_m: float
    pitch_deg: float
    optical_depth: float  # fog: vertical, floor to top; ridge cloud: peak; deck: 0 (see the deck's fields)
    albedo: float
    g: float
    fog_depth_m: float
    deck_altitude_m: float
    deck_density: float
    deck_cover: float  # the pattern's constant c0 [m]: larger, fewer gaps
    haze: float
    shape_seed: int

    @property
    def name(self) -> str:
        return f"{self.index:02d}_{self.kind}"


def plan_scenery(seed: int, count: int, layered: int = 0) -> list[SceneryPlan]:
    """Draw ``count`` members from ``seed``, then ``layered`` fog-under-a-layer members from a generator of their
    own (see the module docstring)."""
    return _plan_plain(seed, count) + _plan_layered(seed, count, layered)


def _plan_plain(seed: int, count: int) -> list[SceneryPlan]:
    if count < 2:
        raise ValueError(f"a family needs at least 2 members (one per half), got {count}")
    rng = np.random.default_rng(seed)
    halves = [HALVES[i % 2] for i in range(count)]
    kind, air = [None] * count, [None] * count
    for half in HALVES:
        members = [i for i in range(count) if halves[i] == half]
        kinds, airs = _balanced(rng, KIND_CYCLE, len(members)), _balanced(rng, (True, False), len(members))
        for i, k, a in zip(members, kinds, airs, strict=True):
            kind[i], air[i] = k, a
    elevation = [0.0] * count
    for i, value in zip(_interleaved(rng, list(range(count)), halves), _spread(*ELEVATION, count, log=False),
                        strict=True):
        elevation[i] = value
    depth = [0.0] * count
    for k in KINDS:
        order = _interleaved(rng, [i for i in range(count) if kind[i] == k], halves)
        lo, hi = FOG_OPTICAL_DEPTH.get(k, CLOUD_OPTICAL_DEPTH if k == "ridge_cloud" else (0.0, 0.0))
        for i, value in zip(order, _spread(lo, hi, len(order), log=True) if hi > 0 else [0.0] * len(order),
                            strict=True):
            depth[i] = value
    return [_draw_member(rng, i, halves[i], kind[i], air[i], elevation[i], depth[i]) for i in range(count)]


def _plan_layered(seed: int, first: int, count: int) -> list[SceneryPlan]:
    """``count`` ``layer_fog`` members numbered from ``first``: per half, thin and thick fog in turn, Earth air
    alternating, the sun spread over ``ELEVATION``."""
    if count <= 0:
        return []
    rng = np.random.default_rng([seed, 1])
    elevations = _spread(*ELEVATION, count, log=False)
    order = rng.permutation(count)
    plans = []
    for n in range(count):
        half, turn = HALVES[(first + n) % 2], n // 2
        fog = ("thin_fog", "thick_fog")[turn % 2]
        depth = float(np.exp(rng.uniform(*np.log(FOG_OPTICAL_DEPTH[fog]))))
        plan = _draw_member(rng, first + n, half, "layer_fog", bool((turn + n) % 2), elevations[order[n]], depth)
        plans.append(plan)
    return plans


def _draw_member(rng, index, half, kind, air, elevation, depth) -> SceneryPlan:
    side = 1.0 if rng.random() < 0.5 else -1.0
    fog = kind in FOGGY
    return SceneryPlan(
        index=index, half=half, kind=kind, air=bool(air), sun_elevation_deg=float(elevation),
        sun_azimuth_deg=float(side * rng.uniform(60.0, 150.0)), terrain_seed=int(rng.integers(0, 2**31 - 1)),
        camera_height_m=float(rng.uniform(60.0, 200.0)), pitch_deg=float(rng.uniform(*PITCH[kind])),
        optical_depth=float(depth),
        albedo=float(rng.uniform(0.9, 1.0)) if fog else (float(rng.choice([1.0, 0.9])) if kind == "ridge_cloud"
                                                          else 1.0),
        g=float(rng.uniform(0.7, 0.9)) if fog else 0.85, fog_depth_m=float(rng.uniform(60.0, 180.0)),
        deck_altitude_m=float(rng.uniform(1100.0, 1600.0)), deck_density=float(rng.uniform(0.02, 0.04)),
        deck_cover=float(rng.uniform(20.0, 70.0)), haze=float(rng.uniform(3.0e-4, 6.0e-4)),
        shape_seed=int(rng.integers(0, 2**31 - 1)))


@dataclass(frozen=True)
class Terrain:
    """A seeded height field [m] over the square ``TERRAIN_SIZE`` centred on the origin: ``BASE_LEVEL`` plus sine
    waves, two hills, a valley along z through x = 0 and, when ``ridge`` > 0, a ridge across the valley at
    z = ``ridge_z``."""

    seed: int
    ridge: float = 0.0
    ridge_z: float = -600.0

    def heights(self, x, z) -> np.ndarray:
        rng = np.random.default_rng(self.seed)
        x, z = np.asarray(x, np.float64), np.asarray(z, np.float64)
        h = np.full(np.broadcast(x, z).shape, BASE_LEVEL)
        for wavelength, amplitude in ((2000.0, 45.0), (1000.0, 25.0), (500.0, 12.0), (250.0, 6.0)):
            for _ in range(2):
                angle, phase = rng.uniform(0.0, 2.0 * math.pi, 2)
                k = 2.0 * math.pi / wavelength
                h += amplitude * np.sin(k * (math.cos(angle) * x + math.sin(angle) * z) + phase)
        for _ in range(2):
            height, sigma = rng.uniform(150.0, 300.0), rng.uniform(300.0, 600.0)
            cx, cz = rng.choice([-1.0, 1.0]) * rng.uniform(900.0, 1600.0), rng.uniform(-1500.0, 1500.0)
            h += height * np.exp(-((x - cx) ** 2 + (z - cz) ** 2) / (2.0 * sigma**2))
        depth, width = rng.uniform(100.0, 180.0), rng.uniform(300.0, 450.0)
        h -= depth * np.exp(-(x**2) / (2.0 * width**2))
        if self.ridge > 0.0:
            h += self.ridge * np.exp(-((z - self.ridge_z) ** 2) / (2.0 * 250.0**2))
        return h

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(points (n^2, 3), triangles (2 (n-1)^2, 3)) on an n x n grid, n = ``TERRAIN_CELLS`` + 1, wound
        counter-clockwise seen from above."""
        n = TERRAIN_CELLS + 1
        axis = np.linspace(-0.5 * TERRAIN_SIZE, 0.5 * TERRAIN_SIZE, n)
        x, z = np.meshgrid(axis, axis, indexing="ij")
        points = np.stack([x, self.heights(x, z), z], axis=-1).reshape(-1, 3)
        i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
        a, b, c, d = i, i + n, i + 1, i + n + 1
        return points, np.stack([a, c, d, a, d, b], axis=-1).reshape(-1, 3).astype(np.int32)


def member_terrain(plan: SceneryPlan) -> Terrain:
    ridge = float(np.random.default_rng(plan.shape_seed).uniform(250.0, 400.0)) if plan.kind == "ridge_cloud" else 0.0
    return Terrain(plan.terrain_seed, ridge=ridge)


def build_scenery_member(plan: SceneryPlan) -> tuple[dict, Terrain, object]:
    """(record for family.json, terrain, the ridge cloud's :class:`CloudShape` or None)."""
    terrain = member_terrain(plan)
    floor = float(terrain.heights(0.0, np.linspace(-2000.0, 2000.0, 81)).min())  # the valley floor [m]
    lowest = float(terrain.mesh()[0][:, 1].min())
    eye_z = 1700.0
    eye = np.array([0.0, float(terrain.heights(0.0, eye_z)) + plan.camera_height_m, eye_z])
    if plan.kind in FOGGY:  # above the fog's top, looking down on it
        eye[1] = max(eye[1], floor + plan.fog_depth_m + 40.0)
    forward = direction(0.0, plan.pitch_deg)
    sun = direction(plan.sun_azimuth_deg, plan.sun_elevation_deg)
    record = {"name": plan.name, "stage": f"{plan.name}.usda", **asdict(plan), "valley_floor_m": floor,
              "lake_m": lowest - 20.0, "camera_position": eye.tolist(), "camera_forward": forward.tolist(),
              "sun_direction": sun.tolist(), "triangles": 2 * TERRAIN_CELLS**2}
    shape = None
    if plan.kind in FOGGY:
        top = floor + plan.fog_depth_m
        record.update(fog_floor_m=lowest - 50.0, fog_top_m=top, fog_extinction=plan.optical_depth / plan.fog_depth_m)
    if plan.kind == "layer_fog":
        rng = np.random.default_rng(plan.shape_seed + 2)
        record.update(layer_map=f"{plan.name}_layer.npy", layer_base_m=floor + float(rng.uniform(*LAYER_BASE)),
                      layer_size_m=LAYER_SIZE, layer_number_density=float(rng.uniform(*LAYER_NUMBER_DENSITY)))
        shape = layer_map(rng)
        record["layer_max_thickness_m"] = float(shape.max())
    elif plan.kind == "ridge_cloud":
        rng = np.random.default_rng(plan.shape_seed + 1)
        crest = float(terrain.heights(0.0, terrain.ridge_z))
        base = crest - float(rng.uniform(150.0, 300.0))
        shape = cumulus(rng, float(rng.uniform(1200.0, 1800.0)), base, CLOUD_RESOLUTION)
        offset = np.array([0.0, 0.0, terrain.ridge_z])
        shape = dataclasses.replace(shape, lower=shape.lower + offset, upper=shape.upper + offset)
        column, _ = peak_column(shape.density, shape.voxel_size)
        record.update(field=f"{plan.name}.npy", ridge_crest_m=crest, cloud_base_m=base,
                      extinction_scale=float(np.float32(plan.optical_depth / column)),
                      lower_m=shape.lower.tolist(), upper_m=shape.upper.tolist())
    elif plan.kind == "deck_haze":
        record.update(deck_mean_altitude_m=floor + plan.deck_altitude_m, haze_floor_m=lowest - 50.0)
    return record, terrain, shape


def layer_map(rng) -> np.ndarray:
    """A broken stratocumulus thickness map [m] (``LAYER_TEXELS`` square, axis 0 = x): cosine waves of 6-1.5 km
    cut at the drawn cover's quantile and scaled to the drawn largest thickness."""
    n = LAYER_TEXELS
    axis = (np.arange(n) + 0.5) / n * LAYER_SIZE
    x, z = np.meshgrid(axis, axis, indexing="ij")
    field = np.zeros((n, n))
    for wavelength in np.geomspace(6000.0, 1500.0, 5):
        angle, phase = rng.uniform(0.0, 2.0 * math.pi, 2)
        k = 2.0 * math.pi / wavelength
        field += (wavelength / 6000.0) ** 0.5 * np.cos(k * (math.cos(angle) * x + math.sin(angle) * z) + phase)
    cut = np.quantile(field, 1.0 - rng.uniform(*LAYER_COVER))
    thick = np.clip(field - cut, 0.0, None)
    return (thick / thick.max() * rng.uniform(*LAYER_THICKNESS)).astype(np.float32)


def make_scenery_family(out: str | Path, *, seed: int = 2028, count: int = 12, layered: int = 0,
                        log=None) -> Path:
    """Write ``count`` members and ``layered`` fog-under-a-layer members (a ``.usda`` stage each, a ``.npy`` field
    for a ridge cloud or a layer's map) and ``family.json`` into ``out``; returns the path of family.json."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for plan in plan_scenery(seed, count, layered):
        record, terrain, shape = build_scenery_member(plan)
        if plan.kind == "layer_fog":
            np.save(out / record["layer_map"], shape)
        elif shape is not None:
            np.save(out / record["field"], shape.density)
        write_scenery_stage(out / record["stage"], record, terrain, seed=seed)
        records.append(record)
        if log is not None:
            log(f"{record['stage']:<20} {record['half']:<4} tau {record['optical_depth']:6.3g}  albedo "
                f"{record['albedo']:.3f} g {record['g']:.2f}  sun {record['sun_elevation_deg']:5.1f} deg "
                f"az {record['sun_azimuth_deg']:+6.1f}  air {int(record['air'])}")
    blob = {"generator": "evaluation/scripts/make_scenery_family.py", "version": SCENERY_VERSION, "profile": "scenery",
            "seed": seed, "count": count + layered, "image_size": list(IMAGE_SIZE), "members": records}
    path = out / "family.json"
    path.write_text(json.dumps(blob, indent=1) + "\n")
    return path


def _write_terrain(stage, terrain: Terrain) -> None:
    from pxr import Gf, UsdGeom, Vt

    points, triangles = terrain.mesh()
    mesh = UsdGeom.Mesh.Define(stage, "/World/Terrain")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(triangles.reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*points.min(axis=0).tolist()),
                                         Gf.Vec3f(*points.max(axis=0).tolist())]))
    _attribute(mesh.GetPrim(), "warpsky:albedo", "Color3f", Gf.Vec3f(*TERRAIN_ALBEDO))


def _kind(prim, kind: str) -> None:
    """``uniform token warpsky:kind = kind`` on ``prim``."""
    from pxr import Sdf

    prim.CreateAttribute("warpsky:kind", Sdf.ValueTypeNames.Token, variability=Sdf.VariabilityUniform).Set(kind)


def _write_fog(stage, record: dict) -> None:
    from pxr import Gf, Vt

    fog = stage.DefinePrim("/World/Fog", "Xform")
    _kind(fog, "analyticFog")
    c0 = record["fog_extinction"]
    _attribute(fog, "warpsky:fog:constant", "Float", c0)
    _attribute(fog, "warpsky:fog:cosine:amplitudes", "FloatArray", Vt.FloatArray([0.3 * c0]))
    _attribute(fog, "warpsky:fog:cosine:waveVectors", "Float3Array", Vt.Vec3fArray([Gf.Vec3f(0.012, 0.0, 0.007)]))
    _attribute(fog, "warpsky:fog:floor", "Float", record["fog_floor_m"])
    _attribute(fog, "warpsky:fog:top", "Float", record["fog_top_m"])
    _attribute(fog, "warpsky:fog:albedo", "Color3f", Gf.Vec3f(record["albedo"]))
    _attribute(fog, "warpsky:fog:g", "Float", record["g"])


def _write_deck(stage, record: dict) -> None:
    from pxr import Gf, Vt

    rng = np.random.default_rng(record["shape_seed"])
    wavelengths = np.geomspace(3000.0, 600.0, 5)
    angles = rng.uniform(0.0, 2.0 * math.pi, len(wavelengths))
    k = 2.0 * math.pi / wavelengths
    deck = stage.DefinePrim("/World/Deck", "Xform")
    _kind(deck, "heightFieldClouds")
    values = {"meanAltitude": ("Float", record["deck_mean_altitude_m"]),
              "polynomial": ("FloatArray", Vt.FloatArray([record["deck_cover"]])),
              "waveVectors": ("Float2Array", Vt.Vec2fArray([Gf.Vec2f(float(kk * math.cos(a)), float(kk * math.sin(a)))
                                                            for kk, a in zip(k, angles, strict=True)])),
              "amplitudes": ("FloatArray", Vt.FloatArray((100.0 * (wavelengths / 3000.0) ** 0.5).tolist())),
              "phases": ("FloatArray", Vt.FloatArray(rng.uniform(0.0, 2.0 * math.pi, len(k)).tolist())),
              "equatorRounding": ("Float", 150.0), "bottomDepth": ("Float", 120.0),
              "density": ("Float", record["deck_density"]), "albedo": ("Color3f", Gf.Vec3f(1.0)),
              "g": ("Float", record["g"])}
    for name, (type_name, value) in values.items():
        _attribute(deck, f"warpsky:hf:{name}", type_name, value)
    _attribute(deck, "warpsky:haze:density", "Color3f", Gf.Vec3f(record["haze"]))
    _attribute(deck, "warpsky:haze:albedo", "Color3f", Gf.Vec3f(0.95))
    _attribute(deck, "warpsky:haze:g", "Float", 0.7)
    _attribute(deck, "warpsky:haze:floor", "Float", record["haze_floor_m"])


def _write_cloud(stage, record: dict) -> None:
    from pxr import Gf, UsdVol

    volume = UsdVol.Volume.Define(stage, "/World/Cloud")
    volume.CreateExtentAttr([Gf.Vec3f(*record["lower_m"]), Gf.Vec3f(*record["upper_m"])])
    _field(stage, volume, "density", record["field"], record["extinction_scale"])
    _attribute(volume.GetPrim(), "warpsky:albedo", "Float", record["albedo"])
    _attribute(volume.GetPrim(), "warpsky:phase", "Token", "hg")
    _attribute(volume.GetPrim(), "warpsky:phase:g", "Float", record["g"])


def _write_layer_fog(stage, record: dict) -> None:
    from pxr import Gf, Sdf

    _write_fog(stage, record)
    layer = stage.DefinePrim("/World/Stratocumulus", "Xform")
    _kind(layer, "stratiformLayer")
    layer.CreateAttribute("warpsky:stratiform:thicknessMap", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath(f"./{record['layer_map']}"))
    _attribute(layer, "warpsky:stratiform:size", "Float2", Gf.Vec2f(record["layer_size_m"], record["layer_size_m"]))
    _attribute(layer, "warpsky:stratiform:numberDensity", "Float", record["layer_number_density"])
    _set_transform(layer, np.eye(3), (0.0, record["layer_base_m"], 0.0))


def write_scenery_stage(path: Path, record: dict, terrain: Terrain, *, seed: int) -> Path:
    """One member as a Y-up, metre stage: camera, sun, terrain mesh, lake plane, its fog, deck or cloud, Earth air
    when drawn, 96 x 64 render settings."""
    from pxr import Gf, Usd, UsdGeom, UsdLux, UsdRender

    from warpsky.usd.authoring import author_earth_air

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = (
        f"warpsky scenery family (seed {seed}) member {record['name']}, {record['half']} half: {record['kind']}, "
        f"sun {record['sun_elevation_deg']:.1f} deg, Earth air {'on' if record['air'] else 'off'}. Written by "
        "evaluation/scripts/make_scenery_family.py.")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.CreateFocalLengthAttr(FOCAL_LENGTH)
    camera.CreateHorizontalApertureAttr(APERTURE[0])
    camera.CreateVerticalApertureAttr(APERTURE[1])
    camera.CreateClippingRangeAttr(Gf.Vec2f(1.0, 60000.0))
    _set_transform(camera.GetPrim(), rotation_towards(-np.array(record["camera_forward"])), record["camera_position"])
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun.CreateAngleAttr(0.53)
    _set_transform(sun.GetPrim(), rotation_towards(record["sun_direction"]), (0.0, 0.0, 0.0))
    _write_terrain(stage, terrain)
    lake = UsdGeom.Plane.Define(stage, "/World/Lake")
    lake.CreateAxisAttr(UsdGeom.Tokens.y)
    lake.CreateWidthAttr(200000.0)
    lake.CreateLengthAttr(200000.0)
    lake.AddTranslateOp().Set(Gf.Vec3d(0.0, record["lake_m"], 0.0))
    _attribute(lake.GetPrim(), "warpsky:albedo", "Color3f", Gf.Vec3f(LAKE_ALBEDO))
    {"thin_fog": _write_fog, "thick_fog": _write_fog, "deck_haze": _write_deck,
     "ridge_cloud": _write_cloud, "layer_fog": _write_layer_fog}[record["kind"]](stage, record)
    if record["air"]:
        atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
        _attribute(atmosphere, "warpsky:atmosphere:altitude", "Float", 0.0)
        author_earth_air(atmosphere)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateCameraRel().SetTargets([camera.GetPath()])
    settings.CreateResolutionAttr(Gf.Vec2i(*IMAGE_SIZE))
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Export(str(path))
    return path
