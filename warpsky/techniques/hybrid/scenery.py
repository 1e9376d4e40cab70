"""The hybrid technique's paths through the scenery: analytic fog, height-field cloud decks with their haze and
triangle meshes (terrain), whose single scattering other passes draw.

Who counts what, so that no light counts twice:

* the fog pass: the fog's single scattering of the sun (Biri 2002's closed form), without its ambient term;
* the deck pass: the deck's and the haze's single scattering of the sun (Max 1986), without its ambient
  term;
* the surfaces pass: the meshes' (and a ground plane's, where it draws it) direct sunlight, without its sky term;
* the paths (:class:`~warpsky.techniques.path_tracer.path_tracer.PathTracing` with ``meshes`` and ``fog``, the
  camera's opaque depth dropped so that they start on the meshes themselves, the deck and its haze voxelised over a
  square around the camera as the path tracer traces them, :mod:`~warpsky.techniques.path_tracer.deck_media`):
  everything else, the stratiform layers' light on the scenery included (the layers voxelised as the path tracer
  traces them, :mod:`~warpsky.techniques.path_tracer.stratiform_media`: a camera ray whose first event lies in a layer's
  altitude band ends there, since the stratiform pass draws the layers; the ground, in their shadow, is then the
  surfaces pass's, its light from the layers the paths'). Their first event, in the fog, the deck, the media or on a
  surface, takes no sunlight (``multiple_only``, as for the voxel media and the ground), then the path gathers the
  sun at its later events and the sky's and the dome's light wherever it goes: that is the light the fog's and the
  deck's ambient terms and the surfaces' sky term approximated (isotropic, unshadowed or shadowed straight above
  only, no light between faces), now traced with the terrain's occlusion, so those terms are left out. A path whose
  first event is the air's ends there (``air_by_table``: the sky pass's tables hold the air's own light). Beyond the
  deck's square the paths see clear air: there the deck keeps its single scattering only (the square's automatic
  size dims the light from beyond it below 1 % along the frame's rays).

The paths' radiance is already attenuated on its way to the eye (the fog's closed-form transmittance, the media and
the air are tracked along the camera ray), so it is not composited by depth behind the fog's or the terrain's layer:
it is the layer's ``front`` light (:class:`~warpsky.core.image.ImageLayer`), added unattenuated in front of the
depth-merged layers and, with air, in front of the sky pass's front air (:func:`~warpsky.passes.frame.render_layers`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from warpsky.core.image import ImageLayer
from warpsky.model.scene import Scene
from warpsky.passes.deck.deck import Deck
from warpsky.passes.fog.fog import Fog
from warpsky.passes.media import SceneryFrame
from warpsky.techniques.path_tracer.deck_media import deck_plan, with_deck_as_media
from warpsky.techniques.path_tracer.path_tracer import PathTracerSettings
from warpsky.techniques.path_tracer.stratiform_media import with_stratiform_as_media


def paths_scene(scene: Scene, around: SceneryFrame, settings, width: int, height: int,
                device: str = "cpu", *, time_budget: float | None = None) -> tuple[Scene, tuple[float, float] | None]:
    """(the scene the paths trace, the altitude band [m] where a camera ray's first event ends its path or None):
    ``scene`` with ``around.ground`` as its ground plane where another pass draws it, no opaque depth on the camera
    (the surfaces pass's meshes and ground, which the paths trace themselves), its height-field deck voxelised into
    its media (``settings``: the path tracer's, for the deck's square and voxels;
    :func:`~warpsky.techniques.path_tracer.deck_media.with_deck_as_media`; ``time_budget``, the frame's, caps its
    voxels) and ``around.stratiform_layers``, the
    stratiform layers another pass draws, voxelised into them too; their band is the one returned."""
    ground = scene.ground if scene.ground is not None else around.ground
    camera = dataclasses.replace(scene.camera, opaque_depth=None)
    traced = dataclasses.replace(scene, ground=ground, camera=camera)
    band = None
    if around.stratiform_layers:
        layered = with_stratiform_as_media(
            dataclasses.replace(traced, stratiform_layers=tuple(around.stratiform_layers)), settings, device)
        added = layered.media[len(traced.media):]
        if added:
            heights = np.concatenate([m.world_corners()[:, 1] for m in added])
            band = (float(heights.min()), float(heights.max()))
        traced = layered
    return with_deck_as_media(traced, settings, width, height, time_budget=time_budget, device=device), band


def scenery_guide(scene: Scene, single: ImageLayer, device: str, around: SceneryFrame) -> ImageLayer:
    """The single-scattering layer as the paths' error estimate and denoiser read it: its transmittance times the
    fogs' (closed form, to the opaque depth; :class:`~warpsky.passes.fog.fog.Fog`) and the deck's and haze's
    (:class:`~warpsky.passes.deck.deck.Deck` without light), zero where the camera ray ends
    on an opaque surface another pass drew (the camera's opaque depth). Its radiance, the level the error estimate
    divides by, adds the light the passes draw beside the paths: the fog's single scattering of the sun as the fog
    pass draws it (in the meshes' and the layers' shadows; its ambient term is the paths') and ``around.drawn``,
    the radiance of the surfaces behind the fog (the passes before the media pass), seen through it; not the
    deck's (left out, as before the deck pass's layer was at hand here: the estimate stays conservative
    there) nor the stratiform layers'. In a frame of passes the fog's and the deck's layers are the passes' own
    (``around.fog``, ``around.deck``, drawn once and kept for their turn); outside one they are drawn here."""
    height, width = single.depth.shape
    opaque = scene.camera.opaque_depth
    depth = None
    if opaque is not None:
        depth = np.asarray(opaque.numpy() if hasattr(opaque, "numpy") else opaque, dtype=np.float32)
    transmittance = single.transmittance
    radiance = single.radiance
    dark = dataclasses.replace(scene, sun=None, extra_suns=(), dome=None)
    through = np.ones_like(transmittance)
    if scene.fogs:
        fog = around.fog
        if fog is None:  # outside a frame of passes: drawn here as the fog pass would
            lit = dataclasses.replace(scene, extra_suns=(), dome=None,
                                      stratiform_layers=tuple(scene.stratiform_layers or around.stratiform_layers))
            fog = Fog(device=device).render(lit, width, height, limit=depth, ambient=np.zeros(3),
                                            occluders=around.occluders)
        transmittance = transmittance * fog.transmittance
        radiance = radiance + fog.radiance
        through = fog.transmittance
    if scene.decks:
        deck = around.deck
        if deck is None:  # outside a frame of passes: its transmittance alone, without light
            deck = Deck(device=device).render(dark, width, height, limit=depth, ambient=np.zeros(3))
        transmittance = transmittance * deck.transmittance
    if around.drawn is not None:
        radiance = radiance + through * np.asarray(around.drawn, dtype=np.float32)
    if depth is not None:
        transmittance = np.where((depth < scene.camera.far)[..., None], 0.0, transmittance)
    return ImageLayer(radiance.astype(np.float32), transmittance.astype(np.float32), single.depth, single.stats)


def deck_paths_features(scene: Scene, settings: PathTracerSettings, width: int, height: int,
                        features: dict[str, str], time_budget: float | None = None) -> dict[str, str]:
    """``features`` with the height-field line saying that the paths trace the deck voxelised (square, voxels)
    beside the deck pass's single scattering (in a frame of ``time_budget`` seconds, which caps the voxels)."""
    clouds, grid, sub = deck_plan(scene, settings, width, height, time_budget=time_budget)
    line = (f"; multiple scattering path traced by hybrid through the deck{' and haze' if clouds.haze else ''} "
            f"voxelised over a square of half-size {0.5 * grid.width[0] * grid.shape[0]:.4g} m around the camera "
            f"({grid.shape[0]}x{grid.shape[1]}x{grid.shape[2]} = {grid.voxels:,} voxels, {sub}x{sub} sub-columns); "
            "the pass's ambient term left to the paths")
    out = dict(features)
    out["deck"] = features.get("deck", clouds.name) + line
    return out
