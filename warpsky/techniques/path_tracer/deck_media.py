"""Height-field cloud decks (Max 1986) for the path tracer: the scene's deck and its haze are voxelised
(:func:`~warpsky.media.deck.deck_voxels.voxelize_deck`) at the scene's time over a square around the camera and traced
with the other media, the ground and the air, so the deck pass (single scattering) can be measured against
an unbiased reference of the same cloud.

Three path tracer settings, with these automatic values:

- ``deck_extent``: half-size [m] of the square. Auto: the farthest horizontal distance at which a ray of the frame
  (its border and centre pixels) enters the slab of the deck's band and haze, plus ln(100) / sigma, where sigma is
  the haze's smallest extinction (or, without haze, half the deck's smallest extinction: a grazing ray through a
  deck with gaps is about half in cloud); light from beyond the square is then dimmed below 1 % along such a ray.
  Capped at :data:`DECK_EXTENT_CAP`. What lies beyond is clear (the deck pass's deck and haze go on).
- ``deck_voxel_width``: horizontal voxel edge [m]. Auto: :func:`~warpsky.media.deck.deck_geometry.feature_length` / 8
  (the shortest wavelength, the equator's rounding c, the polynomial's curvature length).
- ``deck_voxel``: vertical voxel edge [m]. Auto: the band's height / :data:`DECK_VOXEL_ROWS`. Every column's optical
  depth is exact whatever the size (partial volume); the rows set where the tops and bases lie within a voxel.

When the automatic sizes make a grid over :data:`~warpsky.media.stratiform.stratiform_voxels.VOXEL_BUDGET` voxels
(under a time budget, over what :func:`voxel_budget` gives it) they grow together by the smallest factor that fits;
given sizes are kept, and a grid they make over the budget is refused with one line naming the settings. Each column
is split into :func:`supersample` ^ 2 sub-columns (4 x 4 when cheap, 1 under a time budget).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from warpsky.core.resources import MemoryEstimate
from warpsky.media.deck.deck_geometry import feature_length, the_deck
from warpsky.media.deck.deck_voxels import deck_grid, voxelize_deck
from warpsky.media.stratiform.stratiform_voxels import VOXEL_BUDGET, ColumnGrid
from warpsky.model.deck import CloudDeck
from warpsky.model.scene import Scene
from warpsky.techniques.path_tracer.majorants import AUTO_BLOCKS

#: Voxel rows over the deck's band when ``deck_voxel`` is auto.
DECK_VOXEL_ROWS = 32
#: Horizontal voxels per smallest feature when ``deck_voxel_width`` is auto.
DECK_VOXELS_PER_FEATURE = 8
#: Largest automatic ``deck_extent`` [m].
DECK_EXTENT_CAP = 50.0e3
#: Sub-column samples (columns x s^2) up to which the columns are split 4 x 4 (then 2 x 2, then 1).
SUPERSAMPLE_SAMPLES = 2**25
#: Seconds per voxel of the voxelised deck before the first path, on 2 CPU cores: the voxelisation's kernel (1 x 1
#: sub-columns: 23-42 ns a voxel at load 3 on the sunbeams' deck under budgets of 5 and 1 s), the majorants, the
#: upload's copy and its checksum (the three 23 ns a voxel at load 4 on its 133.8 million voxels).
VOXEL_SECONDS = 4.0e-8
#: The share of a frame's time budget the voxelised deck may take before the first path.
VOXEL_BUDGET_SHARE = 0.15
#: Settings names, for messages.
SETTINGS = "deck_extent / deck_voxel_width / deck_voxel"


def traces_decks(technique_cls) -> bool:
    """Whether ``technique_cls`` traces height-field cloud decks itself, as voxel media (instead of next to the
    deck pass)."""
    return bool(getattr(technique_cls, "traces_decks", False))


def frame_directions(scene: Scene, width: int, height: int, samples: int = 16) -> np.ndarray:
    """(N, 3) world directions of the frame's border pixels (``samples`` per edge) and its centre."""
    camera = scene.camera.conformed(width, height)
    t = np.linspace(0.0, 1.0, samples)
    points = [(width * a, 0.0) for a in t] + [(width * a, float(height)) for a in t]
    points += [(0.0, height * a) for a in t] + [(float(width), height * a) for a in t]
    points.append((0.5 * width, 0.5 * height))
    return np.array([camera.pixel_direction(x, y, width, height) for x, y in points])


