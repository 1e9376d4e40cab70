"""Single scattering against closed forms and an independent quadrature."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, add_field, look_rotation, render_layer, write_stage

SIGMA = 0.05  # extinction of the test box [1/m]
HALF = 10.0  # the box spans [-10, 10]^3 m


def box_interval(origin, direction, lo=-HALF, hi=HALF):
    """Exact ray/box parameter interval in float64."""
    inv = np.divide(1.0, direction, out=np.full(3, np.inf), where=direction != 0)
    t1 = (lo - origin) * inv
    t2 = (hi - origin) * inv
    t_enter = np.max(np.minimum(t1, t2))
    t_exit = np.min(np.maximum(t1, t2))
    return max(t_enter, 0.0), t_exit


@pytest.fixture
def box_stage(tmp_path, homogeneous_npy):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=SIGMA, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3))
    return write_stage(tmp_path / "box.usda", spec), spec


def test_transmittance_is_exp_minus_sigma_length(box_stage, device):
    stage, _ = box_stage
    scene, layer = render_layer(stage, device, 24, 24, min_transmittance=0.0)
    cam = scene.camera.conformed(24, 24)
    checked = 0
    for row in range(0, 24, 3):
        for col in range(0, 24, 3):
            d = cam.pixel_direction(col + 0.5, row + 0.5, 24, 24)
            t0, t1 = box_interval(cam.position, d)
            expected = np.exp(-SIGMA * max(t1 - t0, 0.0))
            np.testing.assert_allclose(layer.transmittance[row, col], expected, rtol=1e-4)
            checked += t1 > t0
    assert checked > 20  # most sampled pixels see the box


def sun_exit_distance(points, sun):
    """Distance from each point (inside the box) to the box boundary along ``sun``, vectorised float64."""
    with np.errstate(divide="ignore"):
        inv = np.where(sun != 0, 1.0 / np.where(sun != 0, sun, 1.0), np.inf)
    far = np.where(sun > 0, HALF, -HALF)
    return np.min(np.where(np.isfinite(inv), (far - points) * inv, np.inf), axis=1)


def single_scatter_quadrature(origin, d, sun, albedo=1.0, pieces=64, nodes=32):
    """Independent reference: composite Gauss-Legendre over the eye segment of the isotropic single-scattering
    integral  int exp(-s(t - t0)) s albedo/(4 pi) exp(-s l_sun(t)) dt."""
    t0, t1 = box_interval(origin, d)
    if t1 <= t0:
        return 0.0
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.linspace(t0, t1, pieces + 1)
    half = 0.5 * np.diff(edges)[:, None]
    t = (half * x + 0.5 * (edges[1:] + edges[:-1])[:, None]).reshape(-1)
    weights = (half * w).reshape(-1)
    points = origin + t[:, None] * d
    sun_depth = SIGMA * sun_exit_distance(points, sun)
    integrand = np.exp(-SIGMA * (t - t0)) * SIGMA * albedo / (4 * np.pi) * np.exp(-sun_depth)
    return float(np.sum(weights * integrand))


def test_single_scattering_matches_quadrature(box_stage, device):
    stage, spec = box_stage
    scene, layer = render_layer(stage, device, 16, 16, step_length=0.05, shadow_step_length=0.05,
                                min_transmittance=0.0)
    cam = scene.camera.conformed(16, 16)
    sun = scene.sun.direction
    for row, col in [(8, 8), (5, 9), (11, 6), (7, 12), (3, 3)]:
        d = cam.pixel_direction(col + 0.5, row + 0.5, 16, 16)
        expected = single_scatter_quadrature(cam.position, d, sun)
        assert expected > 0.0
        np.testing.assert_allclose(layer.radiance[row, col], expected, rtol=1e-3)


def test_radiance_is_linear_in_sun_irradiance(tmp_path, homogeneous_npy, device):
    images = []
    for intensity in (1.0, 3.5):
        spec = StageSpec(volume_file=homogeneous_npy, sun_intensity=intensity, camera_position=(0, 0, 50))
        _, layer = render_layer(write_stage(tmp_path / f"s{intensity}.usda", spec), device, 12, 12)
        images.append(layer.radiance)
    assert images[0].max() > 0
    np.testing.assert_allclose(images[1], 3.5 * images[0], rtol=1e-5, atol=1e-12)


def test_zero_density_gives_exactly_nothing(tmp_path, device):
    grid = tmp_path / "zero.npy"
    np.save(grid, np.zeros((5, 5, 5), dtype=np.float32))
    spec = StageSpec(volume_file=grid, camera_position=(0, 0, 30))
    _, layer = render_layer(write_stage(tmp_path / "zero.usda", spec), device, 12, 12)
    assert np.all(layer.radiance == 0.0)
    assert np.all(layer.transmittance == 1.0)


def test_ground_is_opaque_and_lambertian(tmp_path, device):
    """Without media, the ground's radiance is albedo/pi * E * cos(sun zenith) and blocks the background."""
    grid = tmp_path / "zero.npy"
    np.save(grid, np.zeros((2, 2, 2), dtype=np.float32))
    sun = np.array([0.3, 0.8, 0.1])
    spec = StageSpec(volume_file=grid, camera_position=(0, 20, 0), camera_rotation=look_rotation((0, -1, -1)),
                     sun_direction=tuple(sun), ground=(0.0, 0.5))
    _, layer = render_layer(write_stage(tmp_path / "ground.usda", spec), device, 8, 8)
    cos_zenith = sun[1] / np.linalg.norm(sun)
    np.testing.assert_allclose(layer.radiance[4, 4], 0.5 / np.pi * cos_zenith, rtol=1e-5)
    assert np.all(layer.transmittance[4:] == 0.0)


def test_species_field_scatters_with_its_tabulated_phase(tmp_path, homogeneous_npy, species_phase, device):
    """A cloud field (Mie table) in place of the generic density: the isotropic 1/4pi of the quadrature becomes
    the cloud's phase per channel at each pixel's scattering angle; only cloud tables are built."""
    from warpsky.optics import tables
    from warpsky.optics.grid import angle_grid

    cloud = species_phase("cloud")
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.0, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.1, 0.3, -1.0))
    stage = write_stage(tmp_path / "cloud.usda", spec)
    add_field(stage, "cloud", homogeneous_npy, scale=SIGMA)
    before = len(tables.BUILD_LOG)
    scene, layer = render_layer(stage, device, 16, 16, step_length=0.05, shadow_step_length=0.05,
                                min_transmittance=0.0)
    assert {name for name, _, _ in tables.BUILD_LOG[before:]} <= {"cloud"}
    cam = scene.camera.conformed(16, 16)
    sun = scene.sun.direction
    for row, col in [(8, 8), (5, 9), (11, 6), (3, 3)]:
        d = cam.pixel_direction(col + 0.5, row + 0.5, 16, 16)
        isotropic = single_scatter_quadrature(cam.position, d, sun)
        theta = np.arccos(np.clip(np.dot(sun, d), -1.0, 1.0))  # light travels along -sun, leaves along -d
        phase = np.array([np.interp(theta, angle_grid(), cloud[c]) for c in range(3)])
        np.testing.assert_allclose(layer.radiance[row, col], isotropic * 4 * np.pi * phase, rtol=2e-3)
