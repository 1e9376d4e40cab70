"""The quadrature of the deck pass's haze shafts against a finer march, and the rule that chooses the
scenery passes' quadrature settings on a family's tune half (:mod:`evaluation.scenery_settings`)."""

from __future__ import annotations

import math

import numpy as np
from conftest import look_rotation

from evaluation.scenery_settings import Measured, choose
from warpsky.model.deck import CloudDeck, HazeSpec
from warpsky.model.scene import Camera, Scene, Sun
from warpsky.passes.deck.deck import Deck, automatic_steps, shadow_feature


def shafts_scene() -> Scene:
    """A broken deck (four waves of 700 m, about 40 % of the columns clear) 1 km up over haze of 4e-4 /m, the sun
    50 deg up; the camera 100 m up looks 15 deg above the horizon across the shafts."""
    rng = np.random.default_rng(7)
    k = rng.normal(size=(4, 2)) * 2.0 * math.pi / 700.0
    clouds = CloudDeck("/World/Deck", 1000.0, [5.0], k, rng.uniform(10, 30, 4), rng.uniform(0, 6, 4),
                               rounding=40.0, bottom_depth=60.0, density=0.03,
                               haze=HazeSpec(np.full(3, 4e-4), g=0.7, floor=-50.0))
    elevation = math.radians(15.0)
    look = np.array([math.cos(elevation), math.sin(elevation), 0.0])
    camera = Camera("cam", np.array([0.0, 100.0, 0.0]), look_rotation(look), 24.0, 36.0, 24.0, near=1.0, far=2e4)
    sun = math.radians(50.0)
    return Scene(camera, Sun(np.array([0.0, math.sin(sun), math.cos(sun)]), np.ones(3)), decks=(clouds,))


def test_haze_shafts_are_not_darkened_by_the_march():
    """The march at its automatic steps against one with the haze step authored at a 64th of the shadow's shortest
    feature: the image means agree within 0.5 % (the exp-lerp mean of the sun's depth across a shaft's edge, which
    this replaced, was 3 % dark on a deck of the scenery family), and twice as many steps per feature halve the
    relative RMS error at least roughly (first order in the step: the edges). The sun's depth is exact at every step
    here (no shadow map, whose texels about a pixel's footprint wide blur what one ray per pixel resolves: its
    own test is in test_deck_shadow_map.py)."""
    scene = shafts_scene()
    clouds = scene.decks[0]
    fine = Deck(haze_step_length=shadow_feature(clouds) / 64.0, shadow_map_texels=0).render(scene, 32, 24).radiance
    errors = []
    for per_feature in (8, 16):
        out = Deck(haze_steps_per_feature=per_feature, shadow_map_texels=0).render(scene, 32, 24).radiance
        bias = out[..., 1].mean() / fine[..., 1].mean() - 1.0
        errors.append(float(np.sqrt(np.mean((out - fine) ** 2)) / fine.mean()))
        print(f"{per_feature} steps per feature: bias {bias:+.4f}, relative RMSE {errors[-1]:.4f}")
        assert abs(bias) < 0.005
    assert errors[1] < 0.75 * errors[0]
    assert automatic_steps(clouds, 16)[1] <= automatic_steps(clouds, 8)[1]


def rows(candidate: str, tune: list[float], test: list[float], seconds: float) -> list[Measured]:
    return ([Measured(f"m{i}", "tune", candidate, e, 0.0, 0.0, seconds) for i, e in enumerate(tune)]
            + [Measured(f"n{i}", "test", candidate, e, -e, 0.0, seconds) for i, e in enumerate(test)])


def test_choose_takes_the_fastest_within_tolerance_on_the_tune_half():
    """The fastest candidate whose worst tune-half error is within the tolerance is chosen, whatever the test half
    says (it only reports); with none within, the most accurate one, flagged."""
    measured = (rows("fog fast", [0.002, 0.03], [0.0, 0.0], 1.0) + rows("fog mid", [0.004, 0.008], [0.01, 0.02], 2.0)
                + rows("fog slow", [0.0, 0.001], [0.0, 0.0], 4.0))
    choice = choose(measured, "fog", tolerance=0.01)
    assert choice["chosen"] == "fog mid" and choice["within_tolerance"]
    test = choice["candidates"]["fog mid"]["test"]
    assert test["worst"] == 0.02 and test["median"] == 0.015 and math.isclose(test["mean_bias"], -0.015)
    choice = choose(measured, "fog", tolerance=1e-4)
    assert choice["chosen"] == "fog slow" and not choice["within_tolerance"]
