"""Host side of the height-field cloud pass (Max 1986): Max's clouds and the haze shafts below them, for any sun.

=================== ===== ============================= ========= =================================================
setting             unit  default                       range     meaning
=================== ===== ============================= ========= =================================================
``mode``            --    ``exact``                     enum      ``exact``: exp everywhere, the sunlight dimmed by
                                                                  the exact optical depth along the sun ray;
                                                                  ``max``: by Max's thickness rule (one pattern
                                                                  lookup per sample; see below where it fails);
                                                                  ``sexp``: Max's quadratic sexp in the cloud
                                                                  integral (vertical-sun model), to measure it
``step_length``     m     min(0.25 / sigma_max,         > 0       step inside the cloud
                          feature / 16)
``haze_step_length`` m    min(0.25 / sigma_haze,        > 0       step in clear haze (resolves the shafts);
                          shadow feature / 16), longer            authored: that step everywhere
                          along rays close to the sun
``haze_steps_per_   --    16                            1..1024   automatic haze step: steps per shortest feature of
feature``                                                         the deck's shadow
``shadow_map_texels`` --  2 / pixel angle               0..2048   texels per side of each level of the deck's
                                                                  shadow map on the haze; 0: the exact sun-ray
                                                                  optical depth at every haze step (below)
``max_steps``       --    4096                          >= 1      most steps per piece of constant extinction
``min_transmittance`` --  1e-4                          [0, 1)    stop once the view is this opaque
=================== ===== ============================= ========= =================================================

In clear haze below the deck the sunlight's optical depth through the deck is read from a per-frame shadow map
(:mod:`~warpsky.passes.deck.shadow_map`): one exact sun-ray depth per texel instead of one per march step, texels
about a pixel's footprint wide, the march's steps growing with them. On the sunbeams stage the pass went from 33 s
to 3.3 s at 96 x 64 and from 587 s to 35 s at 384 x 256 (2 CPU cores at load 3). Its difference from the per-step
march (4.6 % relative RMS at 96 x 64, +0.1 % bias) is a blur of shaft details finer than a pixel's footprint: against
the per-step march 4 x 4 supersampled per pixel both were 55.8 % off (the shafts and edges within a pixel).

``feature`` is :func:`~warpsky.media.deck.deck_geometry.feature_length` (the shortest wavelength, the equator's rounding
and the polynomial's curvature length). The measured quadrature error against a 4x finer march is in the tests.

Where ``max`` is not trustworthy: Max's thickness rule (:func:`~warpsky.passes.deck.deck_kernels.
deck_shadow_length`) reads the deck in one column, where the ray towards the sun pierces the mean plane; a slanted
sun ray through a deck thicker than its features crosses several of them. On the sunbeams stage (a deck about
300 m thick with features of 200 m to 3 km; 48 x 32 pixels) its radiance against ``exact``: sun overhead, NRMSE
3e-6 (the same integral); 17 deg from the zenith, 13% (bias +6%); 38 deg, 184% (bias +53%); at the stage's own sun
(52 deg from the zenith, 96 x 64 pixels) 276% (bias +128%), and ``sexp`` 76% (bias +49%). It is exact for an
overhead sun and fit for thin decks; it ran about 80 times faster than ``exact`` there with the sun's depth exact at
every step (``shadow_map_texels`` 0).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import warp as wp

from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.errors import UsageError
from warpsky.core.image import ImageLayer
from warpsky.core.resources import LAYER_BYTES, MemoryEstimate
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.dome import ambient_vec, isotropic_ambient
from warpsky.light.sun import sun_struct, sunlight
from warpsky.model.camera import Projection
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.deck import CloudDeck
from warpsky.model.scene import Scene
from warpsky.passes.render_pass import Pass

if TYPE_CHECKING:  # the kernels load when the pass renders, not when a frame asks whether it runs
    from warpsky.passes.deck.deck_kernels import DeckMarch


def shadow_feature(clouds: CloudDeck) -> float:
    """The shortest horizontal feature [m] of the deck's shadow pattern: the shortest wavelength, or the
    polynomial's curvature length (the equator's rounding shapes the thickness near the edges, not the holes)."""
    k = np.linalg.norm(clouds.wave_vectors, axis=1) if len(clouds.wave_vectors) else np.zeros(0)
    lengths = [2.0 * math.pi / v for v in k if v > 0.0]
    if lengths:
        return float(min(lengths))
    from warpsky.media.deck.deck_geometry import feature_length

    return feature_length(clouds)


def haze_step_bound(clouds: CloudDeck) -> float:
    """The longest step in clear haze [m]: a quarter of its mean free path in its densest channel (1e30 without
    haze)."""
    sigma = float(np.max(clouds.haze.density)) if clouds.haze is not None else 0.0
    return 0.25 / sigma if sigma > 0.0 else 1.0e30


#: Steps per shortest feature of the deck's shadow in clear haze by default (``haze_steps_per_feature``). Measured
#: on the 48-member scenery family (``evaluation/scripts/choose_scenery_settings.py``) against 64 steps per feature:
#: relative RMS error median 0.99 % on the tune half, 2.2 % on the test half (worst 2.5 %, mean bias -0.01 %), at 1.3x
#: the time of 8 steps (medians 2.2 % / 4.7 %; before the haze's trapezoid, -3 % bias on a tune deck). No candidate kept
#: the tune half's worst pixel error within 1 %: under a sun 8.5 deg up the shafts are finer than the pixels (74 %
#: at 16 steps, 49 % at 32 for 3x the time), so the default stays at 16 and such decks are not trustworthy per pixel.
HAZE_STEPS_PER_FEATURE = 16
#: The share of a frame's time budget the pass's march may take (:func:`budget_texels`).
BUDGET_SHARE = 0.25
#: Where the march stops under a time budget it cannot afford at the automatic settings (the light beyond is at most
#: 1 % of what it gathered).
BUDGET_TRANSMITTANCE = 0.01
#: Seconds of the march per pixel and per texel of the shadow map's side, on 2 CPU cores: 2.5 s for 96 x 64 pixels
#: at 132 texels on the sunbeams stage at load 3 (3.1e-6), about half that idle.
MARCH_SECONDS = 2.5e-6
#: The shadow map's finest texels per shortest haze step. Bilinear transmittance over texels as long as the step
#: blurs the shafts' edges (on a deck of 700 m waves at 16 steps per feature: 4.8 % relative RMS error against a
#: march 4x finer, +0.2 % bias, where the per-step exact depth gave 0.6 %); at a quarter of the step the finest
#: level is as good as the exact depth at each step, and the map gains only two levels.
TEXELS_PER_HAZE_STEP = 4


def automatic_steps(clouds: CloudDeck, haze_steps_per_feature: int = HAZE_STEPS_PER_FEATURE
                    ) -> tuple[float, float]:
    """(cloud step, shortest haze step) [m] from the deck's extinction and smallest features (module docstring)."""
    from warpsky.media.deck.deck_geometry import feature_length

    feature = feature_length(clouds)
    sigma = float(np.max(clouds.extinction))
    cloud = min(0.25 / sigma, feature / 16.0) if sigma > 0.0 else feature / 16.0
    return cloud, min(haze_step_bound(clouds), shadow_feature(clouds) / haze_steps_per_feature)


