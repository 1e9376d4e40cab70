"""Error against time of the deck pass (Max 1986) on the small deck stage
(:mod:`evaluation.deck_stage`), against the path tracer tracing the voxelised deck and haze.

    PYTHONPATH=. python evaluation/scripts/bench_deck_error_vs_time.py [OUT_DIR] [--spp N] [--res W H] [--device D]

Writes the stage, runs ``warpsky bench error-vs-time``'s report (rows ``deck pass (Max 1986, MODE)`` along
``deck.step_length``) and prints the table; CSV, JSON and PNG go to OUT_DIR.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from evaluation.deck_stage import deck_scene  # noqa: E402
from evaluation.error_vs_time import format_table, run_report, write_outputs  # noqa: E402
from warpsky.core.device import init_warp  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="deck_error_vs_time")
    parser.add_argument("--spp", type=int, default=2048, help="reference samples per pixel")
    parser.add_argument("--res", type=int, nargs=2, default=(96, 64))
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--single-spp", type=int, default=512, help="samples of the single-scattering check "
                        "(0: none)")
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
    if args.single_spp:
        single_scattering_check(scene, args.res, args.device, args.single_spp)
    return 0


def single_scattering_check(scene, res, device: str, spp: int) -> None:
    """Print the exact mode's mean radiance against the path tracer limited to single scattering (max_bounces = 1:
    the deck, the haze and the sunlit ground, no light scattered twice): what the rows' bias is not."""
    import math

    from evaluation.error_vs_time import frame_plan, render_frame_radiance
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    width, height = res
    exact = render_frame_radiance(frame_plan(scene, "single_scatter", {"deck.mode": "exact"}, width, height,
                                             device), scene)[0][..., 1]
    single = PathTracer(PathTracerSettings(spp=spp, seed=7, max_bounces=1), device=device).render(scene, width,
                                                                                                  height)
    noise = math.sqrt(float(single.aovs["variance"][..., 1].sum())) / exact.size
    mean = float(single.radiance[..., 1].mean())
    print(f"exact mode vs path tracer with max_bounces=1 ({spp} spp): {float(exact.mean()) / mean - 1.0:+.4f} "
          f"+- {noise / mean:.4f} (relative, mean radiance)")


if __name__ == "__main__":
    raise SystemExit(main())
