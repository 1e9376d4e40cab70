"""Write an animated stratocumulus thickness-map sequence made with advected textures (Neyret 2003).

Each frame is the 512² base texture advected by wind plus curl noise (3 layers, period 5 min: about two strain
times of the flow), computed on its own (random access): frames can be written in any order or split across
machines and still agree bit for bit with a sequential run on the same device. Writes ``thickness.####.npy``
(float32 [m], rows = layer y) and, with ``--png``, grey previews. Run:

    python tools/make_advected_layer.py [--out out/advected_layer] [--frames 48] [--fps 24] [--png] [--device cpu]
    python tools/make_advected_layer.py --test        # 8 small frames, checks statistics and NaNs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "advected_layer")
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--first", type=int, default=1, help="first frame number (time = frame / fps)")
    parser.add_argument("--fps", type=float, default=24.0, help="frames per second of animation time")
    parser.add_argument("--speedup", type=float, default=60.0, help="simulated seconds per animation second")
    parser.add_argument("--size", type=int, default=512, help="texture side [texels]")
    parser.add_argument("--png", action="store_true", help="also write 8-bit grey previews")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--test", action="store_true", help="8 frames at 128², check statistics, write nothing")
    args = parser.parse_args(argv)

    import numpy as np

    from warpsky.core.device import init_warp, resolve_device
    from warpsky.media.advection.advection import AdvectedTexture, Flow2D, periodic_noise

    init_warp()
    size = 128 if args.test else args.size
    extent = (20000.0, 20000.0)  # [m]
    mean_thickness, thickness_std = 250.0, 80.0  # [m], Bouthors' layers span 0-500 m
    base = periodic_noise((size, size), smoothing_texels=size / 96.0, seed=11)
    texture = (mean_thickness + thickness_std * base).astype(np.float32)
    flow = Flow2D.procedural(extent, wind_m_s=(12.0, 4.0), speed_m_s=6.0, scale_m=10000.0, octaves=3,
                             resolution=(64, 64), seed=12)
    layer = AdvectedTexture(texture, extent, flow, layers=3, period_s=300.0, step_s=5.0,
                            device=resolve_device(args.device))
    frame_count = 8 if args.test else args.frames
    if not args.test:
        args.out.mkdir(parents=True, exist_ok=True)
    for frame in range(args.first, args.first + frame_count):
        time_s = frame / args.fps * args.speedup
        thickness = np.maximum(layer.at(time_s).numpy(), 0.0)  # a layer has no negative thickness
        if args.test:
            ok = np.all(np.isfinite(thickness)) and abs(thickness.mean() / mean_thickness - 1.0) < 0.05
            print(f"frame {frame}: t={time_s:g} s mean {thickness.mean():.1f} m std {thickness.std():.1f} m "
                  f"{'ok' if ok else 'FAILED'}")
            if not ok:
                return 1
            continue
        np.save(args.out / f"thickness.{frame:04d}.npy", thickness.astype(np.float32))
        if args.png:
            from PIL import Image

            grey = np.clip(thickness / (2.0 * mean_thickness) * 255.0, 0.0, 255.0).astype(np.uint8)
            Image.fromarray(grey[::-1]).save(args.out / f"thickness.{frame:04d}.png")
    if not args.test:
        print(f"wrote {frame_count} frames to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
