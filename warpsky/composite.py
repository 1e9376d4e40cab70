"""Combine technique layers front to back into the frame that is written out."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warpsky.scene.model import LUMINANCE_WEIGHTS
from warpsky.techniques.base import Layer


@dataclass
class Frame:
    """Final pixels: linear scene-referred radiance with alpha, and the AOVs written next to it.

    Attributes:
        rgba: (H, W, 4) float32; alpha = 1 - luminance-weighted transmittance of everything in front of the
            background.
        transmittance: (H, W, 3) float32 transmittance to the background.
        depth: (H, W) float32 camera-space depth [m] of the front-most layer that shows something.
        aovs: Extra (H, W, 3) outputs of the layers by name (e.g. ``variance`` of a path-traced layer), seen
            through the layers in front like radiance (variances through the square of their transmittance).
    """

    rgba: np.ndarray
    transmittance: np.ndarray
    depth: np.ndarray
    aovs: dict = field(default_factory=dict)


def composite(layers: list[Layer], far: float) -> Frame:
    """Composite ``layers`` ordered front to back: each is seen through the transmittance of those before it."""
    if not layers:
        raise ValueError("composite needs at least one layer")
    height, width = layers[0].depth.shape
    radiance = np.zeros((height, width, 3), dtype=np.float32)
    transmittance = np.ones((height, width, 3), dtype=np.float32)
    depth = np.full((height, width), far, dtype=np.float32)
    aovs: dict[str, np.ndarray] = {}
    for layer in layers:
        for name, values in layer.aovs.items():
            weight = transmittance**2 if name == "variance" else transmittance
            aovs[name] = aovs.get(name, 0.0) + weight * values
        radiance += transmittance * layer.radiance
        unset = (depth >= far) & (layer.depth < far)
        depth[unset] = layer.depth[unset]
        transmittance *= layer.transmittance
    alpha = 1.0 - transmittance @ LUMINANCE_WEIGHTS.astype(np.float32)
    rgba = np.concatenate([radiance, np.clip(alpha, 0.0, 1.0)[..., None]], axis=-1).astype(np.float32)
    return Frame(rgba, transmittance, depth, {k: np.asarray(v, dtype=np.float32) for k, v in aovs.items()})
