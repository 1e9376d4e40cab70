"""Label the halos of a rendered ice-crystal frame where the closed forms put them.

Every label sits at the direction its closed form gives for the stage's sun, projected through the stage's camera,
so the labelled picture is also a check that the renderer put each arc where the optics says (n: ice's index at
550 nm, e: the sun's elevation):

=========================== ===================================================================================
arc                         direction
=========================== ===================================================================================
parhelia (sundogs)          elevation e, azimuth +-da from the sun, da = 2 asin(n' / 2) - 60°, Bravais' index
                            n' = sqrt(n^2 - sin^2 e) / cos e (plates)
22° halo                    22° from the sun, at its minimum deviation 2 asin(n / 2) - 60° (random crystals);
                            labelled up and to the left of the sun
upper tangent arc           directly above the sun, at that minimum deviation (horizontal columns)
circumzenithal arc          the sun's azimuth, elevation asin(sqrt(n^2 - cos^2 e)) (plates; only for e < 32.2°)
46° halo                    46° from the sun: minimum deviation through a 90° prism, 2 asin(n sin 45°) - 90°;
                            labelled above the sun
parhelic circle             elevation e, 40° left of the sun in azimuth (plates' outer reflections)
=========================== ===================================================================================

Run:  python tools/label_halos.py usd_scenes/sundogs.usda out/sundogs/sundogs.0001.png out/sundogs/labelled.png
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def direction(elevation: float, azimuth: float, sun_azimuth: float) -> np.ndarray:
    """World unit vector (Y up) at ``elevation`` [rad] and ``azimuth`` [rad] from the sun's azimuth."""
    a = sun_azimuth + azimuth
    return np.array([math.cos(elevation) * math.sin(a), math.sin(elevation), -math.cos(elevation) * math.cos(a)])


def rotated_towards(sun: np.ndarray, angle: float, up: bool) -> np.ndarray:
    """The direction ``angle`` [rad] from ``sun`` in its vertical plane, above (``up``) or below it."""
    elevation = math.asin(float(sun[1])) + (angle if up else -angle)
    horizontal = np.array([sun[0], 0.0, sun[2]]) / max(math.hypot(sun[0], sun[2]), 1e-12)
    return horizontal * math.cos(elevation) + np.array([0.0, math.sin(elevation), 0.0])


def on_circle(sun: np.ndarray, radius: float, position_angle: float) -> np.ndarray:
    """The direction ``radius`` [rad] from ``sun`` at ``position_angle`` [rad] around it, from straight above
    the sun (0) towards the right (pi / 2)."""
    up = rotated_towards(sun, 0.5 * math.pi, up=True)
    left = np.cross(sun, up)
    return math.cos(radius) * sun + math.sin(radius) * (math.cos(position_angle) * up
                                                         + math.sin(position_angle) * left)


def arcs(sun: np.ndarray, n: float) -> list[tuple[str, np.ndarray]]:
    """(label, world direction) of each arc for a sun in direction ``sun`` (unit, towards the sun)."""
    e = math.asin(float(sun[1]))
    sun_azimuth = math.atan2(float(sun[0]), -float(sun[2]))
    halo22 = 2.0 * math.asin(n / 2.0) - math.radians(60.0)
    halo46 = 2.0 * math.asin(n * math.sin(math.radians(45.0))) - math.radians(90.0)
    out = [("sun", sun)]
    bravais = math.sqrt(n * n - math.sin(e) ** 2) / math.cos(e)
    if bravais < 2.0:
        da = 2.0 * math.asin(bravais / 2.0) - math.radians(60.0)
        out += [("parhelion", direction(e, -da, sun_azimuth)), ("parhelion", direction(e, da, sun_azimuth))]
    out += [("22° halo", on_circle(sun, halo22, math.radians(-50.0))),
            ("upper tangent arc", rotated_towards(sun, halo22, up=True)),
            ("46° halo", rotated_towards(sun, halo46, up=True)),
            ("parhelic circle", direction(e, math.radians(-40.0), sun_azimuth))]
    if n * n - math.cos(e) ** 2 < 1.0:
        out.append(("circumzenithal arc", direction(math.asin(math.sqrt(n * n - math.cos(e) ** 2)), 0.0,
                                                    sun_azimuth)))
    return out


def pixel(camera, width: int, height: int, world: np.ndarray) -> tuple[float, float] | None:
    """Image position [pixels] of a world direction seen from the (conformed) camera; None behind it."""
    local = camera.rotation.T @ world
    if local[2] >= 0.0:
        return None
    x = (local[0] / -local[2] * camera.focal_length - camera.horizontal_aperture_offset) / camera.horizontal_aperture
    y = (local[1] / -local[2] * camera.focal_length - camera.vertical_aperture_offset) / camera.vertical_aperture
    return (x + 0.5) * width, (0.5 - y) * height


def main(argv: list[str] | None = None) -> int:
    from PIL import Image, ImageDraw, ImageFont

    from warpsky.optics.ice import ice_refractive_index
    from warpsky.usd.stage import StageReader

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stage", help="the rendered USD stage")
    parser.add_argument("image", type=Path, help="its rendered PNG")
    parser.add_argument("out", type=Path, help="the labelled PNG to write")
    args = parser.parse_args(argv)
    scene = StageReader(args.stage).scene_at(None)
    image = Image.open(args.image).convert("RGB")
    width, height = image.size
    camera = scene.camera.conformed(width, height)
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default(size=max(11, width // 60))
    n = float(ice_refractive_index(550e-9))
    for label, world in arcs(np.asarray(scene.sun.direction, dtype=np.float64), n):
        at = pixel(camera, width, height, world)
        if at is None or not (0 <= at[0] < width and 0 <= at[1] < height):
            continue
        x, y = at
        r = max(3, width // 200)
        draw.ellipse((x - r, y - r, x + r, y + r), outline=(255, 255, 255))
        draw.line((x + r, y + r, x + 4 * r, y + 4 * r), fill=(255, 255, 255))
        draw.text((x + 4 * r + 2, y + 4 * r - 2), label, fill=(255, 255, 255), font=font)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    image.save(args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
