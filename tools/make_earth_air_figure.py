"""The README's picture of the Earth's air: the demo cumulus and the first sunrise frame under Riley's flat earth of
pure Rayleigh air (before) and under the Earth's round air with aerosols and ozone (after, what the stages author),
and the cumulus at twilight, the sun 1 deg below the horizon (its top still lit, the sky glowing), which a flat
earth leaves black. Each frame is a ``warpsky render`` of the stage (or a copy with its atmosphere or sun changed);
a pair shares one exposure. Run:

    python tools/make_earth_air_figure.py [--res 384] [--out docs/earth_air.png]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def flat_rayleigh(text: str) -> str:
    """The stage text without the Earth's attributes: Riley's flat earth of pure Rayleigh air."""
    from warpsky.model.scene import EARTH_AIR_ATTRIBUTES

    for name in EARTH_AIR_ATTRIBUTES:
        text = re.sub(rf"\n\s*custom \w+ warpsky:atmosphere:{name} = [^\n]*", "", text)
    return text


def sun_at(text: str, elevation_deg: float) -> str:
    """The stage text with its DistantLight's elevation set to ``elevation_deg`` (its rotateXYZ's first angle; the
    light's +z, towards the sun, rises by -x), the azimuth kept."""
    return re.sub(r'(def DistantLight "Sun"\s*\{[^}]*?float3 xformOp:rotateXYZ = \()[^,]*,',
                  lambda m: f"{m.group(1)}{-elevation_deg:g},", text, count=1)


def render(stage: Path, out: Path, res: int, frame: int) -> np.ndarray:
    from warpsky.output.exr import read_exr

    subprocess.run([sys.executable, "-m", "warpsky", "render", str(stage), str(out.with_suffix("")) + ".####.exr",
                    "--frames", str(frame), "--res", str(res)], check=True, cwd=ROOT)
    return read_exr(f"{out.with_suffix('')}.{frame:04d}.exr").rgba()[..., :3]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--res", type=int, default=384)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "earth_air.png")
    args = parser.parse_args(argv)

    from PIL import Image, ImageDraw

    from warpsky.output.png import auto_exposure, encode

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        stages = {}
        for name in ("cumulus", "sunrise"):
            text = (ROOT / "usd_scenes" / f"{name}.usda").read_text()
            for kind, body in (("before", flat_rayleigh(text)), ("after", text)):
                path = ROOT / "usd_scenes" / f".{name}_{kind}.usda"  # beside the stage: its data paths hold
                path.write_text(body)
                stages[f"{name}_{kind}"] = path
        twilight = ROOT / "usd_scenes" / ".cumulus_twilight.usda"
        twilight.write_text(sun_at((ROOT / "usd_scenes" / "cumulus.usda").read_text(), -1.0))
        stages["cumulus_twilight"] = twilight
        try:
            frames = {key: render(path, folder / key, args.res, 1) for key, path in stages.items()}
        finally:
            for path in stages.values():
                path.unlink()
    rows = [("demo cumulus", "cumulus"), ("sunrise, frame 1 (sun 0.5 deg)", "sunrise")]
    tiles = []
    for label, key in rows:
        exposure = auto_exposure(frames[f"{key}_after"])
        tiles.append([(f"{label}: flat earth, Rayleigh air", encode(frames[f"{key}_before"], exposure=exposure)),
                      (f"{label}: round earth, aerosols, ozone", encode(frames[f"{key}_after"], exposure=exposure))])
    dusk = frames["cumulus_twilight"]
    tiles.append([("twilight, sun 1 deg below the horizon: flat earth", np.zeros_like(encode(dusk))),
                  ("twilight: round earth (the cloud's top still lit)", encode(dusk, exposure=auto_exposure(dusk)))])
    h, w = tiles[0][0][1].shape[:2]
    pad, text_h = 6, 16
    sheet = Image.new("RGB", (2 * w + 3 * pad, len(tiles) * (h + text_h + pad) + pad), "white")
    draw = ImageDraw.Draw(sheet)
    for r, row in enumerate(tiles):
        for c, (label, image) in enumerate(row):
            x, y = pad + c * (w + pad), pad + r * (h + text_h + pad)
            draw.text((x, y), label, fill="black")
            sheet.paste(Image.fromarray(image), (x, y + text_h))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
