"""Does the simulated storm grow an anvil? The solver run (no frames written, no rendering) and, at every few
frames, the horizontal area [km^2] of the columns whose condensate exceeds a threshold somewhere in each height band.

Condensate is cloud + ice + snow: the solver's cloud (liquid and ice) and the frozen share of its precipitation,
by the temperature partition the frames use (:func:`warpsky.simulate.frames.ice_fraction`); rain is left out. An
anvil is ice cloud spreading at and below the tropopause much wider than the updraft: the anvil band's area over the
mid band's (ratio > 2 by 30-40 minutes).

Run:  python evaluation/scripts/storm_anvil.py [--grid 128x128x64] [--dx 500] [--dy 250] [--frames 48]
          [--minutes 40] [--every 6] [--sponge 3000] [--json out/anvil/run.json]

The stepping is ``warpsky simulate``'s: ``--frames`` equal intervals over ``--minutes``, each run by
``CloudSolver.run`` (so the figures are those of the frames a default run writes).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

#: Height bands [km]: low (the cloud base and the updraft's root), mid, anvil (under the 12 km tropopause), above.
BANDS = {"low": (2.0, 4.0), "mid": (5.0, 7.0), "anvil": (9.0, 12.0), "top": (12.0, 99.0)}
#: Condensate that counts [kg/kg] (0.01 g/kg).
THRESHOLD = 1.0e-5


def condensate(fields: dict, base) -> np.ndarray:
    """Cloud + ice + snow [kg/kg] per cell (module docstring)."""
    from warpsky.simulate.frames import ice_fraction

    temperature = fields["theta"] * base.exner[None, :, None]
    return fields["cloud"] + fields["rain"] * ice_fraction(temperature)


def band_areas(q: np.ndarray, dx: float, dy: float) -> dict[str, float]:
    """Area [km^2] of the columns with condensate ``q`` (:func:`condensate`) above :data:`THRESHOLD` somewhere in
    each band (levels whose centres lie in it)."""
    heights = (np.arange(q.shape[1]) + 0.5) * dy / 1000.0
    areas = {}
    for name, (low, high) in BANDS.items():
        levels = (heights >= low) & (heights < high)
        cloudy = q[:, levels, :].max(axis=1) > THRESHOLD if levels.any() else np.zeros((1, 1), bool)
        areas[name] = float(cloudy.sum()) * dx * dx / 1.0e6
    return areas


def summary(fields: dict, base, dx: float, dy: float) -> dict:
    """Band areas, the anvil/mid ratio, the cloud top [km] and the largest updraft [m/s]."""
    q = condensate(fields, base)
    areas = band_areas(q, dx, dy)
    levels = np.nonzero(q.max(axis=(0, 2)) > THRESHOLD)[0]
    return {"areas": areas, "ratio": areas["anvil"] / areas["mid"] if areas["mid"] > 0.0 else float("nan"),
            "top_km": float((levels.max() + 1) * dy / 1000.0) if len(levels) else 0.0,
            "w_max": float(fields["velocity"][..., 1].max()),
            "precip_aloft_g_kg": float(fields["rain"][:, int(5000.0 / dy):, :].max() * 1000.0)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", default="128x128x64", help="NXxNZxNY columns and levels (warpsky simulate's)")
    parser.add_argument("--dx", type=float, default=500.0)
    parser.add_argument("--dy", type=float, default=250.0)
    parser.add_argument("--sponge", type=float, default=None, help="sponge depth [m] (default: the solver's)")
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--minutes", type=float, default=40.0)
    parser.add_argument("--every", type=int, default=6, help="report every this many frames (and the last)")
    parser.add_argument("--json", type=Path, default=None, help="write the reports here")
    args = parser.parse_args(argv)

    import warp as wp

    from warpsky.simulate.solver import CloudSolver, SimulationSettings
    from warpsky.simulate.sounding import weisman_klemp

    wp.config.quiet = True
    nx, nz, ny = (int(v) for v in args.grid.lower().split("x"))
    sponge = {} if args.sponge is None else {"sponge_depth": args.sponge}
    settings = SimulationSettings(nx=nx, ny=ny, nz=nz, dx=args.dx, dy=args.dy, **sponge)
    solver = CloudSolver(weisman_klemp(), settings, "cpu")
    started = time.perf_counter()
    print(f"grid {nx}x{nz}x{ny}, dx {args.dx:g} m, dy {args.dy:g} m, lid {settings.height / 1000:g} km, sponge from "
          f"{(settings.height - settings.sponge_depth) / 1000:g} km; areas "
          f"[km^2] of condensate > {THRESHOLD * 1000:g} g/kg", flush=True)
    print(" min   low 2-4  mid 5-7  anvil 9-12  top 12+  anvil/mid  top km  w max  precip>5km g/kg", flush=True)
    reports = []
    seconds = 60.0 * args.minutes / args.frames
    for frame in range(1, args.frames + 1):
        solver.run(seconds)
        if frame % args.every and frame != args.frames:
            continue
        report = {"minute": solver.time / 60.0, **summary(solver.fields(), solver.base, args.dx, args.dy)}
        reports.append(report)
        a = report["areas"]
        print(f"{report['minute']:4.1f} {a['low']:9.1f} {a['mid']:8.1f} {a['anvil']:11.1f} {a['top']:8.1f} "
              f"{report['ratio']:10.2f} {report['top_km']:7.2f} {report['w_max']:6.1f} "
              f"{report['precip_aloft_g_kg']:8.2f}", flush=True)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cost = {"wall_s": time.perf_counter() - started, "cpu_s": usage.ru_utime + usage.ru_stime}
    print(f"wall {cost['wall_s']:.0f} s, CPU {cost['cpu_s']:.0f} s, {solver.step_count} steps", flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "reports": reports,
                                         **cost}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
