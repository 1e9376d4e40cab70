"""Terrain, analytic fog and height-field clouds: warm ms per frame of each pass and of the whole frame on the two
stages that use them, on cpu and cuda when present.

- ``valley_fog``: terrain mesh (131 k triangles) + Biri fog + sky: the surfaces pass, the fog pass, the frame.
- ``sunbeams``: terrain + Max height-field clouds with haze + sky: the surfaces pass, the deck pass in its
  ``exact``, ``max`` and ``sexp`` modes, the frame.

    python evaluation/benchmarks/bench_scenery.py [--device cpu|cuda|all] [--width 1024 --height 768] [--json]

Needs ``data/terrain.usda`` (``make terrain``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _best(call, repeats: int) -> tuple[float, object]:
    """(fastest wall time [s] of ``repeats`` warm calls, the last result); one call first to compile and warm."""
    result = call()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - started)
    return min(times), result


def stage_rows(stage: str, device: str, width: int, height: int, repeats: int) -> list[dict]:
    from warpsky.passes.frame import depth_layers, ground_pass
    from warpsky.passes.surfaces.surfaces import SurfacesPass, kept_renderer
    from warpsky.render.frame import render_image
    from warpsky.render.options import RenderOptions
    from warpsky.render.plan import make_plan
    from warpsky.usd.stage import StageReader

    reader = StageReader(ROOT / "usd_scenes" / f"{stage}.usda")
    start = reader.time_range().start
    scene = reader.scene_at(start)
    plan = make_plan(scene, resolution=(width, height), device=device)
    rows = []

    def row(what: str, seconds: float, **extra) -> None:
        rows.append({"stage": stage, "device": device, "what": what, "width": width, "height": height,
                     "ms": 1e3 * seconds, **extra})

    surfaces = kept_renderer(device)
    draw_ground = ground_pass(plan.pass_runners, scene) == SurfacesPass.name
    seconds, layer = _best(lambda: surfaces.render(scene, width, height, draw_ground=draw_ground), repeats)
    row("surfaces pass", seconds, triangles=int(layer.stats.get("triangles", 0)))
    limit = layer.depth
    if scene.fogs:
        from warpsky.passes.fog.fog import Fog

        fog = Fog(device=device)
        occluders = surfaces.occluders if scene.meshes else None
        row("fog pass (terrain shadows)",
            _best(lambda: fog.render(scene, width, height, limit=limit, occluders=occluders), repeats)[0])
        row("fog pass (no shadows)", _best(lambda: fog.render(scene, width, height, limit=limit), repeats)[0])
    if scene.decks:
        from warpsky.passes.deck.deck import Deck

        for mode in ("exact", "max", "sexp"):
            clouds = Deck(device=device, mode=mode)
            row(f"deck pass ({mode})",
                _best(lambda c=clouds: c.render(scene, width, height, limit=limit), repeats)[0])
    seconds, _ = _best(lambda: depth_layers(plan, scene), repeats)
    row("all scenery passes", seconds)
    options = RenderOptions(device=device, resolution=(width, height))
    seconds, _ = _best(lambda: render_image(scene, plan, options, stage=str(reader.path), time_code=start), repeats)
    row("frame (passes + sky + composite)", seconds)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="all", help="cpu, cuda:0 or all (every device present)")
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=768)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--stages", nargs="+", default=["valley_fog", "sunbeams"])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    import warp as wp

    from warpsky.core.device import init_warp

    init_warp()
    if not (ROOT / "data" / "terrain.usda").is_file():
        parser.error("data/terrain.usda is missing: run `make terrain` first")
    devices = ["cpu"] + (["cuda:0"] if wp.get_cuda_device_count() else [])
    if args.device != "all":
        devices = [args.device]
    rows = [r for d in devices for s in args.stages for r in stage_rows(s, d, args.width, args.height, args.repeats)]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'stage':<11} {'device':<7} {'size':>9}  {'what':<34} {'ms':>9} {'fps':>8}")
    for r in rows:
        print(f"{r['stage']:<11} {r['device']:<7} {r['width']:>4}x{r['height']:<4}  {r['what']:<34} {r['ms']:9.1f} "
              f"{1e3 / r['ms']:8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