def automatic_extent(scene: Scene, clouds: CloudDeck, width: int, height: int) -> float:
    """Half-size [m] of the voxelised square when ``deck_extent`` is auto (module docstring)."""
    low, high = clouds.band
    if clouds.haze is not None:
        low, high = min(low, clouds.haze.floor), max(high, clouds.haze_top)
    eye = float(scene.camera.position[1])
    enter = 0.0
    for d in frame_directions(scene, width, height):
        across = math.hypot(d[0], d[2])
        if low <= eye <= high:
            continue
        rise = (low - eye) if eye < low else (eye - high)
        dy = d[1] if eye < low else -d[1]
        if dy > 0.0:
            enter = max(enter, rise / dy * across)
    if clouds.haze is not None and float(np.min(clouds.haze.density)) > 0.0:
        sigma = float(np.min(clouds.haze.density))
    else:
        sigma = 0.5 * float(np.min(clouds.extinction))
    reach = math.log(100.0) / sigma if sigma > 0.0 else math.inf
    return float(min(enter + reach, DECK_EXTENT_CAP))


def deck_voxel_sizes(scene: Scene, clouds: CloudDeck, settings, width: int, height: int, *,
                     budget: int = VOXEL_BUDGET) -> tuple[float, float, float]:
    """(half-size of the square, horizontal edge, vertical edge) [m] under the path tracer ``settings``: given
    values as they are, automatic ones from the deck and the frame, the automatic edges grown together until the
    grid fits ``budget`` voxels."""
    extent = settings.deck_extent if settings.deck_extent is not None else automatic_extent(scene, clouds, width,
                                                                                            height)
    low, high = clouds.band
    band = max(high - low, 1e-3)
    given_width, given_height = settings.deck_voxel_width, settings.deck_voxel
    across = given_width if given_width is not None else feature_length(clouds) / DECK_VOXELS_PER_FEATURE
    rows = given_height if given_height is not None else band / DECK_VOXEL_ROWS
    free = int(given_width is None) * 2 + int(given_height is None)

    def voxels(scale: float) -> int:
        w = across * (scale if given_width is None else 1.0)
        h = rows * (scale if given_height is None else 1.0)
        return max(1, math.ceil(2.0 * extent / w - 1e-9)) ** 2 * max(1, math.ceil(band / h - 1e-9))

    scale = 1.0
    if free and voxels(1.0) > budget:
        scale = (voxels(1.0) / budget) ** (1.0 / free)
        while voxels(scale) > budget:  # whole-voxel rounding: a few percent more at most
            scale *= 1.01
    return (float(extent), across * (scale if given_width is None else 1.0),
            rows * (scale if given_height is None else 1.0))


def voxel_budget(time_budget: float | None) -> int:
    """Most voxels of the automatic grid: :data:`~warpsky.media.stratiform.stratiform_voxels.VOXEL_BUDGET`, or under
    a frame's ``time_budget`` [s] what :data:`VOXEL_BUDGET_SHARE` of it voxelises at :data:`VOXEL_SECONDS` a voxel
    (given voxel sizes are kept whatever the time)."""
    if time_budget is None:
        return VOXEL_BUDGET
    return int(min(VOXEL_BUDGET, max(2**16, VOXEL_BUDGET_SHARE * float(time_budget) / VOXEL_SECONDS)))


def supersample(grid: ColumnGrid, time_budget: float | None = None) -> int:
    """Sub-columns per column along each axis: 4 while the grid's sub-column samples stay within
    :data:`SUPERSAMPLE_SAMPLES`, else 2, else 1; 1 under a time budget (2 x 2 took 3.6 times as long to voxelise
    as 1 on the sunbeams' deck under a 1 s budget: 0.57 against 0.16 s)."""
    if time_budget is not None:
        return 1
    for s in (4, 2):
        if grid.voxels * s * s <= SUPERSAMPLE_SAMPLES:
            return s
    return 1


