"""Shared fixtures and helpers: the devices present, a builder that writes real USD stages in any up axis and unit,
fields and atmosphere prims added to such stages, and one-call renders."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from evaluation.family_stages import rotation_towards
from warpsky.core.device import init_warp

init_warp()


def _devices() -> list[str]:
    import warp as wp

    return ["cpu"] + [f"cuda:{i}" for i in range(wp.get_cuda_device_count())]


@pytest.fixture(params=_devices())
def device(request) -> str:
    """Every test taking ``device`` runs on the CPU and on each CUDA device present."""
    return request.param


def look_rotation(forward) -> np.ndarray:
    """Camera rotation (columns right, up, back) that looks along ``forward`` with +Y up."""
    return rotation_towards(-np.asarray(forward, dtype=np.float64))


@dataclass
class StageSpec:
    """A test scene in warpsky's own frame (Y up, metres); :func:`write_stage` converts it to any stage units."""

    camera_position: tuple = (0.0, 0.0, 100.0)
    camera_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    focal_length: float = 50.0  # tenths of a scene unit, as USD stores it
    aperture: tuple = (36.0, 36.0)
    clipping: tuple = (0.1, 1.0e5)  # [m]
    sun_direction: tuple | None = (0.3, 1.0, 0.2)
    sun_intensity: float = 1.0
    volume_file: Path | None = None
    volume_extent: tuple = ((-10.0, -10.0, -10.0), (10.0, 10.0, 10.0))  # [m], for .npy grids
    volume_translate: tuple = (0.0, 0.0, 0.0)  # [m]
    extinction_scale: float = 0.05
    albedo: float = 1.0
    phase: str = "isotropic"
    g: float | None = None
    field_name: str | None = None
    ground: tuple | None = None  # (height [m], albedo)


def _stage_rotation(up: str) -> np.ndarray:
    """Stage-from-warpsky rotation: inverse of the reader's Z-up -> Y-up map."""
    to_world = np.eye(3) if up == "Y" else np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    return to_world.T


def _xform(prim, rotation, translation, up: str, mpu: float) -> None:
    from pxr import Gf, UsdGeom

    rot = _stage_rotation(up)
    m = np.eye(4)
    m[:3, :3] = rot @ np.asarray(rotation, dtype=np.float64)
    m[:3, 3] = rot @ np.asarray(translation, dtype=np.float64) / mpu
    UsdGeom.Xformable(prim).AddTransformOp().Set(Gf.Matrix4d(m.T.tolist()))


def write_stage(path: Path, spec: StageSpec, *, up: str = "Y", mpu: float = 1.0) -> Path:
    """Write ``spec`` as a real USD stage with the given upAxis and metersPerUnit."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdVol

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    UsdGeom.Xform.Define(stage, "/World")
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    scale = 1.0 / mpu  # keep the film back the same physical size whatever the unit
    cam.CreateFocalLengthAttr(spec.focal_length * scale)
    cam.CreateHorizontalApertureAttr(spec.aperture[0] * scale)
    cam.CreateVerticalApertureAttr(spec.aperture[1] * scale)
    cam.CreateClippingRangeAttr(Gf.Vec2f(spec.clipping[0] / mpu, spec.clipping[1] / mpu))
    _xform(cam.GetPrim(), spec.camera_rotation, spec.camera_position, up, mpu)
    if spec.sun_direction is not None:
        sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
        sun.CreateIntensityAttr(spec.sun_intensity)
        _xform(sun.GetPrim(), rotation_towards(spec.sun_direction), (0, 0, 0), up, mpu)
    if spec.volume_file is not None:
        vol = UsdVol.Volume.Define(stage, "/World/Cloud")
        lo, hi = (np.asarray(v, dtype=np.float64) / mpu for v in spec.volume_extent)
        vol.CreateExtentAttr([Gf.Vec3f(*lo.tolist()), Gf.Vec3f(*hi.tolist())])
        _xform(vol.GetPrim(), np.eye(3), spec.volume_translate, up, mpu)
        asset = UsdVol.OpenVDBAsset.Define(stage, "/World/Cloud/density")
        asset.CreateFilePathAttr(Sdf.AssetPath(str(spec.volume_file)))
        if spec.field_name is not None:
            asset.CreateFieldNameAttr(spec.field_name)
        asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(spec.extinction_scale)
        vol.CreateFieldRelationship("density", asset.GetPath())
        prim = vol.GetPrim()
        prim.CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Float).Set(spec.albedo)
        prim.CreateAttribute("warpsky:phase", Sdf.ValueTypeNames.Token).Set(spec.phase)
        if spec.g is not None:
            prim.CreateAttribute("warpsky:phase:g", Sdf.ValueTypeNames.Float).Set(spec.g)
    if spec.ground is not None:
        plane = UsdGeom.Plane.Define(stage, "/World/Ground")
        plane.CreateAxisAttr(UsdGeom.Tokens.y)  # local frames are pre-rotated to warpsky's axes by _xform
        _xform(plane.GetPrim(), np.eye(3), (0.0, spec.ground[0], 0.0), up, mpu)
        plane.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(spec.ground[1]))
    stage.GetRootLayer().Save()
    return path


def add_field(stage_path, name, npy, *, quantity=None, scale=None):
    """Add a field ``name`` (an OpenVDBAsset on ``npy``) to the stage's /World/Cloud Volume."""
    from pxr import Sdf, Usd, UsdVol

    stage = Usd.Stage.Open(str(stage_path))
    vol = UsdVol.Volume(stage.GetPrimAtPath("/World/Cloud"))
    asset = UsdVol.OpenVDBAsset.Define(stage, f"/World/Cloud/{name}")
    asset.CreateFilePathAttr(Sdf.AssetPath(str(npy)))
    if quantity is not None:
        asset.GetPrim().CreateAttribute("warpsky:quantity", Sdf.ValueTypeNames.Token).Set(quantity)
    if scale is not None:
        asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(scale)
    vol.CreateFieldRelationship(name, asset.GetPath())
    stage.Save()