@documented
@dataclass(frozen=True)
class DeckSettings(Settings):
    """Settings of the deck pass (``--set deck.NAME=VALUE``); see the module docstring for what
    ``max`` and ``sexp`` trade and where they are not trustworthy."""

    owner = "deck"
    prefix = "deck."
    mode: Literal["exact", "max", "sexp"] = setting(
        "exact", help="the sunlight reaching a point of the deck or the haze: exact = dimmed by the exact optical "
        "depth along the sun ray; max = by Max's thickness rule (one pattern lookup per sample); sexp = Max's "
        "quadratic sexp in the cloud integral (vertical-sun model), to measure it")
    step_length: float | None = setting(None, unit="m", range="> 0", help="step inside the cloud",
                                        auto="min(0.25 / sigma_max, feature / 16)")
    haze_step_length: float | None = setting(None, unit="m", range="> 0", help="step in clear haze (resolves the "
                                             "shafts); authored: that step everywhere",
                                             auto="min(0.25 / sigma_haze, shadow feature / haze_steps_per_feature), "
                                             "longer along rays close to the sun")
    haze_steps_per_feature: int = setting(HAZE_STEPS_PER_FEATURE, range="1..1024", help="automatic haze step: "
                                          "steps per shortest feature of the deck's shadow (median quadrature error on "
                                          "the scenery family 1-2 %; more for shafts finer than the pixels)")
    shadow_map_texels: int | None = setting(
        None, range="0..2048", help="texels per side of each level of the deck's shadow map on the haze (0: the "
        "exact sun-ray optical depth at every haze step; 1-3 are taken as 4)", auto="2 / the pixel's angle (a texel "
        "about a pixel's footprint wide; fewer under a time budget too short for it)")
    max_steps: int = setting(4096, range=">= 1", help="most steps per piece of constant extinction")
    min_transmittance: float = setting(1.0e-4, range="[0, 1)", help="stop once the view is this opaque")


