"""The :class:`ImageLayer`: what every technique and pass renders, ready to composite front to back, and the frame's
one channel for warnings (a layer's ``warnings`` reach the command line, the batch log and the EXR header)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ImageLayer:
    """One technique's image of what it renders, ready to composite front to back.

    Attributes:
        radiance: (H, W, 3) float32 radiance reaching the eye [sun irradiance units / sr].
        transmittance: (H, W, 3) float32 fraction of the light from behind the layer that passes through it
            (0 where an opaque surface such as the ground is hit).
        depth: (H, W) float32 representative camera-space depth along the view axis [m]: the opacity-weighted
            mean depth of what the layer shows; the camera's far clipping distance where it shows nothing.
        stats: Figures about the render (lookups, seconds, settings) for metadata and benchmarks.
        aovs: Extra per-pixel outputs by name, e.g. ``variance`` (H, W, 3) of a Monte Carlo pixel mean.
        warnings: One line each about what the render could not do as asked (a target error not reached, a camera
            under the terrain); the frame gathers them from every layer.
        parts: The layers a depth merge combined (per pixel in the order of their depths), for deep output; empty
            for a layer drawn as one.
        front: None, or light already attenuated on its way to the eye by everything it crossed (radiance and
            AOVs of paths traced through the fog, the terrain and the media in front of the event that scattered
            it): a depth merge and the composite add it in front of every layer they combine, unattenuated by
            them (its transmittance and depth are not used).
        profile: None, or the layer's extinction along each pixel's camera ray in bins
            (:class:`~warpsky.output.deep_bins.DepthProfile`), which deep output turns into that many volume
            samples; drawn only when a frame asks for deep output.
    """

    radiance: np.ndarray
    transmittance: np.ndarray
    depth: np.ndarray
    stats: dict = field(default_factory=dict)
    aovs: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    parts: list = field(default_factory=list)
    front: ImageLayer | None = None
    profile: object | None = None  # a DepthProfile (warpsky.output.deep_bins, above this module's layer)


def gathered_warnings(layers) -> list[str]:
    """Every warning of ``layers`` (and of the parts a merged layer was made of), once each, in order."""
    out: list[str] = []
    for layer in layers:
        for line in layer.warnings:
            if line not in out:
                out.append(line)
    return out
