"""The conversion of a warpsky scene to Blender Cycles (evaluation/cycles_scene.py), checked without Blender: rays
through Blender's camera equal warpsky's pixel rays turned to Z up, the sun lamp points at the sun with the same
irradiance, the volume material gives back the medium's scattering and absorption coefficients, and the derived
sun-only stage of the benchmark holds nothing Cycles is not given."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from evaluation.cycles_scene import (  # noqa: E402
    BLENDER_FROM_WARPSKY,
    camera_description,
    medium_description,
    sun_description,
    write_description,
)
from warpsky.model.camera import Camera  # noqa: E402
from warpsky.model.lights import Sun  # noqa: E402
from warpsky.model.scene import PhaseModel, VoxelMedium  # noqa: E402


def _rotation_x(degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _blender_rays(spec: dict, width: int, height: int) -> np.ndarray:
    """(H, W, 3) world ray directions of Blender's perspective camera with a horizontal sensor fit: the sensor
    width spans the image width; shifts are in sensor widths (Blender's BKE_camera_params_compute_viewplane)."""
    x = ((np.arange(width) + 0.5) / width - 0.5 + spec["shift_x"]) * spec["sensor_width"]
    y = ((0.5 - (np.arange(height) + 0.5) / height) * height / width + spec["shift_y"]) * spec["sensor_width"]
    local = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -spec["lens"]), axis=-1)
    rays = local @ np.asarray(spec["matrix_world"])[:3, :3].T
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def test_the_frame_turns_y_up_to_z_up():
    np.testing.assert_allclose(np.linalg.det(BLENDER_FROM_WARPSKY), 1.0)
    np.testing.assert_allclose(BLENDER_FROM_WARPSKY @ [0, 1, 0], [0, 0, 1])  # up stays up
    np.testing.assert_allclose(BLENDER_FROM_WARPSKY @ [0, 0, 1], [0, -1, 0])  # warpsky's +Z: Blender's -Y


@pytest.mark.parametrize("size", [(128, 128), (96, 64), (64, 96)])
@pytest.mark.parametrize("offsets", [(0.0, 0.0), (0.3, -0.2)])
def test_blender_camera_rays_are_warpskys(size, offsets):
    width, height = size
    camera = Camera(name="cam", position=np.array([10.0, 250.0, 3600.0]), rotation=_rotation_x(12.0),
                    focal_length=2.8, horizontal_aperture=3.6, vertical_aperture=2.4,
                    horizontal_aperture_offset=offsets[0], vertical_aperture_offset=offsets[1])
    spec = camera_description(camera, width, height)
    conformed = camera.conformed(width, height)
    expected = np.array([[conformed.pixel_direction(x + 0.5, y + 0.5, width, height) for x in range(width)]
                         for y in range(height)]) @ BLENDER_FROM_WARPSKY.T
    np.testing.assert_allclose(_blender_rays(spec, width, height), expected, atol=1e-9)
    np.testing.assert_allclose(np.asarray(spec["matrix_world"])[:3, 3], BLENDER_FROM_WARPSKY @ camera.position)


def test_sun_lamp_points_at_the_sun_with_its_irradiance():
    direction = np.array([-0.80670728, 0.57357644, -0.14224426])
    sun = Sun(direction=direction, irradiance=np.array([1.0, 0.97, 0.92]))
    spec = sun_description(sun)
    rotation = np.asarray(spec["matrix_world"])[:3, :3]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0)
    # a Sun lamp shines down its local -Z: its +Z points at the sun
    np.testing.assert_allclose(rotation[:, 2], BLENDER_FROM_WARPSKY @ direction / np.linalg.norm(direction),
                               atol=1e-7)
    np.testing.assert_allclose(spec["strength"] * np.asarray(spec["color"]), [1.0, 0.97, 0.92])
    assert max(spec["color"]) == 1.0 and spec["angle"] == 0.0


def test_volume_material_gives_back_the_coefficients():
    extinction, albedo = np.array([0.02, 0.01, 0.015]), np.array([0.9, 1.0, 0.5])
    world_from_index = np.array([[12.5, 0, 0, -1206.25], [0, 12.5, 0, 993.75], [0, 0, 12.5, -1206.25], [0, 0, 0, 1]])
    medium = VoxelMedium(name="cloud", density=np.ones((2, 2, 2), np.float32), world_from_index=world_from_index,
                         extinction_scale=extinction, albedo=albedo, phase=PhaseModel(g=0.7))
    spec = medium_description(medium)
    scale = spec["density_scale"]
    scattering = scale * np.asarray(spec["scatter_color"])  # Volume Scatter: sigma_s = density * colour
    absorption = scale * (1.0 - np.asarray(spec["absorption_color"]))  # Volume Absorption: density * (1 - colour)
    np.testing.assert_allclose(scattering, albedo * extinction)
    np.testing.assert_allclose(scattering + absorption, extinction)
    assert spec["g"] == pytest.approx(0.7)
    index = np.array([3.0, 5.0, 7.0, 1.0])
    np.testing.assert_allclose(np.asarray(spec["vdb_matrix"]) @ index,
                               np.append(BLENDER_FROM_WARPSKY @ (world_from_index @ index)[:3], 1.0))
    with pytest.raises(ValueError, match="Henyey-Greenstein"):
        medium_description(VoxelMedium(name="rain", density=medium.density, world_from_index=world_from_index,
                                       species="rain"))


def test_sun_only_stage_holds_the_cloud_camera_and_sun(tmp_path):
    if not (ROOT / "data" / "cumulus.nvdb").is_file():
        pytest.skip("data/cumulus.nvdb is missing: make data")
    from evaluation.benchmarks.bench_cycles import sun_only_stage
    from warpsky.usd.stage import StageReader

    full = StageReader(ROOT / "usd_scenes" / "cumulus.usda").scene_at(None)
    assert full.atmosphere is not None and full.ground is not None
    with pytest.raises(ValueError, match="nothing else"):
        write_description(full, 32, 32, tmp_path / "full")
    stage = sun_only_stage(ROOT / "usd_scenes" / "cumulus.usda", tmp_path / "sun_only.usda", 32)
    scene = StageReader(stage).scene_at(None)
    assert scene.atmosphere is None and scene.ground is None and scene.resolution == (32, 32)
    np.testing.assert_allclose(scene.sun.direction, full.sun.direction)
    np.testing.assert_array_equal(scene.media[0].density, full.media[0].density)
    description = json.loads(write_description(scene, 32, 32, tmp_path / "cycles").read_text())
    assert description["medium"]["density_scale"] == pytest.approx(0.02)
    assert np.load(tmp_path / "cycles" / description["density"]).shape == full.media[0].density.shape
