"""What the benchmarks share: the devices a run measures and the stage it reads."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def bench_devices(spec: str | None = None) -> list[str]:
    """The comma-separated Warp devices of ``spec``, else the CPU and every CUDA device present."""
    import warp as wp

    if spec:
        return spec.split(",")
    return ["cpu"] + [f"cuda:{i}" for i in range(wp.get_cuda_device_count())]


def demo_scene(stage: Path):
    """The scene of ``stage`` at its first time code; None, after saying which command makes it, when the stage is
    the demo cumulus and its field has not been generated."""
    from warpsky.usd.stage import StageReader

    if not (ROOT / "data" / "cumulus.nvdb").exists() and stage.name == "cumulus.usda":
        print("data/cumulus.nvdb is missing: run `python tools/make_cumulus.py` (or `make data`)", file=sys.stderr)
        return None
    return StageReader(stage).scene_at(None)
