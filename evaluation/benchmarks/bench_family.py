"""Benchmark: every technique's error against a path-traced reference across the test half of the validation
family, aggregated per ladder rung (median, p90 and worst relative RMSE, bias, median time).

Generates the family into data/family when it is missing (evaluation/scripts/make_validation_family.py defaults; with
``--profile thick`` the thick family, seed 2027, 12 members, into data/family_thick). Measures
single_scatter, slicing and path_tracer, plus hybrid once it is registered, on the CPU and on every CUDA device
present; writes the table, CSV, JSON and PNG per device under out/bench_family/DEVICE/. References are cached
under $WARPSKY_CACHE/reference/family/ independently of the device, so the first device's references serve the
others (render them on a GPU first: ``warpsky bench error-vs-time --family data/family --half all
--references-only --device cuda``). Timings exclude first compiles. No pass/fail: goals are read by people.

Run:  python evaluation/benchmarks/bench_family.py [--family data/family] [--res 128] [--reference-spp 1024] [--budget
60]
      python evaluation/benchmarks/bench_family.py --profile thick --techniques hybrid,path_tracer --devices cpu
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from evaluation.benchmarks.common import bench_devices  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", choices=("thin", "thick"), default="thin",
                        help="which family to generate when --family holds none (default thin)")
    parser.add_argument("--family", type=Path, default=None,
                        help="default data/family, or data/family_thick with --profile thick")
    parser.add_argument("--out", type=Path, default=None, help="default out/bench_family[_thick]")
    parser.add_argument("--half", choices=("tune", "test", "all"), default="test")
    parser.add_argument("--res", type=int, default=None, help="square image size (default: the family's own, "
                        "128 thin, 64 thick)")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--budget", type=float, default=60.0, help="seconds of ladders per stage (default 60)")
    parser.add_argument("--techniques", default=None, help="comma-separated (default: single_scatter, slicing, "
                        "path_tracer and hybrid when registered)")
    parser.add_argument("--devices", default=None, help="comma-separated Warp devices (default: cpu + all cuda)")
    args = parser.parse_args(argv)


    from evaluation.family import format_family_table, make_family, run_family, write_family_outputs
    from warpsky.core.device import init_warp
    from warpsky.render.registry import technique_names

    init_warp()
    suffix = "" if args.profile == "thin" else f"_{args.profile}"
    args.family = args.family or ROOT / "data" / f"family{suffix}"
    args.out = args.out or ROOT / "out" / f"bench_family{suffix}"
    if not (args.family / "family.json").is_file():
        print(f"generating the {args.profile} validation family into {args.family}", file=sys.stderr)
        if args.profile == "thick":
            make_family(args.family, seed=2027, count=12, profile="thick")
        else:
            make_family(args.family)
    if args.res is None:
        args.res = int(json.loads((args.family / "family.json").read_text()).get("image_size", 128))
    if args.techniques:
        techniques = args.techniques.split(",")
    else:
        techniques = ["single_scatter", "slicing", "path_tracer"]
        techniques += ["hybrid"] if "hybrid" in technique_names() else []
    devices = bench_devices(args.devices)
    for device in devices:
        report = run_family(args.family, techniques, args.res, args.res, device, half=args.half,
                            reference_spp=args.reference_spp, budget_per_stage=args.budget,
                            log=lambda text: print(text, file=sys.stderr))
        print(format_family_table(report))
        for path in write_family_outputs(report, args.out / device.replace(":", "")):
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
