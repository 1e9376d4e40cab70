"""Write the storm: a cumulonimbus cell evolving over a time-lapse, as per-frame NanoVDB fields, and its USD stage.

Fields (values in [0, 1]; each OpenVDBAsset's ``warpsky:extinctionScale`` turns them into extinction [1/m]):

======== ========== ============================================================= ==========================
field    species    where                                                          peak extinction [1/m]
======== ========== ============================================================= ==========================
cloud    cloud      the tower: cloud base 1.8 km, top rising 8 -> 9.5 km           0.03 (τ ~ 100 across it)
rain     rain       shaft under the base, leaning downwind, growing after t = 0.15 4e-4 (τ ~ 1.5 across)
snow     snow       aloft inside the tower between 5 and 9 km                      6e-4
ice      ice        the anvil (its own Volume): 8-11 km, spreading downwind from   6e-4 (τ ~ 1.5 through it)
                    10 to 25 km east of the tower
======== ========== ============================================================= ==========================

Time t runs 0 -> 1 over the frames (a time-lapse: 48 frames stand for 24 minutes of the cell's life, so the stage's
timeCodesPerSecond is 47 / 1440 s while framesPerSecond stays 24). Both Volumes carry wind-advected detail
(``warpsky:detail:*``: 35% amplitude, 400 m features in the cell, 900 m in the anvil) on top of the frames. The
wind blows towards +x (east, towards the rising sun), carrying the detail noise and leaning the rain shaft. The cell
is one Volume (cloud, rain, snow share its grid); the anvil is a second Volume with a coarser, wider grid.

The stage ``usd_scenes/storm.usda`` (written here too, with ``--stage``) has a sunrise DistantLight in the east
(elevation 4 -> 12 deg), an atmosphere, a ground plane and two moving cameras:

- ``/World/RainbowCam`` (the default): east of the shaft with the sun at its back; the primary bow stands in the
  rain shaft under the cloud base.
- ``/World/AnvilCam``: under the anvil looking east into the low sun; the 22 deg halo arcs through the anvil ice.

Run:  python tools/make_storm.py [--out data/storm] [--frames 48] [--res 64] [--stage usd_scenes/storm.usda]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

#: The cell's grid: x, z in [-CELL_XZ, CELL_XZ], y in [0, CELL_Y] [m].
CELL_XZ = 8000.0
CELL_Y = 10400.0
#: The anvil's grid [m]: x in ANVIL_X, y in ANVIL_Y, z in [-ANVIL_Z, ANVIL_Z].
ANVIL_X = (-6000.0, 26000.0)
ANVIL_Y = (7600.0, 11600.0)
ANVIL_Z = 14000.0
CLOUD_BASE = 1800.0
WIND = 6.0  # [m/s] towards +x, for the detail noise over the time-lapse
DURATION = 24 * 60.0  # [s] of storm life the frames span
EXTINCTION = {"cloud": 0.03, "rain": 4.0e-4, "snow": 6.0e-4, "ice": 6.0e-4}


def periodic_noise(shape: tuple[int, int, int], rng: np.random.Generator, octaves: int = 4) -> np.ndarray:
    """Fractal value noise on a grid, periodic along every axis (so the wind can roll it), values in [0, 1]."""
    out = np.zeros(shape)
    total = 0.0
    for octave in range(octaves):
        cells = 4 * 2**octave
        lattice = rng.random((cells, cells, cells))
        coords = [np.arange(n) * cells / n for n in shape]
        axes = []
        for c in coords:
            i0 = np.floor(c).astype(np.int64)
            f = c - i0
            axes.append((i0 % cells, (i0 + 1) % cells, f * f * (3.0 - 2.0 * f)))
        (x0, x1, fx), (y0, y1, fy), (z0, z1, fz) = axes
        layer = np.zeros(shape)
        for xi, wx in ((x0, 1.0 - fx), (x1, fx)):
            for yi, wy in ((y0, 1.0 - fy), (y1, fy)):
                for zi, wz in ((z0, 1.0 - fz), (z1, fz)):
                    layer += (wx[:, None, None] * wy[None, :, None] * wz[None, None, :]
                              * lattice[np.ix_(xi, yi, zi)])
        out += 0.5**octave * layer
        total += 0.5**octave
    return out / total


def shifted(noise: np.ndarray, voxels: float) -> np.ndarray:
    """The periodic noise carried ``voxels`` voxels towards +x (linear between whole-voxel rolls)."""
    whole = math.floor(voxels)
    frac = voxels - whole
    a = np.roll(noise, whole, axis=0)
    return a * (1.0 - frac) + np.roll(a, 1, axis=0) * frac


def smoothstep(edge0: float, edge1: float, x):
    t = np.clip((np.asarray(x) - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def cell_fields(t: float, res: int, noise: np.ndarray) -> dict[str, np.ndarray]:
    """cloud, rain and snow of the cell at time t in [0, 1] on its grid (indexed [x, y, z])."""
    voxel = 2.0 * CELL_XZ / res
    ny = noise.shape[1]
    x = (np.arange(res) + 0.5) * voxel - CELL_XZ
    y = (np.arange(ny) + 0.5) * voxel
    X, Y, Z = np.meshgrid(x, y, x, indexing="ij")
    detail = shifted(noise, WIND * DURATION * t / voxel)
    top = 8000.0 + 1500.0 * smoothstep(0.0, 0.8, t)  # a mature cell: its anvil exists from the first frame
    # the tower: a radius that swells at mid height and narrows into the top; turrets from the noise
    h = np.clip((Y - CLOUD_BASE) / (top - CLOUD_BASE), 0.0, 1.0)
    radius = 2600.0 * (0.75 + 0.45 * np.sin(np.pi * np.clip(h, 0.0, 1.0) ** 0.8)) * np.sqrt(np.clip(1.05 - h, 0, 1))
    r = np.hypot(X, Z)
    body = (1.0 - r / np.maximum(radius, 1.0)) * 2.5 + (detail - 0.5) * 2.2
    vertical = smoothstep(CLOUD_BASE, CLOUD_BASE + 250.0, Y) * (1.0 - smoothstep(top - 600.0, top + 200.0, Y))
    cloud = np.clip(body, 0.0, 1.0) * vertical
    # rain: a shaft under the base, leaning downwind with height, strengthening after t = 0.15
    lean = X - 900.0 * (1.0 - Y / CLOUD_BASE)
    shaft = 1.0 - np.hypot(lean + 400.0, Z) / 2600.0
    below_base = 1.0 - smoothstep(CLOUD_BASE - 100, CLOUD_BASE + 400, Y)
    rain = np.clip(shaft * 3.0 + (detail - 0.5) * 1.5, 0.0, 1.0) * below_base
    rain *= smoothstep(0.15, 0.5, t) * (0.6 + 0.4 * detail)
    # rain inside the lower tower too, where it forms
    rain += 0.5 * cloud * smoothstep(CLOUD_BASE + 2500, CLOUD_BASE, Y) * smoothstep(0.15, 0.5, t)
    snow = cloud * smoothstep(4500.0, 5500.0, Y) * (1.0 - smoothstep(top - 800.0, top, Y)) * (0.5 + detail)
    return {name: _framed(np.clip(v, 0.0, 1.0)) for name, v in (("cloud", cloud), ("rain", rain), ("snow", snow))}


def anvil_field(t: float, res: int, noise: np.ndarray) -> np.ndarray:
    """Anvil ice at time t on the anvil grid: a sheet spreading downwind from the tower top."""
    nx, ny, nz = noise.shape
    vx = (ANVIL_X[1] - ANVIL_X[0]) / nx
    x = ANVIL_X[0] + (np.arange(nx) + 0.5) * vx
    y = ANVIL_Y[0] + (np.arange(ny) + 0.5) * (ANVIL_Y[1] - ANVIL_Y[0]) / ny
    z = -ANVIL_Z + (np.arange(nz) + 0.5) * 2 * ANVIL_Z / nz
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    grow = 0.3 + 0.7 * smoothstep(0.0, 1.0, t)
    reach = 2500.0 + 22000.0 * grow  # downwind edge [m]
    width = 3000.0 + 9000.0 * grow * np.clip((X + 2000.0) / (reach + 2000.0), 0.0, 1.0)
    middle = 9600.0 + 300.0 * np.clip(X / 20000.0, 0.0, 1.0)
    thick = 900.0 * (1.0 - 0.5 * np.clip(X / max(reach, 1.0), 0.0, 1.0))
    detail = shifted(noise, WIND * DURATION * t / vx)
    plan = (1.0 - np.abs(Z) / width) * (1.0 - smoothstep(reach - 3000.0, reach, X)) * smoothstep(-4000.0, -1500.0, X)
    sheet = 1.0 - np.abs(Y - middle) / thick
    ice = np.clip(sheet * 2.0, 0.0, 1.0) * np.clip(plan * 3.0, 0.0, 1.0) * (0.35 + 0.9 * detail)
    return _framed(np.clip(ice, 0.0, 1.0))


def _framed(grid: np.ndarray) -> np.ndarray:
    """Zero the outer voxels so the .nvdb's background matches the grid's edge."""
    grid = grid.astype(np.float32)
    grid[[0, -1], :, :] = 0.0
    grid[:, [0, -1], :] = 0.0
    grid[:, :, [0, -1]] = 0.0
    return grid


def grids(res: int, seed: int = 11):
    """(cell noise, anvil noise, cell voxel size, anvil voxel size): the static detail the frames roll."""
    rng = np.random.default_rng(seed)
    voxel = 2.0 * CELL_XZ / res
    cell_noise = periodic_noise((res, int(round(CELL_Y / voxel)), res), rng)
    anvil_voxel = voxel  # the same cubic voxels as the cell's, over the anvil's wider box
    anvil_shape = tuple(max(4, int(round(extent / anvil_voxel)))
                        for extent in (ANVIL_X[1] - ANVIL_X[0], ANVIL_Y[1] - ANVIL_Y[0], 2 * ANVIL_Z))
    anvil_noise = periodic_noise(anvil_shape, rng)
    return cell_noise, anvil_noise, voxel, anvil_voxel


def file_name(field: str, frame: int) -> str:
    return f"{field}.{frame:04d}.nvdb"


def write_frames(out: Path, frames: int, res: int, seed: int = 11, *, only: list[int] | None = None) -> list[Path]:
    """Write every field of every frame (1-based) as ``out/<field>.<frame>.nvdb``."""
    import warp as wp

    from warpsky.core.device import init_warp

    init_warp()
    out.mkdir(parents=True, exist_ok=True)
    cell_noise, anvil_noise, voxel, anvil_voxel = grids(res, seed)
    written = []
    for frame in only or range(1, frames + 1):
        t = (frame - 1) / max(frames - 1, 1)
        fields = cell_fields(t, res, cell_noise)
        placed = {name: (grid, (-CELL_XZ + voxel / 2, voxel / 2, -CELL_XZ + voxel / 2), voxel)
                  for name, grid in fields.items()}
        anvil = anvil_field(t, res, anvil_noise)
        placed["ice"] = (anvil, (ANVIL_X[0] + anvil_voxel / 2, ANVIL_Y[0] + anvil_voxel / 2,
                                                      -ANVIL_Z + anvil_voxel / 2), anvil_voxel)
        for name, (grid, origin, size) in placed.items():
            path = out / file_name(name, frame)
            tmp = path.with_suffix(".tmp.nvdb")
            volume = wp.Volume.load_from_numpy(grid, min_world=origin, voxel_size=size, bg_value=0.0, device="cpu")
            volume.save_to_nvdb(str(tmp), codec="zip")
            tmp.replace(path)
            written.append(path)
    return written


def sun_direction(frame: int, frames: int) -> tuple[float, float, float]:
    """Towards the sun: due east (+x), rising from 4 to 12 deg over the frames."""
    elevation = math.radians(4.0 + 8.0 * (frame - 1) / max(frames - 1, 1))
    return math.cos(elevation), math.sin(elevation), 0.0


def write_stage(path: Path, data: Path, frames: int) -> Path:
    """The storm stage: both Volumes with time-sampled filePaths, the sunrise, two moving cameras."""
    import os

    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdVol

    from warpsky.usd.authoring import author_earth_air

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = (
        "warpsky storm: a cumulonimbus cell with rain shaft, snow aloft and an ice anvil at sunrise; written by "
        "tools/make_storm.py (make storm writes the data). RainbowCam: sun behind, bow in the rain shaft; "
        "AnvilCam: into the sun under the anvil, 22 deg halo.")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(frames)
    # a time-lapse: one time code is DURATION / (frames - 1) seconds of storm life; playback stays at 24 fps
    stage.SetTimeCodesPerSecond(max(frames - 1, 1) / DURATION)
    stage.SetFramesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    rel = Path(os.path.relpath(data, path.parent)).as_posix()

    def camera(name: str, focal: float, positions, aims):
        cam = UsdGeom.Camera.Define(stage, f"/World/{name}")
        cam.CreateFocalLengthAttr(focal)
        cam.CreateHorizontalApertureAttr(36.0)
        cam.CreateVerticalApertureAttr(24.0)
        cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 300000.0))
        op = UsdGeom.Xformable(cam).AddTransformOp()
        for frame in (1, frames):
            s = (frame - 1) / max(frames - 1, 1)
            eye = Gf.Vec3d(*[a + (b - a) * s for a, b in zip(*positions, strict=True)])
            aim = Gf.Vec3d(*[a + (b - a) * s for a, b in zip(*aims, strict=True)])
            look = Gf.Matrix4d().SetLookAt(eye, aim, Gf.Vec3d(0, 1, 0)).GetInverse()
            op.Set(look, frame)

    # sun at the back: the shaft stands ~38 deg from the antisolar point, where the bow's lower arc crosses it
    camera("RainbowCam", 20.0, ((6600.0, 150.0, 5600.0), (6000.0, 150.0, 5000.0)),
           ((-400.0, 2400.0, 0.0), (-400.0, 2400.0, 0.0)))
    camera("AnvilCam", 12.0, ((4000.0, 60.0, -1500.0), (5500.0, 60.0, 1500.0)),
           ((30000.0, 14000.0, 0.0), (30000.0, 13000.0, 0.0)))

    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(1.0)
    sun.CreateAngleAttr(0.53)
    sun.CreateColorAttr(Gf.Vec3f(1.0, 0.98, 0.95))
    orient = UsdGeom.Xformable(sun).AddOrientOp()
    for frame in range(1, frames + 1):
        toward = Gf.Vec3d(*sun_direction(frame, frames))
        orient.Set(Gf.Quatf(Gf.Rotation(Gf.Vec3d(0.0, 0.0, 1.0), toward).GetQuat()), frame)

    atmosphere = stage.DefinePrim("/World/Atmosphere", "Scope")
    atmosphere.CreateAttribute("warpsky:atmosphere:altitude", Sdf.ValueTypeNames.Float).Set(0.0)
    author_earth_air(atmosphere)
    atmosphere.CreateAttribute("warpsky:atmosphere:scaleHeight", Sdf.ValueTypeNames.Float).Set(8000.0)

    for volume_name, fields in (("Cell", ("cloud", "rain", "snow")), ("Anvil", ("ice",))):
        volume = UsdVol.Volume.Define(stage, f"/World/{volume_name}")
        # wind-advected detail below the grid's resolution, moving with the storm's wind (warpsky:detail:*)
        prim = volume.GetPrim()
        for name, kind, value in (("amplitude", "Float", 0.35), ("scale", "Float", 400.0 if volume_name == "Cell"
                                                                  else 900.0),
                                  ("wind", "Float3", Gf.Vec3f(WIND, 0.0, 1.0)), ("curlSpeed", "Float", 2.5),
                                  ("period", "Float", 240.0), ("seed", "Int", 5)):
            prim.CreateAttribute(f"warpsky:detail:{name}", getattr(Sdf.ValueTypeNames, kind)).Set(value)
        for field in fields:
            asset = UsdVol.OpenVDBAsset.Define(stage, f"/World/{volume_name}/{field}")
            attr = asset.CreateFilePathAttr()
            for frame in range(1, frames + 1):
                attr.Set(Sdf.AssetPath(f"{rel}/{file_name(field, frame)}"), frame)
            asset.CreateFieldNameAttr("")
            asset.GetPrim().CreateAttribute("warpsky:extinctionScale", Sdf.ValueTypeNames.Float).Set(
                EXTINCTION[field])
            volume.CreateFieldRelationship(field, asset.GetPath())

    ground = UsdGeom.Plane.Define(stage, "/World/Ground")
    ground.CreateAxisAttr("Y")
    ground.CreateWidthAttr(400000.0)
    ground.CreateLengthAttr(400000.0)
    ground.GetPrim().CreateAttribute("warpsky:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.12, 0.14, 0.09))

    render = UsdRender.Settings.Define(stage, "/Render/Settings")
    render.CreateCameraRel().SetTargets([Sdf.Path("/World/RainbowCam")])
    render.CreateResolutionAttr(Gf.Vec2i(384, 256))
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    path.parent.mkdir(parents=True, exist_ok=True)
    stage.GetRootLayer().Export(str(path))
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "storm", help="folder for the .nvdb frames")
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--res", type=int, default=64, help="cell voxels along x and z (default 64: 250 m)")
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--stage", type=Path, default=None, help="also write the USD stage here")
    args = parser.parse_args(argv)
    if args.frames < 1 or args.res < 8:
        parser.error("--frames must be >= 1 and --res >= 8")
    started = time.perf_counter()
    written = write_frames(args.out, args.frames, args.res, args.seed)
    print(f"{len(written)} files in {args.out} ({time.perf_counter() - started:.1f} s)", file=sys.stderr)
    if args.stage:
        print(write_stage(args.stage, args.out, args.frames))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
