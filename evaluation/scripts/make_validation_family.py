"""Write the seeded validation family: cloud stages of five kinds spanning optical depth 0.1-300, albedo, phase,
sun elevation and direction, ground and atmosphere, split into a ``tune`` and a ``test`` half. ``--profile thick``
writes the thick family instead: storm cells (droplets, an ice anvil, a rain shaft), stratocumulus decks seen from
below and above, dense cumulus and a camera inside a dense cloud, of peak optical depth 100-1000, at 64 x 64.

Each member is a ``.usda`` stage (camera, sun, Volume, optional ground and atmosphere, 128 x 128 render settings)
and its dense ``.npy`` field; ``family.json`` lists every member with its parameters and half. The logic lives in
``evaluation.family_stages`` (its docstring tables the parameters); ``warpsky bench error-vs-time
--family DIR`` measures the techniques on it.

Run:  python evaluation/scripts/make_validation_family.py [--out data/family] [--seed 2026] [--count 24] [--res 48]
      python evaluation/scripts/make_validation_family.py --profile thick --out data/family_thick --seed 2027 --count 12
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
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "family", help="directory (default data/family)")
    parser.add_argument("--seed", type=int, default=2026, help="random seed (default 2026)")
    parser.add_argument("--count", type=int, default=24, help="members, at least 2 (default 24)")
    parser.add_argument("--res", type=int, default=48, help="voxels along each grid's longest axis, 8..64 "
                        "(default 48)")
    parser.add_argument("--profile", default="thin", choices=("thin", "thick"),
                        help="thin: the validation family (default); thick: peak optical depth 100-1000")
    args = parser.parse_args(argv)
    if args.count < 2:
        parser.error(f"--count must be at least 2 (one member per half), got {args.count}")
    if not 8 <= args.res <= 64:
        parser.error(f"--res must lie in 8..64, got {args.res}")

    from evaluation.family_stages import make_family

    started = time.perf_counter()
    path = make_family(args.out, seed=args.seed, count=args.count, resolution=args.res, profile=args.profile,
                       log=print)
    print(f"wrote {path} ({args.count} members) in {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
