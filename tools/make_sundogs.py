"""Write the sundog stage's cirrostratus: two thin ice sheets as dense .npy fields (procedural and seeded).

``usd_scenes/sundogs.usda`` references ``data/sundogs/plates.npy`` (horizontally oriented plates mixed with
random columns: parhelia, the circumzenithal arc and the 22° halo) and ``data/sundogs/columns.npy`` (horizontal
columns: the upper tangent arc). Each field is a sheet 4 voxels thick whose density is a smooth seeded random
texture in [0.5, 1] across the sheet, so the halos show through streaks of thicker and thinner cirrostratus.

Run:  python tools/make_sundogs.py [--out data/sundogs] [--resolution 96] [--seed 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def sheet_density(resolution: int, seed: int) -> np.ndarray:
    """(resolution, 4, resolution) float32 in [0.5, 1]: a sum of random long-crested waves across the sheet
    (streaks), constant through its thickness."""
    rng = np.random.default_rng(seed)
    x = (np.arange(resolution) + 0.5) / resolution
    gx, gz = np.meshgrid(x, x, indexing="ij")
    field = np.zeros_like(gx)
    for octave in range(5):
        frequency = 2.0 ** octave * 1.5
        angle = rng.uniform(0.0, np.pi)
        phase = rng.uniform(0.0, 2.0 * np.pi)
        # streaks run mostly along one direction, as cirrostratus fibres do
        k = frequency * np.array([np.cos(angle), 0.3 * np.sin(angle)])
        field += np.sin(2.0 * np.pi * (k[0] * gx + k[1] * gz) + phase) / (1.0 + octave)
    field = (field - field.min()) / max(float(np.ptp(field)), 1e-12)
    density = 0.5 + 0.5 * field
    return np.repeat(density[:, None, :], 4, axis=1).astype(np.float32)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("data/sundogs"), help="output folder (default data/sundogs)")
    parser.add_argument("--resolution", type=int, default=96, help="voxels across each sheet (default 96)")
    parser.add_argument("--seed", type=int, default=3, help="random seed (default 3)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, seed in (("plates", args.seed), ("columns", args.seed + 1)):
        path = args.out / f"{name}.npy"
        np.save(path, sheet_density(args.resolution, seed))
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