def add_atmosphere(stage_path, **attributes):
    """Add a /World/Atmosphere prim with ``warpsky:atmosphere:<name>`` attributes (default: a scale height)."""
    from pxr import Sdf, Usd

    stage = Usd.Stage.Open(str(stage_path))
    prim = stage.DefinePrim("/World/Atmosphere", "Scope")
    types = {"scaleHeight": Sdf.ValueTypeNames.Float, "altitude": Sdf.ValueTypeNames.Float,
             "betaSeaLevel": Sdf.ValueTypeNames.Color3f, "enabled": Sdf.ValueTypeNames.Bool,
             "scaleHight": Sdf.ValueTypeNames.Float, "multipleScattering": Sdf.ValueTypeNames.Bool,
             "mieScattering": Sdf.ValueTypeNames.Color3f, "mieAbsorption": Sdf.ValueTypeNames.Color3f,
             "mieScaleHeight": Sdf.ValueTypeNames.Float, "mieAnisotropy": Sdf.ValueTypeNames.Float,
             "ozoneAbsorption": Sdf.ValueTypeNames.Color3f, "ozoneAltitude": Sdf.ValueTypeNames.Float,
             "ozoneWidth": Sdf.ValueTypeNames.Float, "planetRadius": Sdf.ValueTypeNames.Float}
    for name, value in attributes.items():
        prim.CreateAttribute(f"warpsky:atmosphere:{name}", types[name]).Set(value)
    if not attributes:
        prim.CreateAttribute("warpsky:atmosphere:scaleHeight", Sdf.ValueTypeNames.Float).Set(8000.0)
    stage.Save()
    return stage_path


@pytest.fixture
def homogeneous_npy(tmp_path) -> Path:
    """A constant 4^3 grid of ones."""
    path = tmp_path / "box.npy"
    np.save(path, np.ones((4, 4, 4), dtype=np.float32))
    return path


def image_sum_sigma(variance: np.ndarray) -> float:
    """Standard deviation of an RGB image's sum from its per-pixel, per-channel variances: pixels are independent,
    but a path carries all three channels, so they are taken as fully correlated (exact for a grey medium, whose
    channels are equal, and an upper bound otherwise). Summing the variances instead understates it by up to
    sqrt(3): over 40 seeds the image sum's spread was 1.7x what the plain sum of variances claimed."""
    sigma = np.sqrt(np.maximum(np.asarray(variance, dtype=np.float64), 0.0))
    return float(np.sqrt((sigma.sum(axis=-1) ** 2).sum()))


def render_layer(stage_path: Path, device: str, width: int, height: int, *, time=None, **settings):
    """Render a stage with the single-scattering technique; returns (scene, layer)."""
    from warpsky.render.plan import make_plan
    from warpsky.techniques.single_scatter.single_scatter import SingleScatter
    from warpsky.usd.stage import StageReader

    scene = StageReader(stage_path).scene_at(time)
    plan = make_plan(scene, technique="single_scatter", settings={k: str(v) for k, v in settings.items()},
                     resolution=(width, height), device=device)
    return scene, SingleScatter(plan.settings, device=device).render(scene, width, height)


def path_traced(stage, device, size, **settings):
    """Render a stage with the path tracer at ``size`` x ``size``; returns the layer."""
    from warpsky.render.plan import make_plan
    from warpsky.techniques.path_tracer.path_tracer import PathTracer
    from warpsky.usd.stage import StageReader

    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique="path_tracer", settings={k: str(v) for k, v in settings.items()},
                     resolution=(size, size), device=device)
    return PathTracer(plan.settings, device=device).render(scene, size, size)


@pytest.fixture(scope="session")
def optics_cache(tmp_path_factory):
    """One optics cache for the whole session, so slow Mie/ice tables are built once (and first-built here)."""
    import os

    path = tmp_path_factory.mktemp("optics-cache")
    previous = os.environ.get("WARPSKY_CACHE")
    os.environ["WARPSKY_CACHE"] = str(path)
    yield path
    if previous is None:
        os.environ.pop("WARPSKY_CACHE", None)
    else:
        os.environ["WARPSKY_CACHE"] = previous


@pytest.fixture(scope="session")
def species_phase(optics_cache):
    """Phase table (3, M) of a species, built once per session in the session cache."""
    import os

    from warpsky.optics.tables import phase_table

    memo = {}

    def get(name: str) -> np.ndarray:
        if name not in memo:
            previous = os.environ.get("WARPSKY_CACHE")
            os.environ["WARPSKY_CACHE"] = str(optics_cache)  # even inside a test that monkeypatched it
            try:
                memo[name] = phase_table(name)
            finally:
                os.environ["WARPSKY_CACHE"] = previous if previous is not None else str(optics_cache)
        return memo[name]

    return get


def run_cli(args, capsys):
    """Run the ``warpsky`` command in this process: (exit code, stdout, stderr)."""
    from warpsky.cli.main import main

    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err
