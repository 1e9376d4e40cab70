"""Stratiform layers for the path tracer: each layer (Bouthors 2006) is voxelised
(:func:`~warpsky.media.stratiform.stratiform_voxels.voxelize_layer`) and traced with the other media, the ground and the
air, so the stratiform pass can be measured against an unbiased reference of the same cloud.

Voxel sizes come from two path tracer settings, ``layer_voxel`` (vertical edge) and ``layer_voxel_width``
(horizontal edge). Their automatic values, per layer:

- ``layer_voxel``: the layer's largest thickness / :data:`LAYER_VOXEL_ROWS`. Every column's optical depth is
  exact whatever the size (partial volume); the rows set where the top lies within its last voxel.
- ``layer_voxel_width``: half a texel of the thickness map, so the voxel columns follow the bilinear map and its
  hole edges (which run halfway between texel centres) within a quarter texel.

When the grid of those sizes exceeds :data:`~warpsky.media.stratiform.stratiform_voxels.VOXEL_BUDGET` voxels, the
automatic sizes grow together by the smallest factor that fits; given sizes are kept, and a grid they make over the
budget is refused. What the path tracer leaves out next to the stratiform pass: the ground's albedo map (the traced
ground is the plane's uniform albedo).
"""

from __future__ import annotations

import dataclasses
import math

from warpsky.core.resources import MemoryEstimate
from warpsky.media.stratiform.stratiform_voxels import LAYER_SPECIES, VOXEL_BUDGET, layer_grid, voxelize_layer
from warpsky.model.scene import Scene
from warpsky.model.stratiform import StratiformLayer
from warpsky.optics.tables import is_cached
from warpsky.techniques.path_tracer.majorants import AUTO_BLOCKS

#: Voxel rows over a layer's largest thickness when ``layer_voxel`` is auto. On a broken 100 m deck (map texels
#: 125 m, 16 x 16 pixels) halving both automatic edges changed the mean radiance of the cloudy pixels by
#: +2.3 % +- 2.3 % seen from above (4e6 paths per render) and -0.2 % +- 1.1 % from the ground (2e6 paths);
#: quartering them, by +1.6 % +- 2.3 % from above, doubling them by +7.5 % +- 2.3 %. The test pins the view from
#: the ground to 5 %.
LAYER_VOXEL_ROWS = 32

#: Settings names, for messages.
SETTINGS = "layer_voxel / layer_voxel_width"


def traces_layers(technique_cls) -> bool:
    """Whether ``technique_cls`` traces stratiform layers itself, as voxel media (instead of next to the
    stratiform pass)."""
    return bool(getattr(technique_cls, "traces_layers", False))


def texel_width(layer: StratiformLayer) -> float:
    """The smaller edge [m] of one texel of the layer's thickness map."""
    return min(s / n for s, n in zip(layer.size, layer.thickness.shape, strict=True))


def layer_voxel_sizes(layer: StratiformLayer, settings, *, budget: int = VOXEL_BUDGET) -> tuple[float, float]:
    """(horizontal, vertical) voxel edges [m] for ``layer`` under the path tracer ``settings``: given values as
    they are, automatic ones from the map (see the module docstring), grown together until the grid fits
    ``budget`` voxels."""
    given_width, given_height = settings.layer_voxel_width, settings.layer_voxel
    top = float(layer.thickness.max())
    width = given_width if given_width is not None else 0.5 * texel_width(layer)
    height = given_height if given_height is not None else max(top, 1e-3) / LAYER_VOXEL_ROWS
    free = int(given_width is None) * 2 + int(given_height is None)  # how many grid axes a common factor scales

    def voxels(scale: float) -> int:
        w = width * (scale if given_width is None else 1.0)
        h = height * (scale if given_height is None else 1.0)
        return (math.prod(max(1, math.ceil(s / w - 1e-9)) for s in layer.size)
                * max(1, math.ceil(top / h - 1e-9)))

    scale = 1.0
    if free and voxels(1.0) > budget:
        scale = (voxels(1.0) / budget) ** (1.0 / free)
        while voxels(scale) > budget:  # whole-voxel rounding: a few percent more at most
            scale *= 1.01
    return (width * (scale if given_width is None else 1.0), height * (scale if given_height is None else 1.0))


