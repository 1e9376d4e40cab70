"""The scenery family's tables for the README, from ``warpsky bench error-vs-time`` JSON: per technique at one
rung of its ladder (median, p90 and worst net relative RMSE, mean bias over the family's stages), per stage, and
one row per single stage measured with ``warpsky bench error-vs-time STAGE`` (``--stage NAME=JSON``). With
``--docs PATH`` it also writes those figures and the bench reports they come from as one JSON.

Net relative RMSE: the relative RMSE with the reference's own per-pixel variance taken out (``net_rmse``).

Run:  python evaluation/scripts/scenery_family_table.py OUT/family_error_vs_time.json --family DIR \\
          [--stage valley_fog=OUT_VF/error_vs_time.json ...] [--other-half OUT_TUNE/family_error_vs_time.json]
          [--docs docs/scenery_family/scenery_error_vs_time.json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

#: The rung (index along its ladder) each technique is tabled at: a small budget. Rows of another name (the
#: deck pass's, on a deck stage without voxel media) are tabled at their second rung.
RUNGS = {"hybrid": (3,), "single_scatter": (2,), "slicing": (3,), "path_tracer": (4, 6)}
OTHER_RUNG = 1


def _fmt(value, digits=3, sign=False) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:+.{digits}f}" if sign else f"{value:.{digits}f}"


def chosen_rows(rows: list[dict]) -> list[dict]:
    """The rows at the tabled rungs: by ``rung`` where the rows carry it (family), else by their order within
    their technique's rows (single-stage reports)."""
    out, seen = [], {}
    for row in rows:
        index = row.get("rung", seen.get(row["technique"], 0))
        seen[row["technique"]] = index + 1
        if index in RUNGS.get(row["technique"], (OTHER_RUNG,)):
            out.append(row)
    return out


def technique_summary(rows: list[dict]) -> list[dict]:
    """Per technique and setting, over the stages: median, p90 and worst net rel RMSE, mean bias, median s."""
    groups: dict[tuple, list[dict]] = {}
    for row in chosen_rows(rows):
        if row.get("error") or row["net_rmse"] is None:
            continue
        groups.setdefault((row["technique"], row["setting"] if "rung" not in row else row["rung"]), []).append(row)
    out = []
    for (technique, _), members in groups.items():
        net = np.array([r["net_rmse"] for r in members])
        worst = members[int(np.argmax(net))]
        out.append({"technique": technique, "setting": members[0]["setting"], "stages": len(members),
                    "median_net_rmse": float(np.median(net)), "p90_net_rmse": float(np.percentile(net, 90)),
                    "worst_net_rmse": float(net.max()), "worst_stage": worst.get("stage", ""),
                    "mean_bias": float(np.mean([r["bias"] for r in members])),
                    "median_seconds": float(np.median([r["seconds"] for r in members]))})
    return out


def technique_table(summary: list[dict]) -> str:
    lines = ["| technique | setting | stages | median | p90 | worst (stage) | mean bias | median s |",
             "|---|---|---:|---:|---:|---|---:|---:|"]
    for s in summary:
        lines.append(f"| {s['technique']} | {s['setting']} | {s['stages']} | {_fmt(s['median_net_rmse'])} | "
                     f"{_fmt(s['p90_net_rmse'])} | {_fmt(s['worst_net_rmse'])} ({s['worst_stage']}) | "
                     f"{_fmt(s['mean_bias'], sign=True)} | {_fmt(s['median_seconds'], 2)} |")
    return "\n".join(lines)


def _stage_description(member: dict) -> str:
    tau = {"thin_fog": f"fog τ {member['optical_depth']:.2g}", "thick_fog": f"fog τ {member['optical_depth']:.2g}",
           "deck_haze": f"deck {member['deck_density']:.3f} /m, haze {member['haze'] * 1e4:.1f}e-4 /m",
           "ridge_cloud": f"cloud τ {member['optical_depth']:.2g}"}[member["kind"]]
    return (f"{tau}, sun {member['sun_elevation_deg']:.0f}°, air {'on' if member['air'] else 'off'}")


