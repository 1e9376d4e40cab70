"""Rendering a stratiform layer over a textured ground: radiosity paints the ground's colour on the cloud base,
cover 0% and 100%, views from below and above."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.media.stratiform.thickness import procedural_thickness
from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun
from warpsky.model.stratiform import GroundTexture, StratiformLayer
from warpsky.passes.stratiform.stratiform import Stratiform, StratiformSettings

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


def _overcast_from_below(thickness, device, *, camera_xz=(0.0, 0.0), size=128):
    """Render an overcast of 100 m texels at 1.5 km (``thickness`` [m] per texel, centred above the origin) from a
    camera on the ground at ``camera_xz`` looking straight up. Returns (scene, layer, the uniform sky [blue] the
    layer is lit by, each pixel's (x, z) offset from the camera on the cloud base in texels)."""
    from warpsky.passes.stratiform.stratiform import sky_radiance

    texels, texel, base = thickness.shape[0], 100.0, 1500.0
    layer = StratiformLayer(thickness.astype(np.float32), base, (-texels * texel / 2,) * 2, (texels * texel,) * 2)
    cam = Camera("c", np.array([camera_xz[0], 0.0, camera_xz[1]]), look_rotation((0.0, 1.0, 0.0)), 40.0, 36.0,
                 36.0, far=1e5)
    scene = Scene(cam, Sun((0.3, 0.8, 0.2), (1.0, 1.0, 1.0)), atmosphere=Atmosphere())
    out = Stratiform(device=device).render(scene, size, size, layer=layer)
    camera = scene.camera.conformed(size, size)
    rows, cols = np.mgrid[0:size, 0:size]
    d = np.stack([camera.pixel_direction(c + 0.5, r + 0.5, size, size) for r, c in zip(rows.ravel(), cols.ravel(),
                                                                                        strict=True)])
    offset = (d[:, [0, 2]] * (base / d[:, 1:2]) / texel).reshape(size, size, 2)
    return scene, out, float(sky_radiance(scene, base + float(thickness.max()))[2]), offset


def test_vanishing_layer_fades_into_the_sky_behind_it(device):
    """A 1 cm overcast (optical depth ~5e-4) composited over the uniform sky it is lit by shows that sky, plus the
    little sunlight it scatters (up to 3% of the sky towards the sun). It used to add the unscattered sky a second
    time (twice the sky), which drew a hard line wherever the thickness reached 0."""
    _, out, sky, _ = _overcast_from_below(np.full((8, 8), 0.01), device)
    image = out.radiance[..., 2] + out.transmittance[..., 2] * sky
    np.testing.assert_allclose(image, sky, rtol=0.05)


def test_single_clear_texel_opens_a_round_hole_about_a_texel_wide(device):
    """One clear texel in a 300 m overcast (optical depth ~14): the hole's edge lies halfway to the cloudy texel
    centres, 0.5 texel out along the map's axes and 0.41 along the diagonals, and the opacity rises monotonically
    outwards. Interpolating the clear texel as 0 m left the rest of its footprint thick enough to be opaque, a
    pinhole 0.04 texel in radius, and made every hole's outline follow the squares of its clear texels."""
    thickness = np.full((24, 24), 300.0)
    thickness[12, 12] = 0.0  # its centre lies 0.5 texel from the map's centre along x and z
    size = 256
    _, out, _, offset = _overcast_from_below(thickness, device, camera_xz=(50.0, 50.0), size=size)
    opacity = 1.0 - out.transmittance[..., 2]
    half = size // 2
    for axis, (rows, cols) in (("axis", (np.full(half, half), np.arange(half, size))),
                               ("diagonal", (np.arange(half, size), np.arange(half, size)))):
        radius = np.hypot(*offset[rows, cols].T)
        profile = opacity[rows, cols]
        assert np.diff(profile).min() >= -1e-4, axis
        edge = np.interp(0.5, profile, radius)  # where the opacity crosses 1/2, between pixels
        print(f"hole edge along the {axis}: {edge:.3f} texel")
        assert abs(edge - (0.5 if axis == "axis" else 0.414)) < 0.06, (axis, edge)