class Deck:
    """Renders a scene's height-field clouds and their haze as an :class:`~warpsky.core.image.ImageLayer` (single
    scattering of the sun and of the sky's ambient light; :mod:`~warpsky.passes.deck.deck_kernels`). Settings are a
    :class:`DeckSettings`, or its fields as keywords."""

    def __init__(self, settings: DeckSettings | None = None, *, device: str = "cpu", **values):
        self.settings = settings if settings is not None else DeckSettings(**values)
        self.device = device
        self.shadows = None  # the shadow map of the last render

    def __repr__(self) -> str:
        return f"Deck({self.settings!r}, device={self.device!r})"

    def march_settings(self, scene: Scene, clouds: CloudDeck, has_limit: bool,
                       ambient=None) -> DeckMarch:
        from warpsky.passes.deck.deck_kernels import DeckMarch

        s = self.settings
        cloud_auto, haze_auto = automatic_steps(clouds, s.haze_steps_per_feature)
        march = DeckMarch()
        march.cloud_step = float(s.step_length or cloud_auto)
        march.haze_step = float(s.haze_step_length or haze_auto)
        march.haze_feature = 0.0 if s.haze_step_length else shadow_feature(clouds) / s.haze_steps_per_feature
        march.shadow = int(s.mode != "exact")
        march.haze_step_max = haze_step_bound(clouds)
        march.max_steps = s.max_steps
        march.min_transmittance = s.min_transmittance
        march.ambient = ambient_vec(scene) if ambient is None else wp.vec3(*np.asarray(ambient, np.float64).tolist())
        march.ambient_on = int(np.any(np.asarray(march.ambient) > 0.0))
        march.sexp = int(s.mode == "sexp")
        march.has_limit = int(has_limit)
        return march

    def render(self, scene: Scene, width: int, height: int, *, limit: np.ndarray | None = None,
               ambient=None) -> ImageLayer:
        """Render ``scene``'s deck at ``width`` x ``height``. ``limit``: None or (height, width) float32
        camera-space depths [m] of the nearest opaque surface; rays stop there and at the far clipping plane.
        ``ambient``: the isotropic sky radiance, RGB (None: the dome's,
        :func:`~warpsky.light.dome.ambient_radiance`)."""
        from warpsky.media.deck.deck_geometry import deck_struct, haze_struct, the_deck
        from warpsky.passes.deck.deck_kernels import deck_kernel

        camera = scene.camera.conformed(width, height)
        clouds = the_deck(scene)
        started = time.perf_counter()
        if clouds is None:
            return ImageLayer(np.zeros((height, width, 3), np.float32), np.ones((height, width, 3), np.float32),
                              np.full((height, width), camera.far, np.float32), stats={"seconds": 0.0})
        if limit is not None:
            limit = np.ascontiguousarray(limit, dtype=np.float32)
            if limit.shape != (height, width):
                raise UsageError(f"deck pass: limit must be ({height}, {width}) depths, got {limit.shape}")
        device = self.device
        with wp.ScopedDevice(device):
            march = self.march_settings(scene, clouds, limit is not None, ambient)
            depth_limit = wp.array(limit if limit is not None else np.zeros((1, 1), np.float32), dtype=float)
            radiance = wp.zeros((height, width), dtype=wp.vec3)
            transmittance = wp.zeros((height, width), dtype=wp.vec3)
            depth = wp.zeros((height, width), dtype=float)
            hf, haze = deck_struct(clouds, camera.position, scene.time_s, device), haze_struct(clouds, camera.position)
            sun = sun_struct(sunlight(scene))
            mapped = time.perf_counter()
            shadows = self.shadow_map(clouds, camera, width, height, hf, haze, sun, march, depth_limit)
            mapped = time.perf_counter() - mapped
            inputs = [hf, haze, pinhole_camera(camera, width, height), sun, march, shadows, depth_limit, radiance,
                      transmittance, depth]
            launch_rows(deck_kernel, height, width, inputs, device)
            self.shadows = shadows
            wp.synchronize_device(device)
            return ImageLayer(radiance.numpy(), transmittance.numpy(), depth.numpy(), stats={
                "seconds": time.perf_counter() - started, "mode": self.settings.mode,
                "step_length": march.cloud_step, "haze_step_length": march.haze_step,
                "shadow_map": f"{shadows.levels} x {shadows.texels}^2 texels of {shadows.texel:.4g} m"
                if shadows.on else "off", "shadow_map_seconds": mapped})

    def shadow_map(self, clouds: CloudDeck, camera, width: int, height: int, hf, haze, sun, march: DeckMarch,
                   limit):
        """The deck's shadow on the haze for this frame (:mod:`~warpsky.passes.deck.shadow_map`), or an unused map:
        without haze, with the setting 0, in ``max`` or ``sexp`` mode, with the sun within 0.06 deg of the
        horizon, or by default through an orthographic camera (whose pixels' footprints do not grow with
        distance)."""
        from warpsky.passes.deck.deck_kernels import mark_kernel
        from warpsky.passes.deck.shadow_map import auto_texels, build_shadow_map, off_map

        texels = self.settings.shadow_map_texels
        orthographic = camera.projection is Projection.ORTHOGRAPHIC
        if (clouds.haze is None or texels == 0 or self.settings.mode != "exact" or not sun.lit
                or (texels is None and orthographic)):
            return off_map(self.device)
        if texels is None:
            texels = auto_texels(pixel_angle(camera, width))
        direction = np.array([sun.direction[0], sun.direction[1], sun.direction[2]], dtype=np.float64)
        texel = (march.haze_feature if march.haze_feature > 0.0 else march.haze_step) / TEXELS_PER_HAZE_STEP
        reach = camera.far * (1.0 + math.hypot(direction[0], direction[2]) / max(direction[1], 1.0e-3))
        if haze.top > hf.band_low:  # cloud inside the haze cuts its march into pieces: compute every texel
            return build_shadow_map(hf, hf.band_low, direction, texel, texels, reach, self.device, launch_rows)

        def mark(m) -> None:
            launch_rows(mark_kernel, height, width, [haze, pinhole_camera(camera, width, height), sun, march, m,
                                                     limit], self.device)

        return build_shadow_map(hf, haze.top, direction, texel, texels, reach, self.device, launch_rows, mark)


