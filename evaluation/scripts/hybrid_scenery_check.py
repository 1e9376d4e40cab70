"""A technique's frame of fog and terrain against the path tracer's: mean ratio and relative RMSE of the luminance.

    python evaluation/scripts/hybrid_scenery_check.py slab                      # fog slab over a ground plane, no air,
    32 x 32 python evaluation/scripts/hybrid_scenery_check.py /tmp/x/usd_scenes/valley_fog.usda --res 96 64
    --reference-spp 1024

A stage's terrain comes from ``make terrain`` (``tools/make_terrain.py``; a stage copied elsewhere needs its
``../data/terrain.usda`` there). Pixels brighter than 100 x the reference's median (the sun's disk) are left out;
the lower three quarters of the rows are also reported alone (the terrain and the fog under a sky). ``--set`` passes
settings to the technique under test (``--set multiple_scattering=0``: the passes alone).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpsky.cli.options import setting_arg
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.model.fog import AnalyticFog, ConstantTerm
from warpsky.model.scene import Camera, Ground, Scene, Sun
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan
from warpsky.usd.stage import StageReader


def slab_scene() -> Scene:
    """A fog slab of optical depth 1 (albedo 1, g 0.85) 20 m thick over a ground of albedo 0.5, no air; the sun
    41 deg up, the camera 60 m up looking 37 deg down (its top rows see the black sky)."""
    fog = AnalyticFog("slab", [ConstantTerm(0.05)], floor=0.0, top=20.0, albedo=np.ones(3), g=0.85)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, 0.8, 0.6], [0.0, -0.6, 0.8]])
    camera = Camera("cam", np.array([0.0, 60.0, 0.0]), rotation, 18.0, 36.0, 36.0, far=5000.0)
    d = np.array([0.3, 0.6, 0.5])
    return Scene(camera, Sun(d / np.linalg.norm(d), np.ones(3)), fogs=(fog,), ground=Ground(0.0, np.full(3, 0.5)))


def luminance_frame(scene: Scene, technique: str, settings: dict, res: tuple[int, int]) -> tuple[np.ndarray, float]:
    plan = make_plan(scene, technique=technique, settings=settings, resolution=res)
    started = time.perf_counter()
    _, layers = render_layers(plan, scene)
    rgb = composite(layers, far=scene.camera.far).rgba[..., :3].astype(np.float64)
    return rgb @ LUMINANCE_WEIGHTS, time.perf_counter() - started


def report(name: str, image: np.ndarray, reference: np.ndarray) -> str:
    keep = reference < 100.0 * np.median(reference)
    lower = np.zeros_like(keep)
    lower[len(keep) // 4:] = True
    parts = []
    for label, mask in (("frame", keep), ("lower 3/4", keep & lower)):
        a, b = image[mask], reference[mask]
        parts.append(f"{label}: mean ratio {a.mean() / b.mean():.3f}, rel RMSE "
                     f"{np.sqrt(np.mean((a - b) ** 2)) / b.mean():.3f}")
    return f"{name}: " + "; ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("stage", help="'slab' or a .usda stage")
    parser.add_argument("--res", type=int, nargs=2, default=None, help="width height (32 32 for the slab, else 96 64)")
    parser.add_argument("--technique", default="hybrid")
    parser.add_argument("--reference-spp", type=int, default=2048)
    parser.add_argument("--set", type=setting_arg, action="append", default=[],
                        help="NAME=VALUE for the technique under test")
    args = parser.parse_args()
    scene = slab_scene() if args.stage == "slab" else StageReader(args.stage).scene_at(None)
    res = tuple(args.res) if args.res else ((32, 32) if args.stage == "slab" else (96, 64))
    settings = dict(args.set)
    image, seconds = luminance_frame(scene, args.technique, settings, res)
    reference, ref_seconds = luminance_frame(scene, "path_tracer", {"spp": str(args.reference_spp)}, res)
    print(f"{args.technique} {seconds:.1f} s, path_tracer ({args.reference_spp} spp) {ref_seconds:.1f} s")
    print(report(args.technique, image, reference))


if __name__ == "__main__":
    main()
