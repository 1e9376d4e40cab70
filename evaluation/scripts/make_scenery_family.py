"""Write the seeded scenery family: terrain meshes with thin and thick valley fog, a height-field cloud deck with
haze over terrain, voxel cumulus cut by a ridge, and valley fog under a broken stratocumulus layer, with and without
Earth air, split into a ``tune`` and a ``test`` half (``evaluation.scenery_family``'s docstring tables the
parameters).

Each member is a ``.usda`` stage (camera, sun, terrain mesh of 3200 triangles, a lake plane, its fog, deck, cloud or
fog and layer, 96 x 64 render settings) and, for a ridge cloud, its dense ``.npy`` field (for a layer, its
thickness map); ``family.json`` lists every member with
its parameters and half. ``warpsky bench error-vs-time --family DIR`` measures the techniques on it against the
path tracer, which traces the meshes, the fog, the deck and the layer.

Run:  python evaluation/scripts/make_scenery_family.py [--out data/scenery_family] [--seed 2028] [--count 12] [--layered
4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "scenery_family",
                        help="directory (default data/scenery_family)")
    parser.add_argument("--seed", type=int, default=2028, help="random seed (default 2028)")
    parser.add_argument("--count", type=int, default=12, help="members, at least 2 (default 12)")
    parser.add_argument("--layered", type=int, default=4,
                        help="fog-under-a-stratocumulus-layer members appended after them (default 4)")
    args = parser.parse_args(argv)
    if args.count < 2:
        parser.error(f"--count must be at least 2 (one member per half), got {args.count}")

    from evaluation.scenery_family import make_scenery_family

    started = time.perf_counter()
    path = make_scenery_family(args.out, seed=args.seed, count=args.count, layered=max(0, args.layered), log=print)
    print(f"wrote {path} ({args.count + max(0, args.layered)} members) in {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