def budget_settings(settings: DeckSettings, budget: float, frame) -> DeckSettings:
    """``settings`` for a frame of ``budget`` seconds: where the automatic shadow map costs more than the budget
    affords (:func:`budget_texels`), a smaller one, cloud steps of a quarter of the mean free path (not the features'
    16th) and a march that stops at a transmittance of 1 % (their automatic values only)."""
    from warpsky.media.deck.deck_geometry import the_deck
    from warpsky.passes.deck.shadow_map import auto_texels

    camera = frame.scene.camera.conformed(frame.width, frame.height)
    texels = budget_texels(budget, camera, frame.width, frame.height)
    if settings.shadow_map_texels is not None or texels >= auto_texels(pixel_angle(camera, frame.width)):
        return settings
    sigma = float(np.max(the_deck(frame.scene).extinction))
    step = settings.step_length if settings.step_length is not None or sigma <= 0.0 else 0.25 / sigma
    return dataclasses.replace(settings, shadow_map_texels=texels, step_length=step,
                               min_transmittance=max(settings.min_transmittance, BUDGET_TRANSMITTANCE))


def budget_texels(budget: float, camera, width: int, height: int) -> int:
    """The shadow map's texels per side in a frame of ``budget`` seconds: the automatic size (2 / the pixel's angle),
    or fewer, so that the pass's march takes about :data:`BUDGET_SHARE` of the budget at
    :data:`MARCH_SECONDS` per pixel and texel (the march takes about N / 2 steps per level a ray crosses)."""
    from warpsky.passes.deck.shadow_map import auto_texels

    affordable = BUDGET_SHARE * budget / (MARCH_SECONDS * max(width * height, 1))
    return int(max(16, min(auto_texels(pixel_angle(camera, width)), affordable)))


def frame_key(scene: Scene) -> tuple:
    """What a frame's shadow map depends on besides the settings: the deck, the time, the camera's position and the
    sun's direction."""
    from warpsky.media.deck.deck_geometry import the_deck

    light = sunlight(scene)
    sun = None if light is None else tuple(np.asarray(light.direction, np.float64).tolist())
    return id(the_deck(scene)), scene.time_s, tuple(np.asarray(scene.camera.position, np.float64).tolist()), sun


def pixel_angle(camera, width: int) -> float:
    """The mean angle [rad] a pixel of a perspective camera spans across the view."""
    return 2.0 * math.atan(0.5 * camera.horizontal_aperture / camera.focal_length) / max(width, 1)


