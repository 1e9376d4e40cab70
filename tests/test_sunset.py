"""A sunset through the horizon, frame by frame: 49 sun elevations from -1 deg to +1 deg (a 0.53 deg disk) over a
small box cloud and a ground plane, with and without air, rendered through the whole frame pipeline (plan, passes,
composite) by every technique and by the stratiform pass.

The sun's disk sets gradually behind the flat horizon, so the frame mean must change smoothly: no frame-to-frame
jump larger than twice the larger of its two neighbouring jumps (plus a small allowance for Monte Carlo noise, the
same seed in every frame). Every frame is finite and non-negative; frames whose whole disk is below the horizon are
black (the sun is the only light), frames with any of it above are lit, in every technique alike.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpsky.model.scene import Atmosphere, Camera, Ground, PhaseKind, PhaseModel, Scene, Sun, VoxelMedium
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan

#: Sun elevations of the sequence [deg]: 1/24 deg apart, one frame exactly on the horizon.
ELEVATIONS_DEG = np.linspace(-1.0, 1.0, 49)
#: Angular diameter of the sun [deg] (the DistantLight default).
SUN_ANGLE_DEG = 0.53
#: Image size [px]; every frame is tiny, the sequence is what is tested.
SIZE = 8
#: Low settings per technique (fixed seeds: the same paths in every frame).
CASES = {
    "single_scatter": {"step_length": "20", "shadow_step_length": "20"},
    "slicing": {"slice_count": "16", "light_resolution": "16", "orders": "8"},
    "path_tracer": {"spp": "512", "seed": "5", "max_bounces": "8"},
    "hybrid": {"spp": "256", "seed": "5", "max_bounces": "8", "denoise": "0", "target_error": "0",
               "step_length": "20", "shadow_step_length": "20"},
}
#: Allowance on each jump for Monte Carlo noise, relative to the sequence's brightest frame mean (the paths of one
#: frame decorrelate from the next at their first step towards the sun; the frame mean's noise is about 1%).
NOISE = {"path_tracer": 0.04, "hybrid": 0.04}
#: Allowance for float32 rounding in the deterministic techniques, relative to the brightest frame mean.
ROUNDING = 1.0e-5
#: Largest jump relative to the brightest frame: the visible fraction of the disk changes by at most
#: 2 step / (pi r) = 10% of the sun per frame (its slope at the horizon); half as much again for the ground's
#: cosine and the air's transmittance, which change with it.
STEEPEST = 1.5 * 2.0 * (ELEVATIONS_DEG[1] - ELEVATIONS_DEG[0]) / (math.pi * 0.5 * SUN_ANGLE_DEG)


def sun_towards(elevation_deg: float) -> np.ndarray:
    """Unit vector towards a sun behind the camera and to its right, ``elevation_deg`` above the horizon."""
    e = math.radians(elevation_deg)
    azimuth = math.radians(30.0)  # from +Z (behind the camera) towards +X
    return np.array([math.cos(e) * math.sin(azimuth), math.sin(e), math.cos(e) * math.cos(azimuth)])


def sunset_scene(elevation_deg: float, *, air: bool, layer: bool = False) -> Scene:
    """A 400 m box cloud 1.2 km ahead of a camera 150 m above a grey ground, lit by a sun at ``elevation_deg``;
    ``layer`` replaces the cloud with a stratiform layer."""
    pitch = math.radians(4.0)  # the cloud fills a third of the frame, the ground below the horizon a third
    forward = np.array([0.0, math.sin(pitch), -math.cos(pitch)])
    back = -forward
    right = np.array([1.0, 0.0, 0.0])
    rotation = np.column_stack([right, np.cross(back, right), back])
    camera = Camera("camera", np.array([0.0, 150.0, 0.0]), rotation, 35.0, 20.0, 20.0, near=1.0, far=1.0e5)
    sun = Sun(sun_towards(elevation_deg), np.array([1.0, 0.97, 0.92]), math.radians(SUN_ANGLE_DEG))
    atmosphere = Atmosphere() if air else None
    if layer:
        from warpsky.model.stratiform import StratiformLayer

        thickness = np.full((8, 8), 200.0, np.float32)
        thickness[2:5, 3:6] = 0.0  # a hole: shadow and light on the ground
        return Scene(camera, sun, ground=Ground(0.0, np.full(3, 0.3)), atmosphere=atmosphere,
                     stratiform_layers=(StratiformLayer(thickness, 400.0, (-2000.0, -4000.0), (4000.0, 4000.0)),))
    world_from_index = np.diag([100.0, 100.0, 100.0, 1.0])
    world_from_index[:3, 3] = (-150.0, 200.0, -1350.0)  # 4 voxels of 100 m: a box from y = 150 m to 550 m
    cloud = VoxelMedium("cloud", np.ones((4, 4, 4), np.float32), world_from_index, extinction_scale=np.full(3, 0.01),
                        albedo=np.full(3, 0.95), phase=PhaseModel(PhaseKind.HG, 0.6))
    return Scene(camera, sun, media=(cloud,), ground=Ground(0.0, np.full(3, 0.3)), atmosphere=atmosphere)


def frame_means(technique: str, settings: dict[str, str], *, air: bool, layer: bool = False) -> np.ndarray:
    """Mean RGB radiance of every frame of the sequence (checking each frame is finite and non-negative)."""
    means = []
    for elevation in ELEVATIONS_DEG:
        scene = sunset_scene(float(elevation), air=air, layer=layer)
        plan = make_plan(scene, technique=technique, settings=dict(settings), resolution=(SIZE, SIZE), device="cpu")
        _, layers = render_layers(plan, scene)
        rgb = composite(layers, far=scene.camera.far).rgba[..., :3]
        assert np.all(np.isfinite(rgb)), f"{technique}: non-finite pixels at {elevation:+.4f} deg"
        assert rgb.min() >= 0.0, f"{technique}: negative radiance {rgb.min()} at {elevation:+.4f} deg"
        means.append(float(rgb.mean()))
    return np.asarray(means)


def largest_relative_jump(means: np.ndarray) -> float:
    """Largest frame-to-frame change of the frame mean, relative to the sequence's brightest frame."""
    return float(np.abs(np.diff(means)).max() / max(means.max(), 1e-30))


