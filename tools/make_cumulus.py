"""Write the demo cumulus density as .npy, .nvdb and .vdb (procedural and seeded; nothing large is committed).

The cloud is a union of soft spheres piled on a flat base, eroded by fractal value noise: a cauliflower top and a
flat bottom, values in [0, 1]. ``usd_scenes/cumulus.usda`` references ``data/cumulus.nvdb``.

Run:  python tools/make_cumulus.py [--out data] [--seed 7] [--res 96]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from warpsky.evaluation.family_shapes import fbm, soft_spheres, with_turrets

#: Cloud footprint [m] along x and z, and height [m] along y; the grid spans this box.
EXTENT_XZ = 2400.0
EXTENT_Y = 1600.0
BASE_HEIGHT = 1000.0  # cloud base above the ground [m]


def cumulus_density(resolution: int = 96, seed: int = 7) -> tuple[np.ndarray, float]:
    """Density grid indexed [x, y, z] and its voxel size [m]."""
    rng = np.random.default_rng(seed)
    nx = nz = resolution
    voxel = EXTENT_XZ / resolution
    ny = int(round(EXTENT_Y / voxel))
    x = (np.arange(nx) + 0.5) * voxel - EXTENT_XZ / 2
    y = (np.arange(ny) + 0.5) * voxel
    z = (np.arange(nz) + 0.5) * voxel - EXTENT_XZ / 2
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    # Soft spheres: a big central tower, shoulders around it, all sitting on the base at y = 0, and turrets.
    blobs = [(0.0, 420.0, 0.0, 480.0), (-380.0, 260.0, 120.0, 330.0), (360.0, 240.0, -80.0, 320.0)]
    shape = soft_spheres(X, Y, Z, with_turrets(rng, blobs, 28))
    flat_base = np.clip(Y / 100.0, 0.0, 1.0)
    points = np.stack([(X + EXTENT_XZ / 2) / EXTENT_XZ, Y / EXTENT_Y, (Z + EXTENT_XZ / 2) / EXTENT_XZ], axis=-1)
    density = np.clip((shape * 3.0 - 0.8 * fbm(points, rng, 6)) * flat_base, 0.0, 1.0)
    # Zero the outermost voxels so every format (clamped .npy, background-padded VDB) agrees at the edges.
    density[[0, -1], :, :] = 0.0
    density[:, [0, -1], :] = 0.0
    density[:, :, [0, -1]] = 0.0
    return density.astype(np.float32), voxel


def write_all(out: Path, resolution: int, seed: int) -> list[Path]:
    import warp as wp

    from warpsky.device import init_warp

    init_warp()
    out.mkdir(parents=True, exist_ok=True)
    density, voxel = cumulus_density(resolution, seed)
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
    parser.add_argument("--res", type=int, default=96, help="voxels along x and z (default 96)")
    args = parser.parse_args(argv)
    for path in write_all(args.out, args.res, args.seed):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
