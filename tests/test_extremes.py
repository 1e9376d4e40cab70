"""Stiff and extreme cases: finite, non-negative, bounded output, checked against closed forms where they exist."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, render_layer, write_stage

HALF = 10.0


def assert_sane(layer):
    assert np.all(np.isfinite(layer.radiance)) and np.all(layer.radiance >= 0.0)
    assert np.all(np.isfinite(layer.transmittance))
    assert np.all((layer.transmittance >= 0.0) & (layer.transmittance <= 1.0))
    assert np.all(np.isfinite(layer.depth))


@pytest.mark.parametrize("tau_step", [1e-9, 1e-6, 1e-3, 1.0, 1e3, 1e5])
def test_optical_depth_per_step_from_1e_minus_9_to_1e5(tmp_path, homogeneous_npy, device, tau_step):
    """Front face of a homogeneous box, sun at 36.87 deg from the face normal, isotropic phase.

    Thin: L = E p sigma l exactly to first order. Thick (semi-infinite): L = E p mu0 / (mu0 + mu), mu = 1."""
    step = 0.5
    sigma = tau_step / step
    sun = np.array([0.6, 0.0, 0.8])
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=sigma, camera_position=(0, 0, 30),
                     sun_direction=tuple(sun))
    _, layer = render_layer(write_stage(tmp_path / "s.usda", spec), device, 9, 9, step_length=step,
                            shadow_step_length=step, min_transmittance=0.0)
    assert_sane(layer)
    p = 1.0 / (4.0 * np.pi)
    centre = layer.radiance[4, 4, 0]
    if sigma * 2 * HALF < 1e-4:
        # thin: each point sees the sun nearly unattenuated; first-order closed form, relative error ~ tau
        np.testing.assert_allclose(centre, p * sigma * 2 * HALF, rtol=1e-3)
    elif sigma * 2 * HALF > 50:
        np.testing.assert_allclose(centre, p * 0.8 / 1.8, rtol=1e-4)
        assert np.all(layer.transmittance[4, 4] < 1e-20)


@pytest.mark.parametrize("g", [0.0, 0.5, 0.9])
def test_sun_exactly_behind_the_camera(tmp_path, homogeneous_npy, device, g):
    """Back-scatter from a semi-infinite medium lit along the view: L = E p(180 deg) / 2."""
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=50.0, camera_position=(0, 0, 30),
                     sun_direction=(0.0, 0.0, 1.0), phase="hg", g=g)
    _, layer = render_layer(write_stage(tmp_path / "s.usda", spec), device, 9, 9, step_length=0.2,
                            shadow_step_length=0.2)
    assert_sane(layer)
    p_back = (1 - g * g) / (4 * np.pi * (1 + g) ** 3)
    np.testing.assert_allclose(layer.radiance[4, 4], p_back / 2, rtol=1e-4)


@pytest.mark.parametrize("g", [0.0, 0.85])
def test_sun_exactly_in_front_view_along_the_light(tmp_path, homogeneous_npy, device, g):
    """Looking straight at the sun through a slab: every scattering point has the same total path, so
    L = E p(0) sigma l exp(-sigma l) exactly, with axis-aligned (zero-component) shadow rays."""
    sigma = 0.03
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=sigma, camera_position=(0, 0, 30),
                     sun_direction=(0.0, 0.0, -1.0), phase="hg", g=g, aperture=(1.0, 1.0))
    _, layer = render_layer(write_stage(tmp_path / "s.usda", spec), device, 3, 3, min_transmittance=0.0)
    assert_sane(layer)
    length = 2 * HALF
    p_forward = (1 - g * g) / (4 * np.pi * (1 - g) ** 3)
    np.testing.assert_allclose(layer.radiance[1, 1], p_forward * sigma * length * np.exp(-sigma * length), rtol=1e-4)


def test_camera_inside_the_volume(tmp_path, homogeneous_npy, device):
    sigma = 0.07
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=sigma, camera_position=(1.0, -2.0, 3.0))
    scene, layer = render_layer(write_stage(tmp_path / "s.usda", spec), device, 15, 15, min_transmittance=0.0)
    assert_sane(layer)
    cam = scene.camera.conformed(15, 15)
    for row, col in [(7, 7), (0, 0), (14, 3), (5, 11)]:
        d = cam.pixel_direction(col + 0.5, row + 0.5, 15, 15)
        with np.errstate(divide="ignore"):
            exits = np.where(d > 0, (HALF - cam.position) / d, np.where(d < 0, (-HALF - cam.position) / d, np.inf))
        exit_t = exits.min()
        start = cam.near / np.dot(d, cam.forward)
        np.testing.assert_allclose(layer.transmittance[row, col], np.exp(-sigma * (exit_t - start)), rtol=1e-4)
    assert layer.radiance[7, 7].sum() > 0


def test_scene_100_km_from_the_origin_renders_the_same(tmp_path, device):
    rng = np.random.default_rng(11)
    grid = tmp_path / "g.npy"
    np.save(grid, rng.random((8, 6, 8)).astype(np.float32))
    images = []
    for offset in (np.zeros(3), np.array([1.0e5, 2.0e4, -1.0e5])):
        spec = StageSpec(volume_file=grid, camera_position=tuple(np.array([4.0, 3.0, 45.0]) + offset),
                         volume_translate=tuple(offset), ground=(offset[1] - 12.0, 0.3), phase="hg", g=0.7)
        _, layer = render_layer(write_stage(tmp_path / f"s{offset[0]:g}.usda", spec), device, 16, 16)
        assert_sane(layer)
        images.append(layer)
    peak = images[0].radiance.max()
    assert np.abs(images[1].radiance - images[0].radiance).max() <= 1e-4 * peak
    assert np.abs(images[1].transmittance - images[0].transmittance).max() <= 1e-4


@pytest.mark.parametrize("elevation_deg", [0.0, -0.0, -5.0, 1e-6])
def test_sun_on_or_below_the_horizon_with_ground(tmp_path, homogeneous_npy, device, elevation_deg):
    el = np.radians(elevation_deg)
    spec = StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40), ground=(-10.0, 0.95),
                     sun_direction=(np.cos(el), np.sin(el), 0.0))
    _, layer = render_layer(write_stage(tmp_path / "s.usda", spec), device, 12, 12)
    assert_sane(layer)
    if elevation_deg < 0:
        assert np.all(layer.radiance == 0.0)  # the ground hides the sun from everything above it