def assert_sets_smoothly(means: np.ndarray, allowance: float, label: str) -> None:
    """No jump larger than twice the larger neighbouring jump (plus ``allowance`` times the brightest frame);
    black while the whole disk is below the horizon, lit while it is all above."""
    radius = 0.5 * SUN_ANGLE_DEG
    below, above = ELEVATIONS_DEG <= -radius, ELEVATIONS_DEG >= radius
    brightest = float(means.max())
    assert brightest > 0.0, f"{label}: every frame is black"
    np.testing.assert_array_equal(means[below], 0.0, err_msg=f"{label}: light from a sun below the horizon")
    assert np.all(means[~below] > 0.0), f"{label}: unlit frames with part of the disk above the horizon"
    assert np.all(means[above] > 1.0e-3 * brightest), f"{label}: dark frames with the disk above the horizon"
    jumps = np.abs(np.diff(means))
    neighbours = np.maximum(np.concatenate([[0.0], jumps[:-1]]), np.concatenate([jumps[1:], [0.0]]))
    limit = 2.0 * neighbours + allowance * brightest
    assert jumps.max() <= (STEEPEST + allowance) * brightest, (
        f"{label}: a frame changes by {jumps.max() / brightest:.3f} of the brightest frame, more than the disk "
        f"setting allows ({STEEPEST:.3f})")
    worst = int(np.argmax(jumps - limit))
    assert np.all(jumps <= limit), (
        f"{label}: the frame mean jumps by {jumps[worst]:.4g} between {ELEVATIONS_DEG[worst]:+.4f} and "
        f"{ELEVATIONS_DEG[worst + 1]:+.4f} deg (neighbouring jumps {neighbours[worst]:.4g}, brightest frame "
        f"{brightest:.4g})")


@pytest.mark.slow  # four techniques x two airs: 25 s of the fast suite
@pytest.mark.parametrize("air", [False, True], ids=["no-air", "air"])
@pytest.mark.parametrize("technique", list(CASES))
def test_sunset_is_smooth_in_every_technique(technique, air):
    means = frame_means(technique, CASES[technique], air=air)
    label = f"{technique} ({'air' if air else 'no air'})"
    print(f"\n{label}: largest frame-to-frame jump {largest_relative_jump(means):.4f} of the brightest frame mean")
    assert_sets_smoothly(means, NOISE.get(technique, ROUNDING), label)