def deck_sun_transmittance(scene: Scene, points: np.ndarray, device: str = "cpu", *,
                           exact: bool = False, shadow_map=None) -> np.ndarray:
    """(N, 3) transmittance of the sunlight reaching world ``points`` (N, 3) [m] through the scene's deck and haze.

    Max §6: the sun ray from the point pierces the mean plane at Q and the light is attenuated by
    exp(-sigma (g - h)(Q)), the deck's vertical thickness there (a point above the plane: the cloud above it in
    its column; a sun at or below the horizon: the exact sun-ray optical depth); ``exact`` uses the exact
    optical depth along the sun ray everywhere, read from ``shadow_map`` (the
    :class:`~warpsky.passes.deck.shadow_map.DeckShadowMap` a :class:`Deck` drew this frame with, from the same camera)
    where it holds the point. The haze multiplies by exp(-sigma_haze x its path to the slab's edge). Ones without a
    deck or a sun."""
    from warpsky.media.deck.deck_geometry import deck_struct, haze_struct, the_deck
    from warpsky.passes.deck.deck_kernels import sun_transmittance_kernel
    from warpsky.passes.deck.shadow_map import off_map

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    clouds = the_deck(scene)
    light = sunlight(scene)
    if clouds is None or light is None:
        return np.ones((len(pts), 3))
    reference = scene.camera.position
    with wp.ScopedDevice(device):
        relative = wp.array((pts - reference).astype(np.float32), dtype=wp.vec3)
        out = wp.zeros(len(pts), dtype=wp.vec3)
        wp.launch(sun_transmittance_kernel, dim=len(pts), inputs=[
            deck_struct(clouds, reference, scene.time_s, device), haze_struct(clouds, reference),
            wp.vec3(*np.asarray(light.direction, dtype=np.float64).tolist()), relative, int(exact),
            shadow_map if shadow_map is not None and exact else off_map(device), out])
        return out.numpy().astype(np.float64)


class DeckPass(Pass):
    """Max's clouds and haze shafts, stopped by the nearest opaque surface, lit through the frame's air."""

    name = "deck"
    shades_air = True
    Settings = DeckSettings

    @classmethod
    def runs(cls, scene, technique) -> bool:
        return bool(scene.decks) and not technique.traces_decks

    @classmethod
    def refusal(cls, scene, technique):
        if cls.runs(scene, technique) and technique.traces_air:
            return "height-field clouds", [clouds.name for clouds in scene.decks]
        return None

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if not scene.decks:
            return {"deck": 'none (no prim with warpsky:kind = "heightFieldClouds")'}
        lines = []
        for clouds in scene.decks:
            haze = "with haze" if clouds.haze is not None else "no haze"
            lines.append(f"{clouds.name}: mean plane {clouds.mean_altitude:g} m, {len(clouds.amplitudes)} waves, "
                         f"density {clouds.density:g} 1/m, {haze}")
        return {"deck": "; ".join(lines) + f" (Max 1986; single scattering, mode {settings.mode})"}

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        pixels = width * height
        return MemoryEstimate().add("deck", host=pixels * (0 if is_cpu(self.device) else LAYER_BYTES),
                                    device=pixels * LAYER_BYTES)

    def shadow(self, scene):
        """By the exact sun-ray optical depth (Max's thickness rule fails for decks thicker than their features),
        read from the shadow map this pass drew its layer with in the same frame (same camera and time) where the
        map holds the point."""
        kept = getattr(self, "_shadows", None)
        shadows = kept[1] if kept is not None and kept[0] == frame_key(scene) else None
        return lambda points: deck_sun_transmittance(scene, points, self.device, exact=True, shadow_map=shadows)

    def own_layer(self, frame) -> ImageLayer:
        """The deck's and the haze's single scattering of the sun, and their ambient term unless the technique
        path traces the sky's light on them (:meth:`~warpsky.techniques.technique.Technique.scenery_paths`); drawn once
        per frame (the media pass hands it to those paths' error estimate)."""

        def draw() -> ImageLayer:
            seen = frame.light.lit_at_media(frame.scene)
            ambient = isotropic_ambient(seen, frame.light.sky)
            if frame.technique.scenery_paths(frame.scene):
                ambient = np.zeros(3)
            budget = getattr(getattr(frame.technique, "settings", None), "time_budget", None)
            settings = self.settings if budget is None else budget_settings(self.settings, float(budget), frame)
            deck = Deck(settings, device=self.device)
            layer = deck.render(seen, frame.width, frame.height, limit=frame.limit, ambient=ambient)
            self._shadows = (frame_key(frame.scene), deck.shadows)
            return layer

        return self.keep(frame, draw)

    def render(self, frame) -> list[ImageLayer]:
        return [self.own_layer(frame)]
