"""The validation family: a seeded set of cloud stages that fast techniques are tuned on (one half) and measured
on (the other half).

Every decision is drawn from one ``numpy.random.Generator`` seeded by ``seed``, so a seed gives byte-identical
files on the same machine. Members alternate between the halves (even index: ``tune``, odd: ``test``) and each
half draws its categorical values from a balanced, shuffled list, so with at least ten members both halves hold
every kind, albedo, phase, lighting and ground/atmosphere combination value. Continuous values are spread
evenly (optical depth log-evenly per kind, sun elevation evenly) and dealt to the halves alternately, so the
family's extremes are always present:

===================== =========================================================================================
parameter             values
===================== =========================================================================================
kind                  cumulus, stratocumulus, towering (anvil), cirrus (thin, tenuous), inside (camera in it)
peak optical depth    0.1 .. 300 overall, log-spread per kind: cirrus 0.1-3, stratocumulus 1-100, inside
                      0.3-30, cumulus 1-300, towering 3-300 (see below for how it is measured)
albedo                1, 0.9 (``warpsky:albedo``)
phase                 ``hg`` with g = 0.85, ``cloud`` (tabulated Mie, the field is ``field:cloud``), ``isotropic``
sun elevation         2 .. 90 deg
lighting              front (sun behind the camera), side, back (sun behind the cloud; moved sideways in 5 deg
                      steps until it lies 40 deg or more from the view axis, so the sun's disk is never in frame)
ground, atmosphere    with and without each (a grey ``Plane`` at y = 0, a Rayleigh ``Scope`` with scale height
                      8 km)
===================== =========================================================================================

The peak optical depth is ``warpsky:extinctionScale`` x the largest line integral of the field along the grid's
x, y or z lines (the straight line through the cloud's thickest part); the scale is set so it hits the target.
Cameras are square (128 x 128 by the stage's render settings), placed so the occupied voxels fill about 90% of the
frame's half-width, at least 30 m above the ground; the ``inside`` kind puts the camera at the blob's centre.

The ``thick`` profile (:data:`PROFILES`) draws the same way from other values: kinds cumulus (peak optical depth
100-1000), stratocumulus (100-500, seen from below or above), ``storm`` (150-1000: a towering cell whose anvil is
ice, ``ICE_OPTICAL_DEPTH`` of the droplets' depth, over a rain shaft of optical depth ``RAIN_OPTICAL_DEPTH`` in a
Volume of its own; always the Mie ``cloud`` phase) and inside (100-300); albedo 1 and 0.99; ``hg`` and ``cloud``
phase; 64 x 64 images, so path-traced references fit a CPU.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from evaluation.family_shapes import SHAPES, CloudShape, peak_column, storm_species

#: Bumped whenever the generator's output changes for a seed.
FAMILY_VERSION = 1
HALVES = ("tune", "test")
#: Horizontal size [m] and cloud base altitude [m] ranges per kind.
FOOTPRINT = {"cumulus": (1000.0, 2600.0), "stratocumulus": (2000.0, 3000.0), "towering": (1800.0, 2800.0),
             "cirrus": (1500.0, 3000.0), "inside": (1200.0, 2500.0)}
BASE = {"cumulus": (700.0, 1500.0), "stratocumulus": (1200.0, 2000.0), "towering": (600.0, 1200.0),
        "cirrus": (5000.0, 7000.0), "inside": (800.0, 1500.0)}
#: Camera pitch ranges [deg] per kind (positive: looking up); stratocumulus is seen from below or from above.
PITCH = {"cumulus": (-12.0, 12.0), "stratocumulus": (20.0, 40.0), "towering": (-5.0, 15.0),
         "cirrus": (25.0, 50.0), "inside": (-10.0, 10.0)}
HG_G = 0.85
#: Sun azimuth relative to the camera's view azimuth [deg] per lighting.
LIGHTING = {"front": 180.0, "side": 90.0, "back": 0.0}
ELEVATION = (2.0, 90.0)
FOCAL_LENGTH = 30.0
APERTURE = 24.0  # square film back, same units as FOCAL_LENGTH
FILL = 0.9
MIN_CAMERA_HEIGHT = 30.0  # [m]
SUN_CLEARANCE = 40.0  # [deg] smallest angle between the sun and the view axis
GROUND_ALBEDO = 0.2
SCALE_HEIGHT = 8000.0  # [m]
#: A storm's anvil ice: its peak optical depth as a fraction of the droplets'; its rain shaft's peak optical depth.
ICE_OPTICAL_DEPTH = 0.1
RAIN_OPTICAL_DEPTH = 3.0


@dataclass(frozen=True)
class FamilyProfile:
    """What a family draws from: its kinds and their peak optical depths, albedos, phases and image size."""

    name: str
    optical_depth: dict  # kind -> (lowest, highest) peak optical depth
    albedos: tuple
    phases: tuple
    image_size: int

    @property
    def kinds(self) -> tuple:
        return tuple(self.optical_depth)


#: ``thin``: the validation family of every kind from cirrus to cumulus. ``thick``: storms and dense decks of peak
#: optical depth 100-1000, where light scatters hundreds of times.
PROFILES = {
    "thin": FamilyProfile("thin", {"cumulus": (1.0, 300.0), "stratocumulus": (1.0, 100.0),
                                   "towering": (3.0, 300.0), "cirrus": (0.1, 3.0), "inside": (0.3, 30.0)},
                          albedos=(1.0, 0.9), phases=("hg", "cloud", "isotropic"), image_size=128),
    "thick": FamilyProfile("thick", {"cumulus": (100.0, 1000.0), "stratocumulus": (100.0, 500.0),
                                     "storm": (150.0, 1000.0), "inside": (100.0, 300.0)},
                           albedos=(1.0, 0.99), phases=("hg", "cloud"), image_size=64),
}
for _kind, _parent in (("storm", "towering"),):  # a storm cell is a towering cloud with rain and an ice anvil
    FOOTPRINT[_kind], BASE[_kind], PITCH[_kind] = FOOTPRINT[_parent], BASE[_parent], PITCH[_parent]
#: The thin family's values, as the tests and docs name them.
OPTICAL_DEPTH = PROFILES["thin"].optical_depth
ALBEDOS = PROFILES["thin"].albedos
PHASES = PROFILES["thin"].phases
IMAGE_SIZE = PROFILES["thin"].image_size


@dataclass
class MemberPlan:
    """Everything drawn for one member before its field exists (angles in degrees, lengths in metres)."""

    index: int
    half: str
    kind: str
    optical_depth_target: float
    albedo: float
    phase: str
    lighting: str
    sun_elevation_deg: float
    ground: bool
    atmosphere: bool
    footprint_m: float
    base_m: float
    view_azimuth_deg: float
    view_pitch_deg: float
    sun_jitter_deg: float
    shape_seed: int

    @property
    def name(self) -> str:
        return f"{self.index:02d}_{self.kind}"


def _balanced(rng: np.random.Generator, values, count: int) -> list:
    """``count`` values cycling through ``values`` (each present once ``count >= len(values)``), shuffled."""
    cycle = [values[i % len(values)] for i in range(count)]
    return [cycle[i] for i in rng.permutation(count)]


def _interleaved(rng: np.random.Generator, indices: list[int], halves: list[str]) -> list[int]:
    """``indices`` shuffled within each half, then dealt alternately from the halves (random half first)."""
    groups = [[i for i in indices if halves[i] == h] for h in HALVES]
    groups = [[g[j] for j in rng.permutation(len(g))] for g in groups]
    if rng.random() < 0.5:
        groups.reverse()
    order = []
    for k in range(max(len(g) for g in groups)):
        order += [g[k] for g in groups if k < len(g)]
    return order


def _spread(lo: float, hi: float, count: int, *, log: bool) -> list[float]:
    """``count`` values evenly from ``lo`` to ``hi`` (both included; the middle when ``count == 1``)."""
    steps = [0.5] if count == 1 else [j / (count - 1) for j in range(count)]
    if log:
        return [float(lo * (hi / lo) ** s) for s in steps]
    return [float(lo + (hi - lo) * s) for s in steps]


def plan_members(seed: int, count: int, profile: FamilyProfile = PROFILES["thin"]) -> list[MemberPlan]:
    """Draw the parameters of ``count`` members of ``profile`` from ``seed`` (see the module docstring)."""
    if count < 2:
        raise ValueError(f"a family needs at least 2 members (one per half), got {count}")
    rng = np.random.default_rng(seed)
    halves = [HALVES[i % 2] for i in range(count)]
    drawn: dict[str, list] = {k: [None] * count for k in ("kind", "albedo", "phase", "lighting", "ground",
                                                          "atmosphere")}
    choices = {"kind": profile.kinds, "albedo": profile.albedos, "phase": profile.phases, "lighting": tuple(LIGHTING),
               "ground": (True, False), "atmosphere": (True, False)}
    for half in HALVES:
        members = [i for i in range(count) if halves[i] == half]
        for name, values in choices.items():
            for i, value in zip(members, _balanced(rng, values, len(members)), strict=True):
                drawn[name][i] = value
    depth = [0.0] * count
    for kind in profile.kinds:
        order = _interleaved(rng, [i for i in range(count) if drawn["kind"][i] == kind], halves)
        for i, value in zip(order, _spread(*profile.optical_depth[kind], len(order), log=True), strict=True):
            depth[i] = value
    elevation = [0.0] * count
    order = _interleaved(rng, list(range(count)), halves)
    for i, value in zip(order, _spread(*ELEVATION, count, log=False), strict=True):
        elevation[i] = value
    plans = []
    for i in range(count):
        kind = drawn["kind"][i]
        pitch = rng.uniform(*PITCH[kind])
        if kind == "stratocumulus" and rng.random() < 0.5:
            pitch = -pitch  # seen from above
        plans.append(MemberPlan(
            index=i, half=halves[i], kind=kind, optical_depth_target=depth[i], albedo=drawn["albedo"][i],
            phase="cloud" if kind == "storm" else drawn["phase"][i], lighting=drawn["lighting"][i],
            sun_elevation_deg=elevation[i],
            ground=drawn["ground"][i], atmosphere=drawn["atmosphere"][i],
            footprint_m=float(rng.uniform(*FOOTPRINT[kind])), base_m=float(rng.uniform(*BASE[kind])),
            view_azimuth_deg=float(rng.uniform(0.0, 360.0)), view_pitch_deg=float(pitch),
            sun_jitter_deg=float(rng.uniform(-20.0, 20.0)), shape_seed=int(rng.integers(0, 2**31 - 1)),
        ))
    return plans


def direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector at ``azimuth_deg`` (0: towards -z, 90: towards +x) and ``elevation_deg`` above the horizon."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az)])


def rotation_towards(axis) -> np.ndarray:
    """A rotation (columns x, y, z) whose +z axis points along ``axis``."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _occupied_points(shape: CloudShape, level: float = 0.05) -> np.ndarray:
    """World positions [m] of the corners of every voxel whose density exceeds ``level``."""
    voxel = shape.voxel_size
    cells = np.argwhere(shape.density > level).astype(np.float64)
    corners = np.array(list(np.ndindex(2, 2, 2)), dtype=np.float64)
    lo, hi = cells.min(axis=0), cells.max(axis=0) + 1.0
    box = lo + corners * (hi - lo)  # the occupied cells' bounding box, then its hull's sample: the cells themselves
    points = np.concatenate([box, cells + 0.5])
    return shape.lower + points * voxel


