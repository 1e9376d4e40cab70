"""``warpsky simulate``: grow a storm with the cloud solver (:mod:`warpsky.simulate`) and write it as a stage that
``warpsky render`` renders."""

from __future__ import annotations

from pathlib import Path

from warpsky.core.errors import UsageError

DESCRIPTION = """\
Simulate a thunderstorm cell and write it for rendering: an anelastic cloud solver in Warp kernels (on a MAC grid:
semi-Lagrangian velocity, conservative flux transport of heat and water, buoyancy with condensate loading, vorticity
confinement, a pressure projection by preconditioned conjugate gradients, a sponge under the lid; after Harris et
al. 2003) with Kessler rain (snow falling slowly and cloud ice converting slowly where it is cold) and saturation
adjustment with the heat of deposition aloft, started from a sounding (CM1's input_sounding format; default:
Weisman & Klemp 1982, 15 m/s of shear) and a warm bubble (+2 K, 10 km x 1.4 km radii). Lateral boundaries are
periodic, and the grid moves with the storm (--domain-speed).

Writes DIR/NAME/<field>.<frame>.nvdb (cloud, rain, ice, snow extinction [1/m] from warpsky.model.water_optics,
condensate above the freezing level partitioned into ice by temperature; velocity [m/s] for motion blur), the stage
DIR/NAME.usda (rewritten after every frame, so a stopped run keeps the frames it finished) and the sounding used,
DIR/NAME.input_sounding."""

EPILOG = """\
examples:
  warpsky simulate --out out/sim                     # 128x128x64 cells, 48 frames over 40 minutes
  warpsky simulate --grid 64x64x48 --dx 1000 --frames 12 --minutes 30 --out out/small
  warpsky simulate --sounding my_input_sounding --device cuda --out out/cuda
  warpsky render out/sim/storm.usda out/sim/storm.####.exr --frames 48 --technique slicing --res 128x96
"""


def _grid(text: str) -> tuple[int, int, int]:
    try:
        nx, nz, ny = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"--grid takes NXxNYxLEVELS (e.g. 128x128x64), got {text!r}") from None
    return nx, ny, nz


def _speed(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        u, v = (float(value) for value in text.split(","))
    except ValueError:
        raise UsageError(f"--domain-speed takes U,V in m/s (e.g. 10,0), got {text!r}") from None
    return u, v


def add_parser(sub) -> None:
    import argparse

    cmd = sub.add_parser("simulate", help="grow a storm with the cloud solver and write it as a stage",
                         description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    cmd.add_argument("--sounding", type=Path, metavar="FILE",
                     help="CM1 input_sounding (surface p [mb], θ [K], q_v [g/kg]; then z [m], θ, q_v, u, v per line; "
                     "default: Weisman & Klemp 1982)")
    cmd.add_argument("--grid", default="128x128x64", metavar="NXxNYxLEVELS",
                     help="cells along x, along y (horizontal) and levels (default 128x128x64)")
    cmd.add_argument("--dx", type=float, default=500.0, metavar="M", help="horizontal spacing [m] (default 500)")
    cmd.add_argument("--dz", type=float, default=250.0, metavar="M",
                     help="level spacing [m] (default 250: 64 levels reach 16 km)")
    cmd.add_argument("--frames", type=int, default=48, help="frames to write, evenly over the run (default 48)")
    cmd.add_argument("--minutes", type=float, default=40.0, help="minutes of storm life to simulate (default 40)")
    cmd.add_argument("--time-step", type=float, default=10.0, metavar="S", help="longest time step [s] (default 10)")
    cmd.add_argument("--seed", type=int, default=1, help="seed of the bubble's small random perturbation")
    cmd.add_argument("--domain-speed", default=None, metavar="U,V",
                     help="the grid's motion [m/s] along x and y: the solver takes the wind relative to it and the "
                     "frames move with it, so the storm stays in the periodic domain (default: the mean wind of "
                     "the lowest 6 km; 0,0 keeps the grid still)")
    cmd.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for the stage and its grids")
    cmd.add_argument("--name", default="storm", help="stage name: DIR/NAME.usda and DIR/NAME/ (default storm)")
    cmd.add_argument("--device", default="auto", help="cpu, cuda, cuda:N or auto (default: CUDA when present)")


def cmd_simulate(args) -> int:
    from warpsky.core.device import resolve_device
    from warpsky.core.progress import format_seconds
    from warpsky.simulate.run import simulate
    from warpsky.simulate.solver import SimulationSettings
    from warpsky.simulate.sounding import read_sounding, weisman_klemp

    nx, ny, nz = _grid(args.grid)
    settings = SimulationSettings(nx=nx, ny=ny, nz=nz, dx=args.dx, dy=args.dz, time_step=args.time_step,
                                  seed=args.seed, domain_speed=_speed(args.domain_speed))
    sounding = read_sounding(args.sounding) if args.sounding else weisman_klemp()
    if sounding.height[-1] < settings.height:
        raise UsageError(f"the sounding ends at {sounding.height[-1]:g} m, under the grid's top "
                         f"({settings.height:g} m = {ny} levels of {args.dz:g} m)")
    summary = simulate(sounding, settings, frames=args.frames, minutes=args.minutes, out=args.out,
                       device=resolve_device(args.device), name=args.name)
    print(f"{summary.stage}: {summary.frame_count} frames over {summary.storm_seconds / 60.0:.1f} min in "
          f"{format_seconds(summary.wall_seconds)} ({summary.step_count} steps; total water changed by "
          f"{100.0 * summary.water_change:+.2f} %)")
    return 0
