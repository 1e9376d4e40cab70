"""The sun's transmittance through stratiform layers on the device (:mod:`warpsky.media.stratiform.stratiform_shadow`)
against the host's closed form, and the fog pass's sunlight in a layer's shadow."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import warp as wp
from conftest import look_rotation

from warpsky.media.stratiform.stratiform_shadow import LayerShadows, layer_shadows, layers_sun_transmittance
from warpsky.media.stratiform.thickness import layer_sun_transmittance
from warpsky.model.fog import AnalyticFog, ConstantTerm
from warpsky.model.scene import Camera, Scene, Sun
from warpsky.model.stratiform import StratiformLayer
from warpsky.passes.fog.fog import Fog


@wp.kernel
def transmittance_kernel(shadows: LayerShadows, points: wp.array(dtype=wp.vec3d), sun: wp.vec3d,
                         out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = layers_sun_transmittance(shadows, points[i], sun)


def broken_layer(name: str, base: float, origin, seed: int) -> StratiformLayer:
    rng = np.random.default_rng(seed)
    thickness = np.clip(rng.normal(40.0, 60.0, (13, 9)), 0.0, None).astype(np.float32)
    return StratiformLayer(thickness, base, origin, (3000.0, 2000.0), name=name)


def test_device_transmittance_equals_the_closed_form(device):
    """Two broken layers (different maps, placements and bases), points below, between and above them, a camera
    100 km from the origin: the device function equals the product of the host's closed forms within 1e-12."""
    layers = (broken_layer("low", 800.0, (1.0e5 - 1500.0, -900.0), 1), broken_layer("high", 1500.0, (1.0e5 - 1000.0,
                                                                                                      -1200.0), 2))
    eye = np.array([1.0e5, 120.0, 30.0])
    rng = np.random.default_rng(3)
    points = eye + np.c_[rng.uniform(-2500.0, 2500.0, 4000), rng.uniform(-200.0, 1600.0, 4000),
                         rng.uniform(-2500.0, 2500.0, 4000)]
    for elevation in (3.0, 35.0, 90.0, -5.0):
        e, a = math.radians(elevation), math.radians(40.0)
        sun = np.array([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])
        expected = np.prod([layer_sun_transmittance(layer, points, sun)[:, 0] for layer in layers], axis=0)
        out = wp.zeros(len(points), dtype=wp.float64, device=device)
        wp.launch(transmittance_kernel, dim=len(points), device=device,
                  inputs=[layer_shadows(layers, eye, device), wp.array(points - eye, dtype=wp.vec3d, device=device),
                          wp.vec3d(*sun.tolist()), out])
        assert np.abs(out.numpy() - expected).max() < 1e-12
        if elevation > 0.0:
            assert expected.min() < 0.5 < expected.max()


def test_fog_sunlight_lies_in_a_uniform_layer_shadow(device):
    """Under a uniform layer of thickness t the fog's single scattering of the sun is exp(-kappa t / sin e) of
    its value without the layer, to rounding (the ambient term off)."""
    fog = AnalyticFog("slab", [ConstantTerm(0.02)], floor=0.0, top=40.0, albedo=np.ones(3), g=0.8)
    camera = Camera("cam", np.array([0.0, 60.0, 0.0]), look_rotation((0.0, -1.0, -0.7)), 24.0, 36.0, 24.0,
                    far=5000.0)
    e = math.radians(30.0)
    scene = Scene(camera, Sun(np.array([0.0, math.sin(e), math.cos(e)]), np.ones(3)), fogs=(fog,))
    layer = StratiformLayer(np.full((4, 4), 50.0, np.float32), 400.0, (-50000.0, -50000.0), (1.0e5, 1.0e5))
    clear = Fog(device=device).render(scene, 16, 12, ambient=np.zeros(3)).radiance
    shaded = Fog(device=device).render(dataclasses.replace(scene, stratiform_layers=(layer,)), 16, 12,
                                       ambient=np.zeros(3)).radiance
    expected = math.exp(-layer.extinction * 50.0 / math.sin(e))
    assert clear.min() > 0.0
    np.testing.assert_allclose(shaded, clear * expected, rtol=1e-5)
