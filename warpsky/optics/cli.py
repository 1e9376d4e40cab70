"""``warpsky optics``: prebuild, plot and export the tables techniques use (the tables' modules load when a verb
runs, not for ``--help``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warpsky.model.scene import SPECIES_NAMES

CHANNEL_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")


def add_parser(sub) -> None:
    optics = sub.add_parser("optics", help="build, plot and export phase-function tables",
                            description="Phase-function tables per species and RGB channel, cached under "
                            "$WARPSKY_CACHE/optics (default ~/.cache/warpsky).")
    verbs = optics.add_subparsers(dest="optics_command", metavar="VERB", required=True)
    build = verbs.add_parser("build", help="build (or load) tables now, so renders do not wait for them")
    build.add_argument("species", nargs="+", choices=SPECIES_NAMES)
    build.add_argument("--orders", type=int, default=None, metavar="N",
                       help="also build multiple-scattering distributions Ams_0..N (Riley Eq. 20)")
    plot = verbs.add_parser("plot", help="log-scale phase functions per channel (and Ams_n families) to a PNG")
    plot.add_argument("species", nargs="+", choices=SPECIES_NAMES)
    plot.add_argument("-o", "--output", type=Path, required=True, help="PNG to write")
    plot.add_argument("--orders", type=int, default=None, metavar="N",
                      help="add a panel per species with Ams_n for n = 1, 2, 4, 8, ... up to N")
    export = verbs.add_parser("export", help="write the table a technique uses as CSV")
    export.add_argument("species", choices=SPECIES_NAMES)
    export.add_argument("-o", "--output", type=Path, required=True, help="CSV to write")
    export.add_argument("--order", type=int, default=None, metavar="N", help="export Ams_N instead of P")


def run(args) -> int:
    return {"build": _build, "plot": _plot, "export": _export}[args.optics_command](args)


def _build(args) -> int:
    from warpsky.optics.tables import build_tables

    tables = build_tables(args.species, orders=args.orders)
    built = {name for name, _, _ in tables.built}
    for name in tables.species:
        times = [f"{kind} {sec:.1f} s" for n, kind, sec in tables.built if n == name]
        print(f"{name:<6} {'built: ' + ', '.join(times) if name in built else 'loaded from cache'}")
    print(f"total {tables.seconds:.2f} s")
    return 0


def _plot(args) -> int:
    import matplotlib  # heavy: loads only for ``warpsky optics plot``
    import numpy as np

    from warpsky.core.files import atomic_write
    from warpsky.optics.grid import angle_grid
    from warpsky.optics.tables import ams_table, phase_table

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    degrees = np.degrees(angle_grid())
    rows = len(args.species)
    cols = 2 if args.orders else 1
    fig, axes = plt.subplots(rows, cols, figsize=(7.5 * cols, 3.2 * rows), squeeze=False)
    for row, name in enumerate(args.species):
        ax = axes[row, 0]
        table = phase_table(name)
        for c, colour in enumerate(CHANNEL_COLOURS):
            ax.semilogy(degrees, np.maximum(table[c], 1e-8), color=colour, lw=0.8, label="RGB"[c])
        ax.set_title(f"{name}: phase function per channel")
        ax.set_xlabel("scattering angle [deg]")
        ax.set_ylabel("p [1/sr]")
        ax.set_xlim(0, 180)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
        if args.orders:
            ams, _ = ams_table(name, args.orders)
            ax = axes[row, 1]
            order = 1
            while order <= args.orders:
                ax.semilogy(degrees, np.maximum(ams[order, 1], 1e-8), lw=0.8, label=f"n={order}")
                order *= 2
            ax.set_title(f"{name}: Ams_n, green channel")
            ax.set_xlabel("scattering angle [deg]")
            ax.set_xlim(0, 180)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    atomic_write(args.output, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    print(args.output)
    return 0


def _export(args) -> int:
    import numpy as np

    from warpsky.core.files import atomic_write
    from warpsky.optics.grid import angle_grid
    from warpsky.optics.tables import ams_table, phase_table

    if args.order is None:
        table, label = phase_table(args.species), "P"
    else:
        ams, _ = ams_table(args.species, max(args.order, 1))
        table, label = ams[args.order], f"Ams_{args.order}"
    data = np.column_stack([np.degrees(angle_grid()), table.T])
    header = f"# warpsky {args.species} {label}; p in 1/sr, integral over the sphere = 1\nangle_deg,R,G,B"

    def write(tmp):
        np.savetxt(tmp, data, delimiter=",", header=header, comments="", fmt="%.10g")

    atomic_write(args.output, write)
    print(args.output)
    return 0


if __name__ == "__main__":  # pragma: no cover
    parser = argparse.ArgumentParser(prog="warpsky")
    add_parser(parser.add_subparsers(dest="command"))
    sys.exit(run(parser.parse_args()))
