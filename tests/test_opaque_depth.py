"""A volume cut by an opaque mesh: the media's camera rays end at the surface the surfaces pass drew, so the part
of the volume in front of the mesh shows over it and the part behind it is hidden, pixel by pixel."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.model.scene import Camera, Scene, Sun, VoxelMedium
from warpsky.model.terrain import TerrainMesh
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan

SIZE = 24
SIGMA = 0.05  # 1/m


def box(z0: float, z1: float) -> VoxelMedium:
    """A homogeneous 20 x 20 m box (x, y in -10..10 m) from z0 to z1, one voxel deep per 5 m."""
    depth = int(round((z1 - z0) / 5.0))
    world_from_index = np.diag([5.0, 5.0, 5.0, 1.0])
    world_from_index[:3, 3] = [-10.0 + 2.5, -10.0 + 2.5, z0 + 2.5]
    return VoxelMedium("box", np.ones((4, 4, depth), np.float32), world_from_index, np.full(3, SIGMA), np.ones(3))


def frame(media, device: str, technique: str, settings: dict) -> np.ndarray:
    """RGBA of the media in front of a grey wall at z = 0 (60 m from the camera), the sun behind the camera."""
    wall = TerrainMesh("wall", np.array([[-60.0, -60.0, 0.0], [60.0, -60.0, 0.0], [60.0, 60.0, 0.0],
                                         [-60.0, 60.0, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]]), (0.4, 0.4, 0.4))
    sun_direction = np.array([0.0, 0.3, 1.0]) / math.hypot(0.3, 1.0)
    camera = Camera("cam", np.array([0.0, 0.0, 60.0]), look_rotation((0.0, 0.0, -1.0)), 30.0, 36.0, 36.0,
                    near=0.5, far=1.0e4)
    scene = Scene(camera=camera, sun=Sun(sun_direction, np.ones(3)), media=tuple(media), meshes=(wall,))
    plan = make_plan(scene, technique=technique, settings=settings, resolution=(SIZE, SIZE), device=device)
    _, layers = render_layers(plan, scene)
    return composite(layers, far=camera.far).rgba


@pytest.mark.parametrize("technique,settings,rtol", [
    ("single_scatter", {"step_length": "0.25"}, 0.01),
    ("slicing", {"slice_count": "256"}, 0.05),
])
def test_a_volume_straddling_a_wall_shows_its_front_part_only(device, technique, settings, rtol):
    """A box from z = -15 to 5 m through a wall at z = 0 (most of it behind, so as a whole layer it sorted
    behind the wall and vanished) renders as the box's front part alone, z = 0..5 m, in front of the wall: the same
    pixels within the march's discretisation; and the box does show (it darkens the wall where it is)."""
    cut = frame([box(-15.0, 5.0)], device, technique, settings)
    front = frame([box(0.0, 5.0)], device, technique, settings)
    bare = frame([], device, technique, settings)
    centre = (slice(SIZE // 2 - 3, SIZE // 2 + 3),) * 2
    np.testing.assert_allclose(cut[centre], front[centre], rtol=rtol, atol=1e-6)
    assert not np.allclose(cut[centre][..., :3], bare[centre][..., :3], rtol=0.05)


def test_hybrid_paths_end_at_the_wall(device):
    """hybrid (march plus paths for the multiple scattering): the straddling box against the front part alone,
    the same seed: equal within the paths' noise, the light the paths gather behind the wall left out."""
    settings = {"spp": "64", "target_error": "0", "seed": "3", "step_length": "0.5"}
    cut = frame([box(-15.0, 5.0)], device, "hybrid", settings)
    front = frame([box(0.0, 5.0)], device, "hybrid", settings)
    centre = (slice(SIZE // 2 - 3, SIZE // 2 + 3),) * 2
    np.testing.assert_allclose(cut[centre].mean(axis=(0, 1)), front[centre].mean(axis=(0, 1)), rtol=0.03)
