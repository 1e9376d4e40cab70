"""Benchmark: how smooth the 22° halo's inner edge is in a rendered frame, in pixels.

Along rays from the sun at position angles ``--angles`` (degrees from straight above the sun, both sides), the
luminance of the EXR is sampled (bilinear between pixel centres) every 0.02° of angular distance from the sun
between 19° and 24°; the inner edge is the distance of its steepest rise (refined by a parabola through the
largest difference and its neighbours). A small circle on the sky (centre direction and angular radius) is
fitted to those edge points by least squares, and each point's residual is turned into pixels by the camera's
local scale along the ray. A halo looked up from coarse bins shows stair steps: residuals of several pixels
that jump from one ray to the next. The default angles avoid the upper tangent arc (above the sun) and the
parhelia (beside it), which touch the halo.

Run:  python evaluation/benchmarks/bench_halo_edge.py [out/sundogs/sundogs.0001.exr] [--stage usd_scenes/sundogs.usda]
      [--angles 30:75] [--json out/bench_halo_edge.json]
(after ``make sundogs``, or the render commands it runs). No pass/fail: goals are read by people.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
sys.path.insert(0, str(ROOT))

#: Angular distances [deg] searched for the edge, and their spacing.
SEARCH_DEG = (19.0, 24.0, 0.02)
#: Rec. 709 luminance weights.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def edge_distance(profile: np.ndarray, step_deg: float) -> float:
    """Offset [deg] from the profile's start of its steepest rise, refined by a parabola."""
    rise = np.diff(profile)
    k = int(np.argmax(rise))
    offset = 0.0
    if 0 < k < len(rise) - 1:
        left, mid, right = rise[k - 1], rise[k], rise[k + 1]
        curvature = left - 2.0 * mid + right
        if curvature < 0.0:
            offset = 0.5 * (left - right) / curvature
    return (k + 0.5 + offset) * step_deg


def fit_small_circle(points: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, float]:
    """(centre unit vector, angular radius [rad]) of the small circle nearest (N, 3) unit ``points``."""
    from scipy.optimize import least_squares

    tangent_u = np.cross(centre, [0.0, 1.0, 0.0])
    tangent_u /= np.linalg.norm(tangent_u)
    tangent_v = np.cross(tangent_u, centre)

    def direction(p):
        c = centre + p[0] * tangent_u + p[1] * tangent_v
        return c / np.linalg.norm(c)

    def residual(p):
        return np.arccos(np.clip(points @ direction(p), -1.0, 1.0)) - p[2]

    start = np.array([0.0, 0.0, float(np.mean(np.arccos(np.clip(points @ centre, -1.0, 1.0))))])
    fit = least_squares(residual, start, x_scale=1e-3)
    return direction(fit.x), float(fit.x[2])


def measure(stage: str, exr: str, angles_deg: np.ndarray) -> dict:
    """Edge residuals of the frame ``exr`` rendered from ``stage`` (see the module docstring)."""
    from label_halos import on_circle, pixel
    from scipy.ndimage import map_coordinates

    from warpsky.output.exr import read_exr
    from warpsky.usd.stage import StageReader

    image = read_exr(exr)
    rgb = np.stack([image.channels[c].astype(np.float64) for c in "RGB"], axis=-1)
    luminance = rgb @ LUMINANCE
    scene = StageReader(stage).scene_at(None)
    camera = scene.camera.conformed(image.width, image.height)
    sun = np.asarray(scene.sun.direction, dtype=np.float64)
    start, stop, step = SEARCH_DEG
    distances = np.arange(start, stop + 0.5 * step, step)
    points, scales, used = [], [], []
    for angle in angles_deg:
        dirs = [on_circle(sun, math.radians(d), math.radians(angle)) for d in distances]
        at = [pixel(camera, image.width, image.height, d) for d in dirs]
        if any(p is None or not (1 <= p[0] < image.width - 1 and 1 <= p[1] < image.height - 1) for p in at):
            continue
        xy = np.array(at) - 0.5  # pixel centres sit at half-integers
        profile = map_coordinates(luminance, [xy[:, 1], xy[:, 0]], order=1)
        edge = start + edge_distance(profile, step)
        k = int(round((edge - start) / step))
        points.append(on_circle(sun, math.radians(edge), math.radians(angle)))
        scales.append(np.hypot(*(xy[min(k + 1, len(xy) - 1)] - xy[max(k - 1, 0)])) / math.radians(2.0 * step))
        used.append(float(angle))
    if len(points) < 4:
        raise SystemExit(f"only {len(points)} rays of the halo lie inside the frame")
    points = np.array(points)
    centre, radius = fit_small_circle(points, sun)
    residual_px = (np.arccos(np.clip(points @ centre, -1.0, 1.0)) - radius) * np.array(scales)
    return {"exr": str(exr), "rays": len(points), "radius_deg": math.degrees(radius),
            "centre_from_sun_deg": math.degrees(math.acos(min(1.0, float(centre @ sun)))),
            "pixels_per_deg": float(np.mean(scales)) * math.pi / 180.0,
            "rms_px": float(np.sqrt(np.mean(residual_px**2))), "max_px": float(np.max(np.abs(residual_px))),
            "ray_to_ray_max_px": float(np.max(np.abs(np.diff(residual_px)))) if len(points) > 1 else 0.0,
            "angles_deg": used, "residual_px": residual_px.round(3).tolist()}


def angle_list(text: str, spacing: float) -> np.ndarray:
    """Position angles [deg] from ``lo:hi``, every ``spacing``, on both sides of the sun."""
    lo, hi = (float(v) for v in text.split(":"))
    side = np.arange(lo, hi + 0.5 * spacing, spacing)
    return np.concatenate([-side[::-1], side])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("exr", nargs="?", default=str(ROOT / "out" / "sundogs" / "sundogs.0001.exr"))
    parser.add_argument("--stage", default=str(ROOT / "usd_scenes" / "sundogs.usda"))
    parser.add_argument("--angles", default="30:75", help="position angles lo:hi [deg] from above the sun")
    parser.add_argument("--spacing", type=float, default=0.25, help="between rays [deg of position angle]")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args(argv)
    result = measure(args.stage, args.exr, angle_list(args.angles, args.spacing))
    print(f"{'frame':<40} {'rays':>5} {'radius':>8} {'px/deg':>7} {'rms px':>7} {'max px':>7} {'ray-to-ray':>10}")
    print(f"{Path(result['exr']).name:<40} {result['rays']:>5} {result['radius_deg']:>7.3f}° "
          f"{result['pixels_per_deg']:>7.2f} {result['rms_px']:>7.2f} {result['max_px']:>7.2f} "
          f"{result['ray_to_ray_max_px']:>10.2f}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
