"""Error against time of the height-field pass (Max 1986) on the small deck stage
(:mod:`warpsky.evaluation.deck_stage`), against the path tracer tracing the voxelised deck and haze.

    PYTHONPATH=. python tools/bench_deck_error_vs_time.py [OUT_DIR] [--spp N] [--res W H] [--device D]

Writes the stage, runs ``warpsky bench error-vs-time``'s report (rows ``height-field pass (Max 1986, MODE)`` along
``heightfield.step_length``) and prints the table; CSV, JSON and PNG go to OUT_DIR.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from warpsky.device import init_warp
from warpsky.evaluation.deck_stage import deck_scene
from warpsky.evaluation.error_vs_time import format_table, run_report, write_outputs


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="deck_error_vs_time")
    parser.add_argument("--spp", type=int, default=2048, help="reference samples per pixel")
    parser.add_argument("--res", type=int, nargs=2, default=(96, 64))
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--budget", type=float, default=120.0, help="seconds for the ladders")
    args = parser.parse_args()
    init_warp()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = deck_scene(out / "deck.usda")
    report = run_report(scene, techniques=["single_scatter"], width=args.res[0], height=args.res[1],
                        device=args.device, budget=args.budget, reference_spp=args.spp)
    print(format_table(report))
    write_outputs(report, out, stem="deck_error_vs_time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
