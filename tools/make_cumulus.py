"""Write the demo cumulus density as .npy, .nvdb and .vdb (procedural and seeded; nothing large is committed).

A cumulus congestus 2.4 km across: soft spheres (a central tower, shoulders low and wide, turrets biased upwards)
give the macro shape; cauliflower billows of inverted cellular noise, a wispy, eroded edge and a flat base come
from :mod:`evaluation.billows` (one Warp kernel). Values in [0, 1]. ``usd_scenes/cumulus.usda``
references ``data/cumulus.nvdb``. The default 192 x 128 x 192 grid (12.5 m voxels) takes a few seconds.

``--shape spheres --res 96`` writes the earlier demo field instead (soft spheres eroded by value noise, no billows),
on which the README's older demo-cumulus measurements were taken.

Run:  python tools/make_cumulus.py [--out data] [--seed 7] [--res 192] [--shape billows|spheres]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from evaluation.billows import billow_grid_numpy  # noqa: E402
from evaluation.family_shapes import fbm, soft_spheres, with_turrets  # noqa: E402

#: Cloud footprint [m] along x and z, and height [m] along y; the grid spans this box.
EXTENT_XZ = 2400.0
EXTENT_Y = 1600.0
BASE_HEIGHT = 1000.0  # cloud base above the ground [m]
#: Voxels along x and z by default.
RESOLUTION = 192


def cumulus_spheres(rng: np.random.Generator) -> np.ndarray:
    """(N, 4) spheres (centre x, y, z, radius) [m] relative to the grid's lower corner: the macro shape."""
    c = EXTENT_XZ / 2
    blobs = [(c, 560.0, c - 40.0, 470.0), (c - 430.0, 240.0, c + 110.0, 380.0), (c + 420.0, 220.0, c - 90.0, 360.0),
             (c + 60.0, 180.0, c + 330.0, 330.0), (c - 80.0, 200.0, c - 380.0, 320.0)]
    return np.array(with_turrets(rng, blobs, 30), dtype=np.float32)


def sphere_density(rng: np.random.Generator, shape: tuple, voxel: float) -> np.ndarray:
    """The earlier demo field: soft spheres on a flat base eroded by fractal value noise, no billows."""
    axes = [(np.arange(n) + 0.5) * voxel for n in shape]
    X, Y, Z = np.meshgrid(axes[0] - EXTENT_XZ / 2, axes[1], axes[2] - EXTENT_XZ / 2, indexing="ij")
    blobs = [(0.0, 420.0, 0.0, 480.0), (-380.0, 260.0, 120.0, 330.0), (360.0, 240.0, -80.0, 320.0)]
    field = soft_spheres(X, Y, Z, with_turrets(rng, blobs, 28))
    flat_base = np.clip(Y / 100.0, 0.0, 1.0)
    points = np.stack([(X + EXTENT_XZ / 2) / EXTENT_XZ, Y / EXTENT_Y, (Z + EXTENT_XZ / 2) / EXTENT_XZ], axis=-1)
    return np.clip((field * 3.0 - 0.8 * fbm(points, rng, 6)) * flat_base, 0.0, 1.0)


def cumulus_density(resolution: int = RESOLUTION, seed: int = 7, kind: str = "billows") -> tuple[np.ndarray, float]:
    """Density grid indexed [x, y, z] and its voxel size [m]; ``kind`` "billows" (the demo) or "spheres"."""
    rng = np.random.default_rng(seed)
    voxel = EXTENT_XZ / resolution
    shape = (resolution, int(round(EXTENT_Y / voxel)), resolution)
    size = np.array(shape, dtype=np.float64) * voxel
    if kind == "spheres":
        density = sphere_density(rng, shape, voxel)
    else:
        density = billow_grid_numpy(shape, size, cumulus_spheres(rng), seed)
    # Zero the outermost voxels so every format (clamped .npy, background-padded VDB) agrees at the edges.
    density[[0, -1], :, :] = 0.0
    density[:, [0, -1], :] = 0.0
    density[:, :, [0, -1]] = 0.0
    return density.astype(np.float32), voxel


def write_all(out: Path, resolution: int, seed: int, kind: str = "billows") -> list[Path]:
    import warp as wp

    from warpsky.core.device import init_warp

    init_warp()
    out.mkdir(parents=True, exist_ok=True)
    density, voxel = cumulus_density(resolution, seed, kind)
    written = []
    npy = out / "cumulus.npy"
    np.save(npy, density)
    written.append(npy)
    min_world = (-EXTENT_XZ / 2 + voxel / 2, BASE_HEIGHT + voxel / 2, -EXTENT_XZ / 2 + voxel / 2)
    volume = wp.Volume.load_from_numpy(density, min_world=min_world, voxel_size=voxel, bg_value=0.0, device="cpu")
    nvdb = out / "cumulus.nvdb"
    volume.save_to_nvdb(str(nvdb), codec="zip")
    written.append(nvdb)
    tool = shutil.which("nanovdb_convert")
    if tool:
        vdb = out / "cumulus.vdb"
        subprocess.run([tool, "-f", str(nvdb), str(vdb)], check=True, capture_output=True)
        written.append(vdb)
    else:
        print("nanovdb_convert not found (Debian package libnanovdb-tools): skipped cumulus.vdb", file=sys.stderr)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent.parent / "data")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--res", type=int, default=RESOLUTION, help=f"voxels along x and z (default {RESOLUTION})")
    parser.add_argument("--shape", choices=("billows", "spheres"), default="billows",
                        help="billows: the demo cumulus (default); spheres: the earlier, smoother demo field")
    args = parser.parse_args(argv)
    for path in write_all(args.out, args.res, args.seed, args.shape):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
