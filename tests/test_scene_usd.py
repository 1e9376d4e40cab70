"""USD reading: units and up axis, camera mapping, sun, ground, render settings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import StageSpec, add_field, look_rotation, render_layer, write_stage

from warpsky.usd.stage import StageReader


def cloud_grid(tmp_path):
    rng = np.random.default_rng(3)
    values = rng.random((6, 5, 7)).astype(np.float32)
    path = tmp_path / "cloud.npy"
    np.save(path, values)
    return path


@pytest.mark.parametrize("up,mpu", [("Z", 0.01), ("Z", 1.0), ("Y", 0.3048)])
def test_units_and_up_axis_render_the_same(tmp_path, device, up, mpu):
    spec = StageSpec(volume_file=cloud_grid(tmp_path), camera_position=(8.0, 12.0, 45.0),
                     camera_rotation=look_rotation((-0.15, -0.25, -1.0)), sun_direction=(0.5, 0.7, -0.2),
                     volume_translate=(2.0, 1.0, -3.0), phase="hg", g=0.6, ground=(-12.0, 0.4))
    _, ref = render_layer(write_stage(tmp_path / "yup_m.usda", spec), device, 20, 16)
    _, other = render_layer(write_stage(tmp_path / "other.usda", spec, up=up, mpu=mpu), device, 20, 16)
    peak = ref.radiance.max()
    assert peak > 0
    assert np.abs(other.radiance - ref.radiance).max() <= 1e-4 * peak
    assert np.abs(other.transmittance - ref.transmittance).max() <= 1e-4


def block_grid(tmp_path):
    path = tmp_path / "block.npy"
    np.save(path, np.ones((2, 2, 2), dtype=np.float32))
    return path


def deficit_centroid(layer):
    weight = 1.0 - layer.transmittance[..., 1]
    rows, cols = np.indices(weight.shape)
    total = weight.sum()
    assert total > 0, "the block is not visible"
    # pixel (row, col) covers [col, col + 1): its centre is at col + 0.5
    return (weight * (cols + 0.5)).sum() / total, (weight * (rows + 0.5)).sum() / total


@pytest.mark.parametrize("position", [(0.0, 0.0, -50.0), (8.0, 0.0, -50.0), (0.0, 6.0, -50.0), (-5.0, -4.0, -40.0)])
def test_block_lands_on_predicted_pixel(tmp_path, device, position):
    """A camera at the origin looking down -Z: +X is image right, +Y is image up (row 0 at the top)."""
    width, height = 64, 48
    spec = StageSpec(volume_file=block_grid(tmp_path), volume_extent=((-0.5,) * 3, (0.5,) * 3),
                     volume_translate=position, camera_position=(0.0, 0.0, 0.0), aperture=(36.0, 27.0),
                     focal_length=35.0, extinction_scale=2.0)
    _, layer = render_layer(write_stage(tmp_path / "block.usda", spec), device, width, height)
    x, y, z = position
    # Independent pinhole projection: screen = focal * (x, y) / depth, mapped to pixels with row 0 on top.
    expected_col = (0.5 + 35.0 * x / -z / 36.0) * width
    expected_row = (0.5 - 35.0 * y / -z / 27.0) * height
    col, row = deficit_centroid(layer)
    assert col == pytest.approx(expected_col, abs=0.35)
    assert row == pytest.approx(expected_row, abs=0.35)


def test_sun_direction_irradiance_and_angle(tmp_path):
    from pxr import Gf, Usd, UsdGeom, UsdLux

    path = tmp_path / "sun.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.Camera.Define(stage, "/Cam")
    light = UsdLux.DistantLight.Define(stage, "/Sun")
    light.CreateIntensityAttr(2.0)
    light.CreateExposureAttr(1.5)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.5, 0.25))
    light.CreateAngleAttr(1.0)
    # Rotating the light 30 deg about X tips its +Z (the way to the sun) towards stage -Y.
    light.AddRotateXOp().Set(30.0)
    stage.GetRootLayer().Save()
    sun = StageReader(path).read_sun()
    zup = np.array([0.0, -math.sin(math.radians(30)), math.cos(math.radians(30))])
    np.testing.assert_allclose(sun.direction, [zup[0], zup[2], -zup[1]], atol=1e-6)
    np.testing.assert_allclose(sun.irradiance, 2.0 * 2**1.5 * np.array([1.0, 0.5, 0.25]), rtol=1e-6)
    assert sun.angular_diameter == pytest.approx(math.radians(1.0))


def test_render_settings_give_resolution_and_camera(tmp_path):
    from pxr import Gf, Usd, UsdGeom, UsdRender

    path = tmp_path / "rs.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Camera.Define(stage, "/A")
    UsdGeom.Camera.Define(stage, "/B")
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(320, 200))
    settings.CreateCameraRel().SetTargets(["/B"])
    stage.GetRootLayer().Save()
    reader = StageReader(path)
    assert reader.render_settings() == ((320, 200), "/B")
    assert reader.scene_at().camera.name == "/B"


def test_time_sampled_file_path_picks_per_frame_files(tmp_path):
    from pxr import Sdf, Usd, UsdVol

    for frame, value in ((1, 1.0), (2, 3.0)):
        np.save(tmp_path / f"d.{frame}.npy", np.full((2, 2, 2), value, dtype=np.float32))
    spec = StageSpec(volume_file=tmp_path / "d.1.npy")
    path = write_stage(tmp_path / "anim.usda", spec)
    stage = Usd.Stage.Open(str(path))
    attr = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Cloud/density")).GetFilePathAttr()
    attr.Clear()
    attr.Set(Sdf.AssetPath(str(tmp_path / "d.1.npy")), 1.0)
    attr.Set(Sdf.AssetPath(str(tmp_path / "d.2.npy")), 2.0)
    stage.Save()
    reader = StageReader(path)
    assert reader.read_media(1.0)[0].density.max() == 1.0
    assert reader.read_media(2.0)[0].density.max() == 3.0
    assert reader.read_media(7.0)[0].density.max() == 3.0  # held, not interpolated


def test_species_fields_become_media_with_their_cross_sections(tmp_path, homogeneous_npy):
    path = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, extinction_scale=0.25))
    add_field(path, "rain", homogeneous_npy, quantity="concentration", scale=2.0)
    add_field(path, "ice", homogeneous_npy, scale=0.5)
    add_field(path, "temperature", homogeneous_npy)  # not rendered, ignored
    media = {m.name: m for m in StageReader(path).read_media()}
    assert set(media) == {"/World/Cloud", "/World/Cloud:rain", "/World/Cloud:ice"}
    assert media["/World/Cloud"].species is None
    np.testing.assert_allclose(media["/World/Cloud"].extinction_scale, 0.25)
    assert media["/World/Cloud:rain"].species == "rain"
    np.testing.assert_allclose(media["/World/Cloud:rain"].extinction_scale, 2.0 * 6.28e-6)  # Riley Table 2
    np.testing.assert_allclose(media["/World/Cloud:ice"].extinction_scale, 0.5)
    np.testing.assert_array_equal(media["/World/Cloud:ice"].world_from_index, media["/World/Cloud"].world_from_index)


@pytest.mark.parametrize("field,quantity,message", [
    ("rain", "mass", "warpsky:quantity"), ("density", "concentration", "needs a species field"),
])
def test_bad_quantity(tmp_path, homogeneous_npy, field, quantity, message):
    from pxr import Sdf, Usd

    from warpsky.core.errors import SceneError

    path = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))
    if field == "density":
        stage = Usd.Stage.Open(str(path))
        stage.GetPrimAtPath("/World/Cloud/density").CreateAttribute(
            "warpsky:quantity", Sdf.ValueTypeNames.Token).Set(quantity)
        stage.Save()
    else:
        add_field(path, field, homogeneous_npy, quantity=quantity)
    with pytest.raises(SceneError, match=message):
        StageReader(path).read_media()
