"""Decide what a frame needs before anything runs: technique, settings, device, resolution, features.

This is where "leave out what a scene does not need" lives, and what ``warpsky info`` prints.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

import numpy as np

from warpsky.errors import UsageError
from warpsky.scene.model import Scene
from warpsky.techniques.base import DEFAULT_TECHNIQUE, parse_settings, technique_class

DEFAULT_WIDTH = 512


@dataclass
class RenderPlan:
    """What will run for one frame, fully resolved."""

    technique: str
    settings: object
    device: str
    width: int
    height: int
    features: dict[str, str] = field(default_factory=dict)

    def settings_dict(self) -> dict:
        return dataclasses.asdict(self.settings)

    def settings_json(self) -> str:
        return json.dumps({"technique": self.technique, **self.settings_dict()}, sort_keys=True)

    def describe(self) -> str:
        lines = [
            f"technique   {self.technique}",
            f"device      {self.device}",
            f"resolution  {self.width} x {self.height}",
            "settings    " + ", ".join(f"{k}={_fmt(v)}" for k, v in self.settings_dict().items()),
        ]
        lines += [f"{name:<11} {state}" for name, state in self.features.items()]
        return "\n".join(lines)


def _fmt(value) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def resolve_resolution(scene: Scene, resolution: tuple[int, int | None] | None) -> tuple[int, int]:
    """Image size: ``--res``, else the stage's render settings, else 512 wide at the camera's aspect ratio."""
    camera = scene.camera
    aspect = camera.horizontal_aperture / camera.vertical_aperture
    if resolution is None:
        resolution = scene.resolution or (DEFAULT_WIDTH, None)
    width, height = resolution
    if height is None:
        height = max(1, round(width / aspect))
    if width <= 0 or height <= 0:
        raise UsageError(f"resolution must be positive, got {width}x{height}")
    return int(width), int(height)


def make_plan(
    scene: Scene,
    *,
    technique: str = DEFAULT_TECHNIQUE,
    settings: dict[str, str] | None = None,
    resolution: tuple[int, int | None] | None = None,
    device: str = "cpu",
) -> RenderPlan:
    cls = technique_class(technique)
    instance = cls(parse_settings(cls.Settings, settings), device=device)
    width, height = resolve_resolution(scene, resolution)
    features = {}
    if scene.sun is None:
        features["sun"] = "none (no visible DistantLight): media render black, transmittance only"
    else:
        sun = scene.sun
        features["sun"] = (
            f"{sun.name}: elevation {np.degrees(sun.elevation):.2f} deg, "
            f"irradiance {np.round(sun.irradiance, 4).tolist()}"
        )
    if scene.media:
        voxels = sum(int(np.prod(m.shape)) for m in scene.media)
        features["media"] = f"{len(scene.media)} voxel grid(s), {voxels:,} voxels, {voxels * 4 / 2**20:.1f} MiB"
    else:
        features["media"] = "none"
    species = tuple(dict.fromkeys(m.species for m in scene.media if m.species is not None))
    if species:
        from warpsky.optics.tables import is_cached

        states = [f"{name} ({'cached' if is_cached(name) else 'to build'})" for name in species]
        features["optics"] = "phase tables for " + ", ".join(states)
    else:
        features["optics"] = "analytic phase only: no species fields, no tables built"
    if scene.atmosphere is not None:
        atm = scene.atmosphere
        night = scene.sun is None or scene.sun.direction[1] <= 0.0
        features["sky"] = (
            f"{atm.name}: analytic Riley single-scattering sky, aerial perspective and sun disk; betaSeaLevel "
            f"{np.round(atm.beta_sea_level * 1e6, 3).tolist()} /Mm, scale height {atm.scale_height:g} m, altitude "
            f"{atm.altitude:g} m" + ("; sun below the horizon: night (black sky)" if night else "")
        )
    else:
        features["sky"] = "off (no warpsky:atmosphere prim): black background, no sky pass"
    features["ground"] = (
        f"{scene.ground.name} at y = {scene.ground.height:g} m, albedo {np.round(scene.ground.albedo, 3).tolist()}"
        if scene.ground is not None
        else "off (no Plane prim): kernel built without the ground branch"
    )
    return RenderPlan(technique, instance.resolved_settings(scene), device, width, height, features)