def voxelised_layers(scene: Scene, settings, device: str) -> tuple:
    """The scene's stratiform layers with any cloud, each as a voxel medium at its time (:attr:`time_s`)."""
    media = []
    for layer in scene.stratiform_layers:
        if float(layer.thickness.max()) <= 0.0:
            continue
        width, height = layer_voxel_sizes(layer, settings)
        media.append(voxelize_layer(layer, layer.time_s, width, vertical=height, setting=SETTINGS, device=device))
    return tuple(media)


def with_stratiform_as_media(scene: Scene, settings, device: str) -> Scene:
    """``scene`` with its stratiform layers voxelised and appended to its media (no layers left); ``scene`` itself
    when it has none."""
    if not scene.stratiform_layers:
        return scene
    return dataclasses.replace(scene, media=scene.media + voxelised_layers(scene, settings, device),
                               stratiform_layers=())


def layer_voxel_memory(scene: Scene, settings) -> MemoryEstimate:
    """Bytes of the scene's voxelised layers: on the host the float64 fractions and the float32 grid while it is
    built and its majorant copy; on the device the grid and its majorants."""
    estimate = MemoryEstimate()
    for layer in scene.stratiform_layers:
        width, height = layer_voxel_sizes(layer, settings)
        voxels = layer_grid(layer, width, vertical=height, max_voxels=2**62).voxels
        block = max(1, int(settings.majorant_block or AUTO_BLOCKS[0]))
        estimate.add("layer voxels", host=16 * voxels, device=4 * voxels + 4 * voxels / block**3 + 4)
    return estimate


def stratiform_voxel_features(scene: Scene, settings, features: dict[str, str]) -> dict[str, str]:
    """``warpsky info``'s lines for a technique that traces the layers: ``features`` with the media, layers and
    ground lines saying how each layer is voxelised (sizes, grid, voxels) instead of what the stratiform pass
    would build."""
    lines = {}
    count = len(scene.stratiform_layers)
    for number, layer in enumerate(scene.stratiform_layers, start=1):
        key = "layer" if count == 1 else f"layer {number}"
        if float(layer.thickness.max()) <= 0.0:
            lines[key] = f"{layer.name}: no cloud (thickness 0 everywhere): nothing to trace"
            continue
        width, height = layer_voxel_sizes(layer, settings)
        grid = layer_grid(layer, width, vertical=height, max_voxels=2**62)
        auto = [name for name, value in (("layer_voxel_width", settings.layer_voxel_width),
                                         ("layer_voxel", settings.layer_voxel)) if value is None]
        how = f" ({', '.join(auto)} auto)" if auto else ""
        advected = f", map advected to t = {layer.time_s:g} s" if layer.advection is not None else ""
        lines[key] = (f"{layer.name}: stratiform (Bouthors 2006) voxelised for the path tracer: "
                      f"{grid.width[0]:.4g} x {grid.width[1]:.4g} x {grid.height:.4g} m voxels{how}, "
                      f"{grid.shape[0]}x{grid.shape[1]}x{grid.shape[2]} = {grid.voxels:,} "
                      f"({grid.voxels * 4 / 2**20:.1f} MiB), partial volume (exact column optical depth), kappa "
                      f"{layer.extinction:.4g} 1/m, stratus phase table{advected}; no stratiform pass, no radiosity "
                      "model (the ground bounce is traced)")
    out = {}
    for name, line in features.items():
        if name == "layers":
            out.update(lines)
        elif name == "media":
            out[name] = (line if scene.media else "none") + f"; plus {count} voxelised stratiform layer(s)"
        elif name == "optics" and LAYER_SPECIES not in scene.species:
            state = f"{LAYER_SPECIES} ({'cached' if is_cached(LAYER_SPECIES) else 'to build'}) for the layers"
            out[name] = (line + ", " + state) if line.startswith("phase tables") else "phase tables for " + state
        elif name == "ground" and scene.ground is not None:
            head = line.split("; drawn by the stratiform pass")[0]
            out[name] = head + "; traced with the voxelised layers"
            if scene.ground.albedo_map is not None:
                out[name] += " at its uniform albedo (the albedo map is not traced)"
        else:
            out[name] = line
    return out
