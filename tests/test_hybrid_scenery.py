"""The hybrid technique on analytic fog and meshes: the fog and surfaces passes' single scattering plus the paths'
multiple scattering (:mod:`warpsky.techniques.hybrid.scenery`) against the path tracer, which traces it all."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.model.fog import AnalyticFog, ConstantTerm
from warpsky.model.lights import Dome
from warpsky.model.scene import Camera, Ground, Scene, Sun
from warpsky.model.terrain import TerrainMesh
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan

SIZE = 8


def slab_scene(floor: str, dome: bool) -> Scene:
    """A fog slab of optical depth 1 (albedo 1, g 0.85, as the valley fog's) 20 m thick over a Lambertian floor of
    albedo 0.5 (the ground plane or a flat mesh), no air, the sun 45 deg up, optionally a uniform dome; the camera
    60 m up sees only the floor through the fog."""
    fog = AnalyticFog("slab", [ConstantTerm(0.05)], floor=0.0, top=20.0, albedo=np.ones(3), g=0.85)
    camera = Camera("cam", np.array([0.0, 60.0, 0.0]), look_rotation((0.0, -1.0, -0.5)), 36.0, 36.0, 36.0,
                    far=5000.0)
    d = np.array([0.3, 0.6, 0.5])
    sun = Sun(d / np.linalg.norm(d), np.ones(3))
    extra = {"dome": Dome(np.full(3, 0.05))} if dome else {}
    if floor == "mesh":
        h = 3000.0
        mesh = TerrainMesh("floor", np.array([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]]),
                           np.array([[0, 2, 1], [0, 3, 2]]), (0.5, 0.5, 0.5))
        return Scene(camera, sun, fogs=(fog,), meshes=(mesh,), **extra)
    return Scene(camera, sun, fogs=(fog,), ground=Ground(0.0, np.full(3, 0.5)), **extra)


def frame(scene: Scene, technique: str, **settings):
    plan = make_plan(scene, technique=technique, settings={k: str(v) for k, v in settings.items()},
                     resolution=(SIZE, SIZE))
    return plan, composite(render_layers(plan, scene)[1], scene.camera.far)


@pytest.mark.parametrize("floor,dome", [("ground", False), ("mesh", True)])
def test_fog_over_a_floor_matches_the_path_tracer(floor, dome):
    """Undenoised, hybrid's frame (fog pass + surfaces pass + paths) is an unbiased estimate of the path tracer's:
    the image means agree within 4 sigma and 5 % (sigma about 1 %). The passes alone (as before the paths traced
    the scenery) give 9 % of it without the dome: the fog's and the floor's multiple scattering is most of the
    light. With a dome the fog's ambient
    term and the floor's sky term are left to the paths (those terms are 25 % of the path tracer's frame under
    this dome: counted twice they would fail this test)."""
    scene = slab_scene(floor, dome)
    plan, mine = frame(scene, "hybrid", spp=2048, target_error=0, denoise=0, seed=3)
    assert plan.passes == ("surfaces", "media", "fog")
    _, traced = frame(scene, "path_tracer", spp=4096, seed=5)
    a, b = mine.rgba[..., 1].astype(np.float64).mean(), traced.rgba[..., 1].astype(np.float64).mean()
    sigma = np.sqrt(mine.aovs["variance"][..., 1].sum() + traced.aovs["variance"][..., 1].sum()) / SIZE**2
    z = (a - b) / sigma
    print(f"\nfog slab over {floor} (dome {dome}): hybrid {a:.5f}, path tracer {b:.5f} +- {sigma:.5f}, z = {z:.2f}")
    assert abs(z) < 4.0 and abs(a / b - 1.0) < 0.05
    assert mine.aovs["multiple_scatter"][..., 1].mean() > 0.5 * a


def test_without_multiple_scattering_the_passes_draw_it_alone():
    """With ``multiple_scattering = 0`` no media pass runs for the scenery: the fog and surfaces passes draw the frame
    as before, their ambient and sky terms included."""
    scene = slab_scene("ground", True)
    plan, single = frame(scene, "hybrid", multiple_scattering=0)
    assert plan.passes == ("surfaces", "fog")
    plan, _ = frame(scene, "hybrid", spp=2, target_error=0, denoise=0)
    assert plan.passes == ("surfaces", "media", "fog") and "path traces the multiple" in plan.features["media"]
    _, traced = frame(scene, "path_tracer", spp=64, seed=5)
    assert single.rgba[..., 1].mean() < 0.4 * traced.rgba[..., 1].mean()


def thin_deck_scene(dome: bool) -> Scene:
    """The height-field reference's thin deck with haze (its single scattering there matches the voxelised deck's:
    -0.09 % +- 0.27 %) 1.5 km over a ground plane of albedo 0.4, the sun 55 deg up, optionally a uniform dome;
    the camera 300 m up looks at the deck from below."""
    from test_deck_reference import thin_deck

    clouds, camera = thin_deck()
    d = np.array([0.4, 0.82, 0.3])
    extra = {"dome": Dome(np.full(3, 0.05))} if dome else {}
    return Scene(camera, Sun(d / np.linalg.norm(d), np.ones(3)), ground=Ground(0.0, np.full(3, 0.4)),
                 decks=(clouds,), **extra)


@pytest.mark.parametrize("dome", [False, True])
def test_deck_over_a_ground_matches_the_path_tracer(dome):
    """A height-field deck: the deck pass's single scattering (its ambient term left to the paths) plus the
    paths through the deck and haze voxelised as the path tracer traces them, undenoised, equal the path tracer's
    frame: image means within 4 sigma and 3 % (sigma about 0.5 %; measured z = -0.4 with and without the dome).
    Without the paths (``multiple_scattering = 0``) the passes give 0.79 of it (0.83 with the dome, their ambient
    term included): the ground's bounce and the deck's multiple scattering."""
    scene = thin_deck_scene(dome)
    settings = {"deck_extent": "2500"}
    plan = make_plan(scene, technique="hybrid", resolution=(24, 16),
                     settings={"spp": "512", "target_error": "0", "denoise": "0", "seed": "3", **settings})
    assert plan.passes == ("surfaces", "media", "deck")
    assert "multiple scattering path traced by hybrid through the deck and haze" in plan.features["deck"]
    mine = composite(render_layers(plan, scene)[1], scene.camera.far)
    plan = make_plan(scene, technique="path_tracer", resolution=(24, 16), settings={"spp": "1024", "seed": "5",
                                                                                     **settings})
    traced = composite(render_layers(plan, scene)[1], scene.camera.far)
    plan = make_plan(scene, technique="hybrid", resolution=(24, 16), settings={"multiple_scattering": "0"})
    passes = composite(render_layers(plan, scene)[1], scene.camera.far)
    a, b = mine.rgba[..., 1].astype(np.float64).mean(), traced.rgba[..., 1].astype(np.float64).mean()
    sigma = np.sqrt(mine.aovs["variance"][..., 1].sum() + traced.aovs["variance"][..., 1].sum()) / (24 * 16)
    alone = passes.rgba[..., 1].astype(np.float64).mean()
    z = (a - b) / sigma
    print(f"\nthin deck (dome {dome}): hybrid {a:.5f}, path tracer {b:.5f} +- {sigma:.5f}, z = {z:.2f}; passes "
          f"alone {alone / b:.3f} of it")
    assert abs(z) < 4.0 and abs(a / b - 1.0) < 0.03
    assert alone < 0.9 * b


def layered_slab_scene(floor: str) -> Scene:
    """The fog slab over its floor (:func:`slab_scene`, no dome) under a broken stratiform layer 300 m up (an 8 x 8
    map of 0-60 m over 2 km, N0 3e8 /m^3: column optical depth up to 2.8); the camera sees the floor through the
    fog only."""
    from warpsky.model.stratiform import StratiformLayer

    thickness = np.array([[60.0 * max(0.0, np.sin(0.9 * i) * np.cos(0.7 * j)) for j in range(8)] for i in range(8)])
    layer = StratiformLayer(thickness.astype(np.float32), 300.0, (-1000.0, -1000.0), (2000.0, 2000.0),
                            name="deck")
    return dataclasses.replace(slab_scene(floor, False), stratiform_layers=(layer,))


@pytest.mark.slow
@pytest.mark.parametrize("floor", ["ground", "mesh"])
def test_fog_under_a_stratiform_layer_matches_the_path_tracer(floor):
    """Fog over a floor under a broken stratiform layer: the fog and surfaces passes' sunlight in the layer's shadow
    (:mod:`~warpsky.media.stratiform.stratiform_shadow`) plus hybrid's paths, which trace the layer voxelised beyond the
    camera rays' first event, undenoised, equal the path tracer's frame (which traces the layer voxelised too): image
    means within 4 sigma and 6 % (sigma about 2 %, most of it the path tracer's, whose sun in the fog is sampled;
    measured z = 0.8 at 4096 paths per pixel over either floor). The passes alone (``multiple_scattering = 0``: the
    stratiform pass draws the ground with its radiosity, the fog its isotropic ambient term) miss it by more than 15
    %."""
    scene = layered_slab_scene(floor)
    plan, mine = frame(scene, "hybrid", spp=2048, target_error=0, denoise=0, seed=3)
    assert plan.passes == ("surfaces", "media", "stratiform", "fog") and "stratiform layers" in plan.features["media"]
    _, traced = frame(scene, "path_tracer", spp=16384, seed=5)
    a, b = mine.rgba[..., 1].astype(np.float64).mean(), traced.rgba[..., 1].astype(np.float64).mean()
    sigma = np.sqrt(mine.aovs["variance"][..., 1].sum() + traced.aovs["variance"][..., 1].sum()) / SIZE**2
    _, alone = frame(scene, "hybrid", multiple_scattering=0)
    z = (a - b) / sigma
    print(f"\nfog under a layer over {floor}: hybrid {a:.5f}, path tracer {b:.5f} +- {sigma:.5f}, z = {z:.2f}; "
          f"passes alone {alone.rgba[..., 1].mean() / b:.3f} of it")
    assert abs(z) < 4.0 and abs(a / b - 1.0) < 0.06 and sigma < 0.03 * b
    assert abs(alone.rgba[..., 1].mean() / b - 1.0) > 0.15


def test_error_estimate_is_relative_to_the_whole_frame():
    """The paths' error estimate divides their noise by the frame's level, the fog's and the floor's sunlight that
    the passes draw included (not by the paths' light alone, which made it conservative by the frame's ratio to
    it): undenoised, it equals the RMS of the paths' standard error over the frame's mean, to rounding."""
    import warpsky.techniques.hybrid.hybrid as hybrid

    scene = slab_scene("ground", False)
    stats = {}
    run = hybrid.MultipleScattering.run

    def keep(self, *args, **kwargs):
        out = run(self, *args, **kwargs)
        stats.update(out[2])
        return out

    hybrid.MultipleScattering.run = keep
    try:
        _, mine = frame(scene, "hybrid", spp=64, target_error=1e-6, denoise=0, seed=3)
    finally:
        hybrid.MultipleScattering.run = run
    noise = np.sqrt(np.mean(mine.aovs["variance"].astype(np.float64)))
    level = mine.rgba[..., :3].astype(np.float64).mean()
    paths = mine.aovs["multiple_scatter"].astype(np.float64).mean()
    assert paths < 0.95 * level  # the passes draw a part of the frame (its sunlit floor and fog)
    assert stats["error_estimate"] == pytest.approx(noise / level, rel=1e-3)


def test_layers_over_a_textured_ground_leave_the_scenery_to_the_passes():
    """A ground albedo map is read by the stratiform pass alone: under layers over such a ground hybrid's paths do
    not trace the scenery (no media pass), the stratiform pass draws the textured ground; without the map they do,
    unless a fog reaches the layers' base."""
    from warpsky.model.stratiform import GroundTexture

    scene = layered_slab_scene("ground")
    texture = GroundTexture(np.full((4, 4, 3), 0.3), (-500.0, -500.0), (1000.0, 1000.0))
    textured = dataclasses.replace(scene, ground=dataclasses.replace(scene.ground, albedo_map=texture))
    from warpsky.passes.frame import ground_pass

    plan = make_plan(textured, technique="hybrid", resolution=(SIZE, SIZE))
    assert "media" not in plan.passes and ground_pass(plan.pass_runners, textured) == "stratiform"
    plan = make_plan(scene, technique="hybrid", resolution=(SIZE, SIZE))
    assert "media" in plan.passes and ground_pass(plan.pass_runners, scene) == "surfaces"
    # a fog reaching the layers' base: its first events there would end as the layers' do, so no paths either
    fog = dataclasses.replace(scene.fogs[0], top=350.0)
    plan = make_plan(dataclasses.replace(scene, fogs=(fog,)), technique="hybrid", resolution=(SIZE, SIZE))
    assert "media" not in plan.passes