def place_camera(plan: MemberPlan, shape: CloudShape) -> tuple[np.ndarray, np.ndarray]:
    """(position [m], forward unit vector): at the blob's centre for ``inside``, else looking at the centre of the
    occupied voxels' box from the distance at which they fill ``FILL`` of the half-frame (no nearer than 1.1 times
    that box's half-diagonal), kept ``MIN_CAMERA_HEIGHT`` above the ground."""
    forward = direction(plan.view_azimuth_deg, plan.view_pitch_deg)
    if plan.kind == "inside":
        return shape.centre.copy(), forward
    points = _occupied_points(shape)
    box = points[:8]
    target = 0.5 * (box.min(axis=0) + box.max(axis=0))
    tan_half = 0.5 * APERTURE / FOCAL_LENGTH
    closest = 1.1 * 0.5 * float(np.linalg.norm(box.max(axis=0) - box.min(axis=0)))
    distance = closest
    for _ in range(40):
        position = target - forward * distance
        if position[1] < MIN_CAMERA_HEIGHT:  # too low: look up at the target from the lowest allowed height
            pitch = math.degrees(math.asin(min((target[1] - MIN_CAMERA_HEIGHT) / distance, 1.0)))
            forward = direction(plan.view_azimuth_deg, pitch)
            position = target - forward * distance
        local = (points - position) @ rotation_towards(-forward)
        spread = float((np.abs(local[:, :2]).max(axis=1) / -local[:, 2]).max())
        distance = max(distance * spread / (FILL * tan_half), closest)
    position = target - forward * distance
    return position, forward


