"""Rendering a stratiform layer over a textured ground: radiosity paints the ground's colour on the cloud base,
cover 0% and 100%, views from below and above."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.media.stratiform import procedural_thickness
from warpsky.scene.layers import GroundTexture, StratiformLayer
from warpsky.scene.model import Atmosphere, Camera, Ground, Scene, Sun
from warpsky.techniques.stratiform.technique import Stratiform, StratiformSettings

EXTENT = ((-10000.0, -10000.0), (20000.0, 20000.0))


def _scene(position, look):
    cam = Camera("c", np.array(position), look_rotation(look), 20.0, 36.0, 24.0, far=1e5)
    return Scene(cam, Sun((0.3, 0.8, 0.2), (1.0, 1.0, 1.0)), ground=Ground(0.0), atmosphere=Atmosphere())


def _texture(colour):
    return GroundTexture(np.broadcast_to(np.float32(colour), (8, 8, 3)).copy(), *EXTENT)


def _render(scene, thickness, texture, radiosity, device):
    layer = StratiformLayer(thickness, 1500.0, *EXTENT)
    return Stratiform(StratiformSettings(radiosity=radiosity), device=device).render(scene, 24, 16, layer=layer,
                                                                                     ground_texture=texture)


def test_ground_colour_reaches_the_cloud_base(device):
    scene = _scene((0.0, 2.0, 0.0), (0.0, 1.0, -0.2))  # looking up at an overcast base
    overcast = np.full((32, 32), 300.0, np.float32)
    snow = _render(scene, overcast, _texture((0.9, 0.9, 0.9)), 1, device)
    water = _render(scene, overcast, _texture((0.05, 0.08, 0.12)), 1, device)
    off = _render(scene, overcast, _texture((0.9, 0.9, 0.9)), 0, device)
    for layer in (snow, water, off):
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
    assert snow.stats["radiosity_converged"] and snow.stats["radiosity_iterations"] >= 2
    # ice blink: the base over snow is brighter than over water, and brighter than without radiosity
    assert snow.radiance.mean() > 1.2 * water.radiance.mean()
    assert snow.radiance.mean() > 1.2 * off.radiance.mean()
    # a 300 m cloud lets the direct beam through at τ(H_v) only
    assert snow.transmittance.max() < 1e-3


@pytest.mark.parametrize("cover", [0.0, 1.0])
def test_cover_extremes_from_below_and_above(device, cover):
    thickness = procedural_thickness(32, cover=cover, max_thickness=400.0, seed=1)
    for position, look in (((0.0, 2.0, 0.0), (0.0, 1.0, -0.3)), ((0.0, 4000.0, 0.0), (0.0, -1.0, -0.3))):
        layer = _render(_scene(position, look), thickness, _texture((0.3, 0.3, 0.3)), 1, device)
        assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0
        if cover == 0.0 and position[1] < 10:
            np.testing.assert_allclose(layer.transmittance, 1.0)  # clear sky: nothing in front of it
        if cover == 1.0 and position[1] > 10:
            assert layer.radiance.mean() > 0.05  # a bright cloud top seen from above