def deck_plan(scene: Scene, settings, width: int, height: int, *, time_budget: float | None = None
              ) -> tuple[CloudDeck, ColumnGrid, int] | None:
    """(deck, grid, sub-columns per axis) of the scene's deck as the path tracer voxelises it (None without a
    deck) for a frame of ``time_budget`` [s] (None: none); a grid over the budget is refused (UsageError naming the
    settings)."""
    clouds = the_deck(scene)
    if clouds is None:
        return None
    extent, across, rows = deck_voxel_sizes(scene, clouds, settings, width, height, budget=voxel_budget(time_budget))
    grid = deck_grid(clouds, scene.camera.position[[0, 2]], extent, across, rows, setting=SETTINGS)
    return clouds, grid, supersample(grid, time_budget)


def with_deck_as_media(scene: Scene, settings, width: int, height: int, *, time_budget: float | None = None,
                       device: str = "cpu") -> Scene:
    """``scene`` with its deck (and haze) voxelised on ``device`` at the scene's time and appended to its media (no
    decks left); ``scene`` itself when it has none. ``time_budget``: the frame's [s], which caps the voxels."""
    planned = deck_plan(scene, settings, width, height, time_budget=time_budget)
    if planned is None:
        return scene
    clouds, grid, s = planned
    media = voxelize_deck(clouds, scene.time_s, scene.camera.position[[0, 2]], 0.5 * grid.width[0] * grid.shape[0],
                          grid.width[0], grid.height, supersample=s, setting=SETTINGS, device=device)
    return dataclasses.replace(scene, media=scene.media + media, decks=())


def deck_voxel_memory(scene: Scene, settings, width: int, height: int, *, time_budget: float | None = None
                      ) -> MemoryEstimate:
    """Bytes of the voxelised deck: on the host the float32 grid (written in place by the voxelisation's kernel)
    and the upload's concatenated copy of it; on the device the grid and its majorants. On the
    sunbeams' deck of 133.8 million voxels (510 MiB) the render's peak was 1.50 GiB above the process before the
    deck, with the grid, its concatenated copy and its upload held at once."""
    estimate = MemoryEstimate()
    planned = deck_plan(scene, settings, width, height, time_budget=time_budget)
    if planned is not None:
        voxels = planned[1].voxels
        block = max(1, int(settings.majorant_block or AUTO_BLOCKS[0]))
        estimate.add("deck voxels", host=8 * voxels,
                     device=4 * voxels + 4 * voxels / block**3 + 8)
    return estimate


def deck_voxel_features(scene: Scene, settings, width: int, height: int, features: dict[str, str]) -> dict[str, str]:
    """``warpsky info``'s lines for a technique that traces the deck: ``features`` with the height-field and media
    lines saying how the deck is voxelised (square, sizes, grid, voxels) instead of what the deck pass
    would do."""
    planned = deck_plan(scene, settings, width, height)
    if planned is None:
        return features
    clouds, grid, s = planned
    auto = [name for name in ("deck_extent", "deck_voxel_width", "deck_voxel") if getattr(settings, name) is None]
    how = f" ({', '.join(auto)} auto)" if auto else ""
    haze = ", haze as a homogeneous box over the same square" if clouds.haze is not None else ""
    line = (f"{clouds.name}: Max 1986 deck voxelised for the path tracer at t = {scene.time_s:g} s over a square of "
            f"half-size {0.5 * grid.width[0] * grid.shape[0]:.4g} m around the camera: {grid.width[0]:.4g} x "
            f"{grid.width[1]:.4g} x {grid.height:.4g} m voxels{how}, {grid.shape[0]}x{grid.shape[1]}x{grid.shape[2]} = "
            f"{grid.voxels:,} ({grid.voxels * 4 / 2**20:.1f} MiB), partial volume ({s}x{s} sub-columns), density "
            f"{clouds.density:g} 1/m{haze}; no deck pass (multiple scattering traced)")
    out = dict(features)
    out["deck"] = line
    media = features.get("media", "none")
    out["media"] = (media if scene.media else "none") + f"; plus the voxelised deck{' and haze' if haze else ''}"
    if scene.ground is not None and "ground" in features:
        out["ground"] = features["ground"].split("; drawn by the surfaces pass")[0] + "; traced with the voxelised deck"
    return out