def place_sun(plan: MemberPlan, forward: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit vector towards the sun, its azimuth relative to the view [deg]) for the member's lighting, moved
    sideways until it lies ``SUN_CLEARANCE`` or more from the view axis."""
    view_azimuth = math.degrees(math.atan2(forward[0], -forward[2]))
    relative = LIGHTING[plan.lighting] + plan.sun_jitter_deg
    step = 5.0 if plan.sun_jitter_deg >= 0.0 else -5.0
    for _ in range(72):
        sun = direction(view_azimuth + relative, plan.sun_elevation_deg)
        if math.degrees(math.acos(float(np.clip(sun @ forward, -1.0, 1.0)))) >= SUN_CLEARANCE:
            break
        relative += step
    return sun, (relative + 180.0) % 360.0 - 180.0


def member_shape(plan: MemberPlan, resolution: int) -> CloudShape:
    rng = np.random.default_rng(plan.shape_seed)
    return SHAPES[plan.kind](rng, plan.footprint_m, plan.base_m, resolution)


def build_member(plan: MemberPlan, resolution: int) -> tuple[dict, CloudShape, dict]:
    """The member's record (what family.json lists), its field and, for a storm, its other species' fields
    (``cloud``, ``ice`` arrays on the field's grid and the ``rain`` shaft's :class:`CloudShape`)."""
    shape = member_shape(plan, resolution)
    species = {}
    if plan.kind == "storm":
        cloud, ice, rain = storm_species(np.random.default_rng(plan.shape_seed + 1), shape, resolution)
        species = {"cloud": cloud, "ice": ice, "rain": rain}
    density = species.get("cloud", shape.density)
    column, axis = peak_column(density, shape.voxel_size)
    scale = float(np.float32(plan.optical_depth_target / column))  # stored as a USD float
    position, forward = place_camera(plan, shape)
    sun, sun_azimuth = place_sun(plan, forward)
    max_density = float(density.max())
    record = {
        "name": plan.name, "stage": f"{plan.name}.usda", "field": f"{plan.name}.npy", **asdict(plan),
        "g": HG_G if plan.phase == "hg" else None,
        "extinction_scale": scale, "max_density": max_density, "chord_m": column / max_density,
        "chord_axis": "xyz"[axis], "optical_depth": scale * column,
        "sun_direction": sun.tolist(), "sun_azimuth_deg": sun_azimuth,
        "camera_position": position.tolist(), "camera_forward": forward.tolist(),
        "grid_shape": list(shape.density.shape), "voxel_m": shape.voxel_size.tolist(),
        "lower_m": shape.lower.tolist(), "upper_m": shape.upper.tolist(),
    }
    if species:
        ice_column, _ = peak_column(species["ice"], shape.voxel_size)
        rain = species["rain"]
        rain_column, _ = peak_column(rain.density, rain.voxel_size)
        record.update(
            ice_field=f"{plan.name}_ice.npy", rain_field=f"{plan.name}_rain.npy",
            ice_extinction_scale=float(np.float32(ICE_OPTICAL_DEPTH * plan.optical_depth_target / ice_column)),
            rain_extinction_scale=float(np.float32(RAIN_OPTICAL_DEPTH / rain_column)),
            rain_grid_shape=list(rain.density.shape), rain_lower_m=rain.lower.tolist(),
            rain_upper_m=rain.upper.tolist())
    return record, shape, species


def make_family(out: str | Path, *, seed: int = 2026, count: int = 24, resolution: int = 48,
                profile: str = "thin", log=None) -> Path:
    """Write ``count`` members of ``profile`` (:data:`PROFILES`; a ``.usda`` stage and its ``.npy`` fields each)
    and ``family.json`` into ``out``; returns the path of family.json."""
    if not 8 <= resolution <= 64:
        raise ValueError(f"grid resolution must lie in 8..64 voxels, got {resolution}")
    if profile not in PROFILES:
        raise ValueError(f"unknown family profile {profile!r}; known: {', '.join(PROFILES)}")
    chosen = PROFILES[profile]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for plan in plan_members(seed, count, chosen):
        record, shape, species = build_member(plan, resolution)
        np.save(out / record["field"], species.get("cloud", shape.density))
        if species:
            np.save(out / record["ice_field"], species["ice"])
            np.save(out / record["rain_field"], species["rain"].density)
        write_member_stage(out / record["stage"], record, shape, seed=seed, image_size=chosen.image_size)
        records.append(record)
        if log is not None:
            log(f"{record['stage']:<24} {record['half']:<4} tau {record['optical_depth']:8.3g}  "
                f"{record['phase']:<9} albedo {record['albedo']:g}  sun {record['sun_elevation_deg']:5.1f} deg "
                f"{record['lighting']:<5} ground {int(record['ground'])} atmosphere {int(record['atmosphere'])}")
    blob = {"generator": "evaluation/scripts/make_validation_family.py", "version": FAMILY_VERSION, "seed": seed,
            "count": count, "resolution": resolution, "image_size": chosen.image_size, "members": records}
    if profile != "thin":  # the thin family's file stays as it was before profiles existed
        blob["profile"] = profile
    path = out / "family.json"
    path.write_text(json.dumps(blob, indent=1) + "\n")
    return path


def _set_transform(prim, rotation: np.ndarray, translation) -> None:
    from pxr import Gf, UsdGeom

    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = translation
    UsdGeom.Xformable(prim).AddTransformOp().Set(Gf.Matrix4d(matrix.T.tolist()))  # USD: row vectors


def _attribute(prim, name: str, type_name: str, value) -> None:
    from pxr import Sdf

    prim.CreateAttribute(name, getattr(Sdf.ValueTypeNames, type_name)).Set(value)


def _field(stage, volume, species: str, file: str, scale: float) -> None:
    """``volume``'s ``field:SPECIES`` on the ``.npy`` ``file`` with its extinction scale."""
    from pxr import Sdf, UsdVol

    asset = UsdVol.OpenVDBAsset.Define(stage, volume.GetPath().AppendChild(species))
    asset.CreateFilePathAttr(Sdf.AssetPath(f"./{file}"))
    _attribute(asset.GetPrim(), "warpsky:extinctionScale", "Float", scale)
    volume.CreateFieldRelationship(species, asset.GetPath())