@pytest.mark.parametrize("air", [False, True], ids=["no-air", "air"])
def test_sunset_is_smooth_in_the_stratiform_pass(air):
    means = frame_means("single_scatter", {}, air=air, layer=True)
    label = f"stratiform pass ({'air' if air else 'no air'})"
    print(f"\n{label}: largest frame-to-frame jump {largest_relative_jump(means):.4f} of the brightest frame mean")
    assert_sets_smoothly(means, ROUNDING, label)


# ---- the host-side sun model ------------------------------------------------------------------------------------


def test_visible_fraction_is_the_segment_above_the_horizon():
    from warpsky.light.sun import visible_elevation, visible_fraction

    radius = math.radians(0.265)
    # area and centroid of the part of the disk above the horizon, by brute-force sampling of the disk
    u = (np.arange(2000) + 0.5) / 2000 * 2.0 - 1.0
    x, y = np.meshgrid(u, u)
    inside = x * x + y * y <= 1.0
    for elevation in np.radians([-0.3, -0.265, -0.2, -0.05, 0.0, 0.1, 0.26, 0.3]):
        above = inside & (elevation + radius * y > 0.0)
        expected = above.sum() / inside.sum()
        np.testing.assert_allclose(visible_fraction(elevation, radius), expected, atol=2e-3)
        if above.any():
            centroid = elevation + radius * y[above].mean()
            np.testing.assert_allclose(visible_elevation(elevation, radius), centroid, atol=2e-3 * radius)
            assert visible_elevation(elevation, radius) > 0.0
    assert visible_fraction(0.0, radius) == 0.5
    assert (visible_fraction(-1e-9, 0.0), visible_fraction(1e-9, 0.0)) == (0.0, 1.0)  # no disk: a step at 0


def test_air_mass_is_finite_and_continuous_through_the_horizon():
    from warpsky.media.air.analytic import air_sine, horizon_air_mass

    gamma = 1.0 / 8000.0
    sines = np.linspace(-0.2, 0.3, 50001)
    values = air_sine(sines, gamma)
    assert np.all(np.isfinite(values)) and np.all(values > 0.0) and np.all(np.diff(values) > 0.0)
    assert np.all(values >= sines)  # never more air than Riley's flat earth
    np.testing.assert_allclose(1.0 / air_sine(0.0, gamma), horizon_air_mass(gamma), rtol=1e-12)
    np.testing.assert_allclose(horizon_air_mass(gamma), 35.4, atol=0.1)
    high = sines > math.e / horizon_air_mass(gamma)
    np.testing.assert_array_equal(values[high], sines[high])  # the flat earth's value where it is finite enough
    slope = np.diff(values) / np.diff(sines)
    assert np.abs(np.diff(slope)).max() < 1e-3  # smooth: no kink where the two meet


def test_sunlight_fades_with_the_disk_and_keeps_its_direction_above():
    from warpsky.light.sun import sun_sunlight

    for elevation_deg, visible in [(-0.3, 0.0), (0.0, 0.5), (0.3, 1.0), (20.0, 1.0)]:
        sun = Sun(sun_towards(elevation_deg), np.array([1.0, 0.5, 0.25]), math.radians(SUN_ANGLE_DEG))
        light = sun_sunlight(sun, horizon=True)
        assert light.visible == pytest.approx(visible)
        np.testing.assert_allclose(light.irradiance, sun.irradiance * visible)
        np.testing.assert_allclose(np.linalg.norm(light.direction), 1.0)
        assert light.lit == (visible > 0.0)
        if visible == 1.0:
            np.testing.assert_array_equal(light.direction, sun.direction)  # unchanged above the horizon
        elif visible > 0.0:
            assert light.direction[1] > max(sun.direction[1], 0.0)  # the visible part's centroid
        unhidden = sun_sunlight(sun, horizon=False)  # no ground, no air: the sun lights from anywhere
        np.testing.assert_array_equal(unhidden.irradiance, sun.irradiance)
        np.testing.assert_array_equal(unhidden.direction, sun.direction)
