"""Stratocumulus over a landscape of water, sand and snow (Bouthors 2006 Fig. 11.E: water sky and ice blink), still
and animated by advected textures (Neyret 2003).

Writes data/stratocumulus/{thickness.npy, ground_albedo.npy}, usd_scenes/stratocumulus.usda (one frame) and
usd_scenes/stratocumulus_anim.usda (48 frames: the same layer with ``warpsky:advection:*`` wind and curl noise; a
time-lapse at timeCodesPerSecond = 0.1, one frame per 10 s of cloud time, played at 24 fps). With ``--render DIR``
also renders the still stage through ``warpsky render`` with radiosity on and off (two EXRs + PNG previews); the
Makefile targets do the same from the shell:

    make stratocumulus          # = python tools/make_stratocumulus.py --out data --render out
    make stratocumulus-anim     # warpsky render usd_scenes/stratocumulus_anim.usda out/stratocumulus_anim/sc.####.exr
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZE = 24000.0  # [m] of cloud layer and ground texture
FRAMES = 48
#: Animated stage: time codes per second of cloud time (0.1: one frame every 10 s) and the advection it gets.
ANIM_TIME_CODES_PER_SECOND = 0.1
ANIM_ADVECTION = """        custom float2 warpsky:advection:wind = (14, 5)
        custom float warpsky:advection:curlSpeed = 2
        custom float warpsky:advection:curlScale = 8000
        custom float warpsky:advection:period = 400
        custom int warpsky:advection:seed = 3
"""
ANIM_HEADER = f"""    startTimeCode = 1
    endTimeCode = {FRAMES}
    timeCodesPerSecond = {ANIM_TIME_CODES_PER_SECOND}
    framesPerSecond = 24
"""


def ground_albedo(resolution: int = 256) -> np.ndarray:
    """(nx, nz, 3): a sea in the west (x < 0), a sand beach, and a snowfield in the east."""
    x = (np.arange(resolution) + 0.5) / resolution * SIZE - SIZE / 2
    wobble = 900.0 * np.sin(np.linspace(0, 5 * np.pi, resolution))[None, :]
    xx = x[:, None] + wobble
    albedo = np.empty((resolution, resolution, 3), np.float32)
    albedo[:] = (0.92, 0.93, 0.96)  # snow
    albedo[xx < 1500.0] = (0.55, 0.45, 0.30)  # sand
    albedo[xx < -500.0] = (0.03, 0.06, 0.09)  # water
    return albedo


STAGE = """#usda 1.0
(
    defaultPrim = "World"
    doc = "warpsky stratocumulus over water, sand and snow (Bouthors 2006){doc}; written by tools/make_stratocumulus.py"
    metersPerUnit = 1
    upAxis = "Y"
{header})

def Xform "World"
{{
    def Camera "Camera"
    {{
        float2 clippingRange = (1, 200000)
        float focalLength = 14
        float horizontalAperture = 36
        float verticalAperture = 24
        float3 xformOp:rotateXYZ = (38, 0, 0)
        double3 xformOp:translate = (0, 2, 1500)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }}

    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = (-50, 30, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }}

    def Scope "Atmosphere"
    {{
        custom float warpsky:atmosphere:altitude = 0
{earth}
    }}

    def Plane "Ground"
    {{
        uniform token axis = "Y"
        custom color3f warpsky:albedo = (0.3, 0.3, 0.3)
        custom asset warpsky:albedoMap = @../data/stratocumulus/ground_albedo.npy@
        custom float2 warpsky:albedoMapSize = ({size}, {size})
    }}

    def Xform "Stratocumulus"
    {{
        uniform token warpsky:kind = "stratiformLayer"
        custom asset warpsky:stratiform:thicknessMap = @../data/stratocumulus/thickness.npy@
        custom float warpsky:stratiform:thicknessScale = 1
        custom float2 warpsky:stratiform:size = ({size}, {size})
        custom float warpsky:stratiform:numberDensity = 3e8
        custom float warpsky:stratiform:effectiveRadius = 7e-6
{advection}        double3 xformOp:translate = (0, 1200, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
"""


def render(stage: Path, out: Path, *, width: int, device: str) -> int:
    """``warpsky render`` the still stage with radiosity on and off (EXR + PNG each); returns the exit code."""
    from warpsky.cli.main import main as warpsky

    for radiosity in ("on", "off"):
        args = ["render", str(stage), str(out / f"stratocumulus-radiosity-{radiosity}.exr"), "--res", str(width),
                "--device", device, "--png", "--exposure", "1"]
        code = warpsky(args + (["--set", "stratiform.radiosity=0"] if radiosity == "off" else []))
        if code != 0:
            return code
    return 0


def write_radiosity_light(folder: Path) -> Path:
    """``folder/stratocumulus-radiosity-light.png``: what radiosity adds (on minus off), each channel scaled by one
    common factor so the ground's colour reflected onto the cloud base shows as hue (sand warm, water dark)."""
    from PIL import Image

    from warpsky.output.exr import read_exr

    on, off = (read_exr(folder / f"stratocumulus-radiosity-{state}.exr").rgba()[..., :3].astype(np.float64)
               for state in ("on", "off"))
    added = np.clip(on - off, 0.0, None)
    scale = max(float(np.percentile(added, 99.5)), 1e-12)
    encoded = np.clip(added / scale, 0.0, 1.0) ** (1.0 / 2.2)
    path = folder / "stratocumulus-radiosity-light.png"
    Image.fromarray(np.round(encoded * 255).astype(np.uint8)).save(path)
    mean = added.reshape(-1, 3).mean(axis=0)
    print(f"{path}: radiosity adds mean RGB {np.round(mean, 4).tolist()} (R:G:B = "
          f"{', '.join(f'{v / mean.sum():.3f}' for v in mean)})")
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--radiosity-light", type=Path, default=None, metavar="DIR",
                        help="only write DIR/stratocumulus-radiosity-light.png from the on/off renders in DIR")
    parser.add_argument("--out", type=Path, default=ROOT / "data", help="data directory")
    parser.add_argument("--render", type=Path, default=None, help="also render to this directory")
    parser.add_argument("--width", type=int, default=384)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    if args.radiosity_light is not None:
        write_radiosity_light(args.radiosity_light)
        return 0
    from warpsky.media.stratiform.thickness import procedural_thickness
    from warpsky.usd.authoring import earth_air_lines

    data = args.out / "stratocumulus"
    data.mkdir(parents=True, exist_ok=True)
    np.save(data / "thickness.npy", procedural_thickness(256, cover=0.75, max_thickness=450.0, seed=8))
    np.save(data / "ground_albedo.npy", ground_albedo())
    stage = ROOT / "usd_scenes" / "stratocumulus.usda"
    stage.write_text(STAGE.format(size=SIZE, doc="", header="", advection="", earth=earth_air_lines()))
    anim = ROOT / "usd_scenes" / "stratocumulus_anim.usda"
    anim.write_text(STAGE.format(size=SIZE, doc=f", {FRAMES} frames advected by wind and curl noise",
                                 header=ANIM_HEADER, advection=ANIM_ADVECTION, earth=earth_air_lines()))
    print(f"wrote {data}/thickness.npy, {data}/ground_albedo.npy, {stage}, {anim}")
    if args.render is not None:
        return render(stage, args.render, width=args.width, device=args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