def write_member_stage(path: Path, record: dict, shape: CloudShape, *, seed: int,
                       image_size: int = IMAGE_SIZE) -> Path:
    """One member as a Y-up, metre stage: camera, sun, the Volume on its ``.npy`` field (a storm's with its ice
    beside, and its rain shaft's Volume), optional ground and atmosphere, and render settings of ``image_size``
    square."""
    from pxr import Gf, Usd, UsdGeom, UsdLux, UsdRender, UsdVol

    stage = Usd.Stage.CreateInMemory()
    layer = stage.GetRootLayer()
    layer.documentation = (
        f"warpsky validation family (seed {seed}) member {record['name']}, {record['half']} half: {record['kind']}, "
        f"peak optical depth {record['optical_depth']:.4g}, {record['phase']} phase, albedo {record['albedo']:g}, "
        f"sun {record['sun_elevation_deg']:.1f} deg {record['lighting']}-lit. Written by "
        "evaluation/scripts/make_validation_family.py.")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.CreateFocalLengthAttr(FOCAL_LENGTH)
    camera.CreateHorizontalApertureAttr(APERTURE)
    camera.CreateVerticalApertureAttr(APERTURE)
    camera.CreateClippingRangeAttr(Gf.Vec2f(1.0, 200000.0))
    _set_transform(camera.GetPrim(), rotation_towards(-np.array(record["camera_forward"])),
                   record["camera_position"])
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun.CreateAngleAttr(0.53)
    _set_transform(sun.GetPrim(), rotation_towards(record["sun_direction"]), (0.0, 0.0, 0.0))
    volume = UsdVol.Volume.Define(stage, "/World/Cloud")
    volume.CreateExtentAttr([Gf.Vec3f(*shape.lower.tolist()), Gf.Vec3f(*shape.upper.tolist())])
    field_name = "cloud" if record["phase"] == "cloud" else "density"
    _field(stage, volume, field_name, record["field"], record["extinction_scale"])
    _attribute(volume.GetPrim(), "warpsky:albedo", "Float", record["albedo"])
    if "ice_field" in record:
        _field(stage, volume, "ice", record["ice_field"], record["ice_extinction_scale"])
        rain = UsdVol.Volume.Define(stage, "/World/Rain")
        rain.CreateExtentAttr([Gf.Vec3f(*record["rain_lower_m"]), Gf.Vec3f(*record["rain_upper_m"])])
        _field(stage, rain, "rain", record["rain_field"], record["rain_extinction_scale"])
    if field_name == "density":
        _attribute(volume.GetPrim(), "warpsky:phase", "Token", record["phase"])
        if record["phase"] == "hg":
            _attribute(volume.GetPrim(), "warpsky:phase:g", "Float", HG_G)
    if record["ground"]:
        plane = UsdGeom.Plane.Define(stage, "/World/Ground")
        plane.CreateAxisAttr(UsdGeom.Tokens.y)
        plane.CreateWidthAttr(200000.0)
        plane.CreateLengthAttr(200000.0)
        _attribute(plane.GetPrim(), "warpsky:albedo", "Color3f", Gf.Vec3f(GROUND_ALBEDO))
    if record["atmosphere"]:
        atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
        _attribute(atmosphere, "warpsky:atmosphere:altitude", "Float", 0.0)
        _attribute(atmosphere, "warpsky:atmosphere:scaleHeight", "Float", SCALE_HEIGHT)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateCameraRel().SetTargets([camera.GetPath()])
    settings.CreateResolutionAttr(Gf.Vec2i(image_size, image_size))
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    layer.Export(str(path))
    return path


def load_family(family_dir: str | Path) -> dict:
    """family.json of ``family_dir`` (what :func:`make_family` wrote)."""
    from warpsky.core.errors import UsageError

    path = Path(family_dir) / "family.json"
    if not path.is_file():
        raise UsageError(f"{family_dir} holds no family.json: generate the family with "
                         f"evaluation/scripts/make_validation_family.py --out {family_dir}")
    return json.loads(path.read_text())