def stage_table(report: dict, family: dict) -> str:
    """One line per stage: its parameters, the reference's noise and each tabled row's net rel RMSE / bias."""
    members = {m["name"]: m for m in family["members"]}
    noise = {r["stage"]: r.get("rel_noise_per_pixel") for r in report["references"]}
    rows = chosen_rows(report["rows"])
    columns = list(dict.fromkeys((r["technique"], r["setting"]) for r in rows))
    head = " | ".join(f"{t} {s}" for t, s in columns)
    lines = [f"| stage | scene | ref noise | {head} |", "|---|---|---:|" + "---:|" * len(columns)]
    for name in dict.fromkeys(r["stage"] for r in rows):
        cells = []
        for technique, setting in columns:
            found = [r for r in rows if r["stage"] == name and r["technique"] == technique and r["setting"] == setting]
            cells.append(f"{_fmt(found[0]['net_rmse'], 2)} / {_fmt(found[0]['bias'], 2, sign=True)}"
                         if found and not found[0].get("error") else "–")
        lines.append(f"| {name} | {_stage_description(members[name])} | {_fmt(noise.get(name), 3)} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def stage_rows(rows: list[dict]) -> list[dict]:
    """A single stage's tabled rows; a technique whose ladder stopped (on its budget) before its tabled rungs
    contributes its last rung instead."""
    chosen = chosen_rows(rows)
    for technique in dict.fromkeys(r["technique"] for r in rows):
        if not any(r["technique"] == technique for r in chosen):
            chosen.append([r for r in rows if r["technique"] == technique][-1])
    return chosen


def single_stage_table(reports: dict[str, dict]) -> str:
    lines = ["| stage | row | setting | net rel RMSE | bias | seconds | ref noise |",
             "|---|---|---|---:|---:|---:|---:|"]
    for name, report in reports.items():
        for row in stage_rows(report["rows"]):
            lines.append(f"| {name} | {row['technique']} | {row['setting']} | {_fmt(row['net_rmse'])} | "
                         f"{_fmt(row['bias'], sign=True)} | {_fmt(row['seconds'], 2)} | "
                         f"{_fmt(report['reference']['rel_noise_per_pixel'])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("report", type=Path, help="family_error_vs_time.json of the family's bench")
    parser.add_argument("--family", type=Path, required=True, help="the family directory (family.json)")
    parser.add_argument("--stage", action="append", default=[], metavar="NAME=JSON",
                        help="a single stage's error_vs_time.json, tabled under NAME (repeatable)")
    parser.add_argument("--other-half", type=Path, metavar="JSON", help="the other half's family_error_vs_time.json: "
                        "its technique table too (and its report in --docs)")
    parser.add_argument("--docs", type=Path, help="write the figures and the reports to this JSON")
    args = parser.parse_args(argv)
    report = json.loads(args.report.read_text())
    family = json.loads((args.family / "family.json").read_text())
    stages = {}
    for item in args.stage:
        name, _, path = item.partition("=")
        stages[name] = json.loads(Path(path).read_text())
    summary = technique_summary(report["rows"])
    print(technique_table(summary), stage_table(report, family), sep="\n\n")
    if stages:
        print("\n" + single_stage_table(stages))
    other = json.loads(args.other_half.read_text()) if args.other_half else None
    if other:
        print(f"\n{other['settings']['half']} half:\n" + technique_table(technique_summary(other["rows"])))
    if args.docs:
        args.docs.parent.mkdir(parents=True, exist_ok=True)
        blob = {"summary": summary, "family": {k: v for k, v in family.items() if k != "members"},
                "members": family["members"], "family_report": report, "stages": stages,
                "rungs": {k: list(v) for k, v in RUNGS.items()}, "other_rung": OTHER_RUNG}
        if other:
            blob.update(other_half_summary=technique_summary(other["rows"]), other_half_report=other)
        args.docs.write_text(json.dumps(blob, indent=1) + "\n")
        print(f"\nwrote {args.docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
