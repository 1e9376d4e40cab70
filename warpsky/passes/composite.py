"""Combine technique layers front to back into the frame that is written out.

What lies behind everything (the dome, :mod:`warpsky.light.background`) comes here worked out; this module only
composites it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warpsky.core.image import ImageLayer, gathered_warnings
from warpsky.core.numerics import LUMINANCE_WEIGHTS


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


def composite(layers: list[ImageLayer], far: float) -> Frame:
    """Composite ``layers`` ordered front to back: each is seen through the transmittance of those before it."""
    if not layers:
        raise ValueError("composite needs at least one layer")
    height, width = layers[0].depth.shape
    radiance = np.zeros((height, width, 3), dtype=np.float32)
    transmittance = np.ones((height, width, 3), dtype=np.float32)
    depth = np.full((height, width), far, dtype=np.float32)
    aovs: dict[str, np.ndarray] = {}
    for layer in layers:
        if layer.front is not None:  # already seen through what lies in front: ahead of the layer itself
            radiance += transmittance * layer.front.radiance
            for name, values in layer.front.aovs.items():
                weight = transmittance**2 if name == "variance" else transmittance
                aovs[name] = aovs.get(name, 0.0) + weight * values
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


def merge_by_depth(layers: list[ImageLayer], far: float) -> ImageLayer:
    """One layer from several that overlap in the image (voxel media, stratiform layers): per pixel, the layers are
    composited front to back in the order of their representative depths (a layer showing nothing sits at ``far``).

    Exact where the layers do not interleave along the ray; where they do (a voxel cloud inside a stratiform
    layer's slab), the representative depths decide, as in Riley's split of the sky at the media's midplane.
    Stats: ``seconds`` and ``lookups`` add up; each input's stats are kept under ``parts``. A layer's ``front``
    light (already attenuated to the eye) is added unattenuated, as if in front of them all; the merged layer holds
    it in its radiance and AOVs.
    """
    if not layers:
        raise ValueError("merge_by_depth needs at least one layer")
    depths = np.stack([np.asarray(layer.depth, dtype=np.float32) for layer in layers])
    order = np.argsort(depths, axis=0, kind="stable")  # (N, H, W), front first; ties keep the given order
    radiance = np.stack([layer.radiance for layer in layers])
    trans = np.stack([layer.transmittance for layer in layers])
    names = sorted({name for layer in layers for name in layer.aovs}
                   | {name for layer in layers if layer.front is not None for name in layer.front.aovs})
    aov_stacks = {name: np.stack([layer.aovs.get(name, np.zeros_like(layer.radiance)) for layer in layers])
                  for name in names}
    height, width = depths.shape[1:]
    out_radiance = np.zeros((height, width, 3), np.float32)
    out_trans = np.ones((height, width, 3), np.float32)
    out_depth = np.full((height, width), far, np.float32)
    out_aovs = {name: np.zeros((height, width, 3), np.float32) for name in names}
    for front in (layer.front for layer in layers if layer.front is not None):
        out_radiance += front.radiance
        for name, values in front.aovs.items():
            out_aovs[name] = out_aovs.get(name, 0.0) + values
    for rank in range(len(layers)):
        index = order[rank]
        pick3 = index[None, ..., None]
        r = np.take_along_axis(radiance, pick3, axis=0)[0]
        t = np.take_along_axis(trans, pick3, axis=0)[0]
        d = np.take_along_axis(depths, index[None], axis=0)[0]
        for name in names:
            weight = out_trans**2 if name == "variance" else out_trans
            out_aovs[name] += weight * np.take_along_axis(aov_stacks[name], pick3, axis=0)[0]
        out_radiance += out_trans * r
        unset = (out_depth >= far) & (d < far)
        out_depth[unset] = d[unset]
        out_trans *= t
    stats = {
        "seconds": float(sum(layer.stats.get("seconds", 0.0) for layer in layers)),
        "lookups": int(sum(layer.stats.get("lookups", 0) for layer in layers)),
        "parts": [layer.stats for layer in layers],
    }
    return ImageLayer(out_radiance, out_trans, out_depth, stats, out_aovs, warnings=gathered_warnings(layers),
                      parts=list(layers))


def with_background(layers: list[ImageLayer], background: np.ndarray, far: float, *,
                    behind_air: bool = False) -> list[ImageLayer]:
    """``layers`` with ``background`` radiance behind them, as an opaque layer at ``far``; or, with ``behind_air``
    (a wrapping pass drew the air: its back layer, the last, is opaque), added to that back layer."""
    if behind_air:
        last = layers[-1]
        return [*layers[:-1], ImageLayer(last.radiance + background, last.transmittance, last.depth, last.stats,
                                         last.aovs, warnings=last.warnings)]
    height, width = background.shape[:2]
    return [*layers, ImageLayer(background, np.zeros_like(background), np.full((height, width), far, np.float32))]


def add_light(layers: list[ImageLayer], more: list[ImageLayer]) -> list[ImageLayer]:
    """Per layer, the radiance (and any variance AOV) of ``layers`` plus that of ``more``: the same passes lit by
    another light (transmittance and depth do not depend on the light and are kept)."""
    out = []
    for layer, extra in zip(layers, more, strict=True):
        aovs = {name: values + extra.aovs[name] if name in extra.aovs else values
                for name, values in layer.aovs.items()}
        stats = dict(layer.stats)
        if "seconds" in extra.stats:
            stats["seconds"] = float(stats.get("seconds", 0.0)) + float(extra.stats["seconds"])
        front = layer.front
        if extra.front is not None:
            front = extra.front if front is None else add_light([front], [extra.front])[0]
        out.append(ImageLayer(layer.radiance + extra.radiance, layer.transmittance, layer.depth, stats, aovs,
                              warnings=gathered_warnings([layer, extra]), front=front))
    return out
