"""Choose the fog pass's quadrature and the deck pass's steps on the tune half of the scenery family, and
report the choice on the test half (``evaluation.scenery_settings``'s docstring says how).

Run:  python evaluation/scripts/choose_scenery_settings.py [--family data/scenery_family_settings] [--count 48]
      [--only deck] [--out docs/scenery_family/settings_choice.json]

The family is written first when its directory holds no ``family.json`` (as
``evaluation/scripts/make_scenery_family.py``
writes it, seed 2029, 48 members: per half 8 thin and 8 thick fogs, 4 decks with haze and 4 ridge clouds, which
hold neither and are skipped), then every member's passes are rendered at the family's size with each candidate
and with the finer quadrature; no path tracing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", type=Path, default=ROOT / "data" / "scenery_family_settings",
                        help="family directory (written when it holds no family.json)")
    parser.add_argument("--seed", type=int, default=2029, help="seed of a family written here (default 2029)")
    parser.add_argument("--count", type=int, default=48, help="members of a family written here (default 48)")
    parser.add_argument("--device", default="cpu", help="device (default cpu)")
    parser.add_argument("--only", choices=("fog", "deck"), default=None, help="measure one element's members only")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "scenery_family" / "settings_choice.json",
                        help="JSON written (default docs/scenery_family/settings_choice.json)")
    args = parser.parse_args(argv)

    from evaluation.scenery_family import make_scenery_family
    from evaluation.scenery_settings import run

    started = time.perf_counter()
    if not (args.family / "family.json").exists():
        make_scenery_family(args.family, seed=args.seed, count=args.count, log=print)
    elements = ("fog", "deck") if args.only is None else (args.only,)
    result = run(args.family, device=args.device, elements=elements)
    result["seconds"] = time.perf_counter() - started
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    for element in elements:
        choice = result[element]
        test = choice["candidates"][choice["chosen"]]["test"]
        print(f"{element}: {choice['chosen']} (tune worst <= {choice['tolerance']:g}: {choice['within_tolerance']}); "
              f"test half: {test}")
    print(f"wrote {args.out} in {result['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
