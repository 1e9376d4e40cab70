"""Stratocumulus over a landscape of water, sand and snow (Bouthors 2006 Fig. 11.E: water sky and ice blink).

Writes data/stratocumulus/{thickness.npy, ground_albedo.npy} and usd_scenes/stratocumulus.usda; with ``--render
DIR`` also renders the stage looking up at the cloud base with radiosity on and off (two EXRs + PNG previews).

    python tools/make_stratocumulus.py --out data --render out            # = make stratocumulus
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZE = 24000.0  # [m] of cloud layer and ground texture


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
    doc = "warpsky stratocumulus over water, sand and snow (Bouthors 2006); written by tools/make_stratocumulus.py"
    metersPerUnit = 1
    upAxis = "Y"
)

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
        double3 xformOp:translate = (0, 1200, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
"""


def render(stage: Path, out: Path, *, width: int, device: str) -> list[Path]:
    """Render with radiosity on and off; returns the written files."""
    from warpsky.composite import composite
    from warpsky.device import init_warp
    from warpsky.media.stratiform import read_stratiform
    from warpsky.output.exr import write_exr
    from warpsky.output.png import write_png
    from warpsky.render import preview_exposure
    from warpsky.scene.usd import StageReader
    from warpsky.techniques.sky.technique import SkyPass, attenuated_sun
    from warpsky.techniques.stratiform.technique import Stratiform, StratiformSettings

    init_warp()
    reader = StageReader(stage)
    scene = reader.scene_at(None)
    layers, texture = read_stratiform(reader)
    height = round(width * 2 / 3)
    written = []
    for radiosity in (1, 0):
        technique = Stratiform(StratiformSettings(radiosity=radiosity), device=device)
        layer = technique.render(attenuated_sun(scene), width, height, layer=layers[0], ground_texture=texture)
        front, back = SkyPass(device=device).render(scene, width, height, media_depth=layer.depth)
        frame = composite([front, layer, back], far=scene.camera.far)
        name = f"stratocumulus-radiosity-{'on' if radiosity else 'off'}"
        exr = write_exr(out / f"{name}.exr", frame.rgba, transmittance=frame.transmittance, depth=frame.depth,
                        metadata={"technique": "stratiform", "radiosity": str(bool(radiosity)),
                                  "stats": str({k: v for k, v in layer.stats.items()})}, half=True)
        png = write_png(out / f"{name}.png", frame.rgba[..., :3], exposure=preview_exposure(scene, 1.0))
        print(f"{exr}  {png}  {layer.stats}")
        written += [Path(exr), Path(png)]
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "data", help="data directory")
    parser.add_argument("--render", type=Path, default=None, help="also render to this directory")
    parser.add_argument("--width", type=int, default=384)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    from warpsky.media.stratiform import procedural_thickness

    data = args.out / "stratocumulus"
    data.mkdir(parents=True, exist_ok=True)
    np.save(data / "thickness.npy", procedural_thickness(256, cover=0.75, max_thickness=450.0, seed=8))
    np.save(data / "ground_albedo.npy", ground_albedo())
    stage = ROOT / "usd_scenes" / "stratocumulus.usda"
    stage.write_text(STAGE.format(size=SIZE))
    print(f"wrote {data}/thickness.npy, {data}/ground_albedo.npy, {stage}")
    if args.render is not None:
        args.render.mkdir(parents=True, exist_ok=True)
        render(stage, args.render, width=args.width, device=args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
