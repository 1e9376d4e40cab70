"""The simulated storm's rainbow shot: the bow's geometry against vectors computed here, the shaft found in a frame,
and the stage's camera, sun and detail."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpsky.simulate import shot
from warpsky.usd.weather.weather_usd import sun_direction


def direction(elevation: float, azimuth: float) -> np.ndarray:
    """Unit vector (east, north, up) at ``elevation`` over the horizon, ``azimuth`` clockwise from north [deg]."""
    return sun_direction(elevation, azimuth)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0)))


def test_bow_azimuth_puts_the_direction_on_the_bow():
    """A direction at the bow azimuth from the antisolar point lies 42 deg from it, for several sun and view
    elevations; at the horizon with the sun on it, the bow's foot is 42 deg along it."""
    for sun_elevation in (5.0, 12.0, 30.0):
        antisolar = -direction(sun_elevation, 180.0)
        for elevation in (0.0, 3.0, 10.0):
            view = direction(elevation, shot.bow_azimuth(sun_elevation, elevation))
            assert abs(angle(view, antisolar) - shot.RAINBOW_DEG) < 1.0e-6
    assert abs(shot.bow_azimuth(0.0, 0.0) - shot.RAINBOW_DEG) < 1.0e-9


def test_the_camera_sees_the_bow_in_the_shaft_with_the_sun_at_its_back():
    """From the shot's eye, the point halfway up the shaft under its base lies 42 deg from the antisolar point; the
    sun is behind the camera; the view looks up by the pitch and the shaft lies inside the field of view."""
    sun = shot.shot_sun()
    shaft = shot.Shaft((3000.0, -2000.0), 1200.0)
    eye, target = shot.shot_camera(shaft, sun)
    mid = np.array([*shaft.centre, 0.5 * shaft.base])
    towards_sun = sun_direction(*sun)
    assert abs(angle(mid - eye, -towards_sun) - shot.RAINBOW_DEG) < 1.0e-6
    view = target - eye
    assert np.dot(view, towards_sun) < 0.0
    assert abs(math.degrees(math.asin(view[2] / np.linalg.norm(view))) - shot.PITCH) < 1.0e-6
    half_height = math.degrees(math.atan(0.5 * shot.APERTURE[1] / shot.FOCAL_LENGTH))
    assert angle(mid - eye, view) < half_height
    assert abs(np.linalg.norm((mid - eye)[:2]) - shot.DISTANCE) < 1.0e-6


def test_the_shaft_is_the_rain_under_the_cloud():
    """Rain in the lowest levels of columns around (east 2, north -1) km under a cloud whose base is level 4 (500 m
    levels): the shaft's centre is the rain's centre and its base the lowest cloudy level's bottom; with no rain,
    the cloud's centre; with nothing, the grid's middle."""
    origin, spacing = np.array([-5000.0, -5000.0, 250.0]), np.array([1000.0, 1000.0, 500.0])
    cloud, rain = np.zeros((11, 11, 20)), np.zeros((11, 11, 20))
    cloud[6:9, 3:6, 4:15] = 0.02
    rain[6:9, 3:6, 0:4] = 1.0e-3
    found = shot.find_shaft({"cloud": cloud, "rain": rain}, origin, spacing)
    np.testing.assert_allclose(found.centre, (2000.0, -1000.0))
    assert found.base == 2000.0
    dry = shot.find_shaft({"cloud": cloud, "rain": np.zeros_like(rain)}, origin, spacing)
    np.testing.assert_allclose(dry.centre, (2000.0, -1000.0))
    clear = shot.find_shaft({"cloud": np.zeros_like(cloud)}, origin, spacing)
    np.testing.assert_allclose(clear.centre, (0.0, 0.0))


def test_the_storm_camera_follows_the_grid_and_the_fields_get_their_edges(tmp_path):
    """Two frames of a grid moving east at 10 m/s: ``/World/StormCam`` stands the storm distance south of each
    frame's grid middle at its eye height, looks north at the aim height over that middle and moves with the grid;
    the cloud, ice and snow fields carry their edges (rain none) and the renderer reads them into the detail."""
    from pxr import Gf, Usd, UsdGeom

    from warpsky.simulate.frames import FrameWriter, weather_state
    from warpsky.simulate.sounding import base_state, weisman_klemp
    from warpsky.usd.stage import StageReader

    shape = (10, 8, 12)
    base = base_state(weisman_klemp(), shape[1], 500.0)
    writer = FrameWriter(tmp_path / "f", tmp_path / "f.usda", 60.0)
    for t in (60.0, 120.0):
        fields = {"theta": np.broadcast_to(base.theta[None, :, None], shape).copy(),
                  "vapour": np.broadcast_to(base.vapour[None, :, None], shape).copy(),
                  "cloud": np.zeros(shape), "rain": np.zeros(shape),
                  "velocity": np.zeros((*shape, 3), np.float32)}
        fields["cloud"][4:7, 2:5, 5:8] = 1.0e-3
        fields["rain"][4:7, 0:2, 5:8] = 1.0e-3
        writer.write(weather_state(fields, base, (1000.0, 500.0), t, (10.0, 0.0)))
    stage = Usd.Stage.Open(str(tmp_path / "f.usda"))
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/StormCam"))
    assert cam and cam.GetFocalLengthAttr().Get() == shot.STORM_FOCAL_LENGTH
    eyes = []
    for code, middle in zip((1.0, 2.0), writer.middles, strict=True):
        world = cam.GetLocalTransformation(code)
        eye = np.array(world.ExtractTranslation())
        look = np.array(world.TransformDir(Gf.Vec3d(0.0, 0.0, -1.0)))
        np.testing.assert_allclose(eye, [middle[0], middle[1] - shot.STORM_DISTANCE, shot.STORM_EYE_HEIGHT],
                                   atol=1e-6)
        aim = np.array([0.0, shot.STORM_DISTANCE, shot.STORM_AIM - shot.STORM_EYE_HEIGHT])
        assert angle(look, aim) < 1.0e-6
        eyes.append(eye)
    np.testing.assert_allclose(eyes[1] - eyes[0], [600.0, 0.0, 0.0], atol=1e-6)  # 60 s at 10 m/s
    media = {m.species: m for m in StageReader(tmp_path / "f.usda").scene_at(2.0).media}
    assert media["cloud"].detail.edge == pytest.approx(shot.EDGES["cloud"])
    assert media["rain"].detail.edge == 0.0
