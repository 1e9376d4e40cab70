"""Skylight on and off (the ``skylight`` setting) in single_scatter and slicing against the path tracer on stages
with an atmosphere: relative RMSE, bias and net RMSE of the composited frame over the covered pixels (96x64,
reference 256 spp, cached next to the rows).

Run:  PYTHONPATH=. python evaluation/benchmarks/bench_skylight.py OUT_DIR STAGE.usda [STAGE.usda ...]
"""
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from evaluation.error_vs_time import error_metrics, frame_plan, reference_image, render_frame_radiance  # noqa: E402
from evaluation.family import covered_pixels  # noqa: E402
from warpsky.core.device import init_warp  # noqa: E402
from warpsky.usd.stage import StageReader  # noqa: E402

init_warp()
W, H, SPP = 96, 64, 256
out = Path(sys.argv[1])
out.mkdir(parents=True, exist_ok=True)
rows = []
for stage in sys.argv[2:]:
    scene = StageReader(stage).scene_at(None)
    assert scene.atmosphere is not None, stage
    name = Path(stage).stem
    t = time.time()
    ref, _, var, _, cached = reference_image(scene, W, H, "cpu", spp=SPP, seed=7, cache_path=out / f"{name}.npz")
    print(f"{name}: reference {time.time() - t:.0f} s (cached {cached})", flush=True)
    covered = covered_pixels(scene, W, H, "cpu")
    for technique in ("single_scatter", "slicing"):
        for sky in (0, 1):
            plan = frame_plan(scene, technique, {"skylight": sky}, W, H, "cpu")
            t = time.time()
            radiance = render_frame_radiance(plan, scene)[0]
            m = error_metrics(radiance, ref, covered, var)
            rows.append({"stage": name, "technique": technique, "skylight": sky, "seconds": time.time() - t, **m})
            print(f"  {technique:<15} skylight={sky} rel RMSE {m['rel_rmse']:.4f} bias {m['bias']:+.4f} "
                  f"net {m['net_rmse']:.4f}", flush=True)
(out / "rows.json").write_text(json.dumps(rows, indent=1))