def test_fog_and_deck_layers_are_drawn_once_per_frame(monkeypatch):
    """The error estimate reads the fog pass's and the deck pass's own layers of the frame (drawn early
    and kept for their turn), so a hybrid scenery frame draws the fog once and the deck once."""
    from warpsky.passes.deck.deck import Deck
    from warpsky.passes.fog.fog import Fog

    calls = {"fog": 0, "deck": 0}
    fog_render, deck_render = Fog.render, Deck.render

    def counted_fog(self, *args, **kwargs):
        calls["fog"] += 1
        return fog_render(self, *args, **kwargs)

    def counted_deck(self, *args, **kwargs):
        calls["deck"] += 1
        return deck_render(self, *args, **kwargs)

    monkeypatch.setattr(Fog, "render", counted_fog)
    monkeypatch.setattr(Deck, "render", counted_deck)
    plan, _ = frame(slab_scene("ground", False), "hybrid", spp=2, target_error=0, denoise=0)
    assert "media" in plan.passes and calls["fog"] == 1
    scene = thin_deck_scene(False)
    plan = make_plan(scene, technique="hybrid", resolution=(24, 16),
                     settings={"spp": "2", "target_error": "0", "denoise": "0", "deck_extent": "2500"})
    render_layers(plan, scene)
    assert "media" in plan.passes and calls["deck"] == 1
