"""Benchmark: every technique (and the stratiform pass) on every device present, cold and warm ms per frame,
kernel vs wall time on CUDA, peak memory, paths/s of the Monte Carlo part; a table on stdout and
``out/bench_speed.json``. A thin wrapper of ``warpsky bench speed`` (see its ``--help`` for the columns and the
fixed-work settings) whose demo stages and JSON path do not depend on the working directory.

Run:  python evaluation/benchmarks/bench_speed.py [--threads 1,2] [--res 128] [--gpu-res 512] [--frames 3] [...]
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    from warpsky.cli.main import main as warpsky_main

    args = list(sys.argv[1:] if argv is None else argv)
    if "--stages" not in args:
        args += ["--stages", ",".join(str(ROOT / "usd_scenes" / name) for name in ("cumulus.usda",
                                                                                  "stratocumulus.usda"))]
    if "--json" not in args:
        args += ["--json", str(ROOT / "out" / "bench_speed.json")]
    return warpsky_main(["bench", "speed", *args])


if __name__ == "__main__":
    sys.exit(main())
