"""Sharp halo edges in the kernels' oriented-ice lookup: the random crystals' 22° halo where the species table puts
its inner edge (not on the sky bins), the upper tangent arc's lower edge resolved by the frame's finer bins, and
the mixed lookup still normalised over the sphere."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from test_oriented_render import sheet_stage

from warpsky.optics.grid import angle_grid
from warpsky.optics.ice import ice_refractive_index
from warpsky.optics.oriented_phase import OrientedPhases, frame_bins, oriented_phases, oriented_value
from warpsky.usd.stage import StageReader

SUN_ELEVATION = 8.0  # deg, as in usd_scenes/sundogs.usda
PHOTONS = 2_000_000  # per channel: enough to place a sharp edge, a few seconds on two CPU cores


@wp.kernel
def lookup_kernel(phases: OrientedPhases, looks: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = oriented_value(phases, 0, looks[i])


def lookup(phases: OrientedPhases, looks: np.ndarray, device: str) -> np.ndarray:
    """(N, 3) phase [1/sr] of slice 0 along (N, 3) world look directions."""
    out = wp.zeros(len(looks), dtype=wp.vec3, device=device)
    wp.launch(lookup_kernel, dim=len(looks), device=device,
              inputs=[phases, wp.array(np.asarray(looks, dtype=np.float32), dtype=wp.vec3, device=device), out])
    return out.numpy().astype(np.float64)


def sun_direction() -> np.ndarray:
    """Towards the sun, SUN_ELEVATION up at azimuth -Z (the stage's DistantLight, rotated (-e, 180, 0))."""
    e = math.radians(SUN_ELEVATION)
    return np.array([0.0, math.sin(e), -math.cos(e)])


def around_sun(distances_deg: np.ndarray, position_angle_deg: float) -> np.ndarray:
    """(N, 3) directions at angular distances from the sun, at a position angle from straight above it."""
    sun = sun_direction()
    up = np.array([0.0, math.cos(math.radians(SUN_ELEVATION)), math.sin(math.radians(SUN_ELEVATION))])
    side = np.cross(sun, up)
    a = math.radians(position_angle_deg)
    d = np.radians(distances_deg)[:, None]
    return np.cos(d) * sun + np.sin(d) * (math.cos(a) * up + math.sin(a) * side)


def steepest_rise(distances_deg: np.ndarray, values: np.ndarray) -> float:
    """Distance [deg] halfway across the largest increase between neighbouring samples."""
    k = int(np.argmax(np.diff(values)))
    return 0.5 * (distances_deg[k] + distances_deg[k + 1])


def ice_sheet(tmp_path, orientation: str, habit: str, fraction: float) -> str:
    """The oriented-ice sheet of the renderer tests with crystals of ``orientation``/``habit`` tilted 0.5°, a
    ``fraction`` of them oriented, the sun SUN_ELEVATION up (the lookup reads only the sun and the crystals)."""
    attributes = (f'token warpsky:ice:orientation = "{orientation}"\n            token warpsky:ice:habit = "{habit}"'
                  f'\n            float warpsky:ice:tilt = 0.5\n            float warpsky:ice:fraction = {fraction}')
    return sheet_stage(tmp_path / f"{orientation}.usda", attributes=attributes, sun=SUN_ELEVATION)


@pytest.fixture
def few_photons(monkeypatch):
    from warpsky.optics import oriented_phase

    monkeypatch.setattr(oriented_phase, "FRAME_PHOTONS", PHOTONS)


@pytest.mark.slow
def test_random_crystals_22_degree_halo_keeps_the_species_table_inner_edge(tmp_path, device, optics_cache,
                                                                         species_phase, few_photons):
    """Plates mixed with random columns, as in the sundogs stage: away from the plates' arcs, the lookup's 22°
    halo rises where the ``ice`` table rises (its 0.1° nodes), at every position angle alike, and between the
    nodes it is continuous. Mixed on the sky bins, the edge sat where the bins put it: up to half a degree off,
    differently at neighbouring position angles (the steps of the halo's inner edge)."""
    stage = ice_sheet(tmp_path, "plate", "plate", 0.6)
    phases = oriented_phases(StageReader(stage).scene_at(None), device)
    distances = np.arange(20.5, 23.0, 0.01)
    table = np.interp(np.radians(distances), angle_grid(), species_phase("ice")[1])
    expected = steepest_rise(distances, table)
    edges = []
    for angle in np.arange(40.0, 60.0, 0.7):  # between the upper tangent region and the parhelia
        green = lookup(phases, around_sun(distances, angle), device)[:, 1]
        edges.append(steepest_rise(distances, green))
        assert np.max(np.abs(np.diff(green))) < 0.2 * (table.max() - table.min())  # no jump: a continuous lookup
    assert np.max(np.abs(np.array(edges) - expected)) < 0.1, (expected, edges)


@pytest.mark.slow
def test_upper_tangent_arc_lower_edge_is_sharp_and_at_minimum_deviation(tmp_path, device, optics_cache,
                                                                       few_photons):
    """Horizontal columns: straight above the sun the upper tangent arc's lower edge sits at the 60° prism's
    minimum deviation 2 asin(n / 2) - 60° (red, 650 nm: 21.7°) within a bin, and rises from a tenth to nine
    tenths of its peak within 0.5°, which the frame's 0.25° bins resolve; bilinear between 1° bins it took a
    degree."""
    stage = ice_sheet(tmp_path, "column", "column", 1.0)
    phases = oriented_phases(StageReader(stage).scene_at(None), device)
    distances = np.arange(20.0, 24.0, 0.01)
    red = lookup(phases, around_sun(distances, 0.0), device)[:, 0]
    peak = int(np.argmax(red))
    rising = red[:peak + 1]
    low = distances[np.nonzero(rising < 0.1 * red[peak])[0][-1]]
    high = distances[np.nonzero(rising < 0.9 * red[peak])[0][-1]]
    assert high - low < 0.5, (low, high)
    n = float(ice_refractive_index(650e-9))
    closed_form = math.degrees(2.0 * math.asin(n / 2.0)) - 60.0
    assert abs(0.5 * (low + high) - closed_form) < frame_bins().elevation_step_deg, (low, high, closed_form)


@pytest.mark.slow
def test_mixed_lookup_integrates_to_one_over_the_sphere(tmp_path, device, optics_cache, few_photons):
    """The oriented table normalised on its bins and the random table normalised on the angle grid, mixed by
    their shares: the lookup integrated over the sphere (midpoint rule in elevation and azimuth, 0.05° near the
    sun, where the diffraction peak is) is 1 in every channel within 1 %."""
    stage = ice_sheet(tmp_path, "plate", "plate", 0.6)
    phases = oriented_phases(StageReader(stage).scene_at(None), device)
    sun = sun_direction()
    total = np.zeros(3)
    for lo, hi, step in ((0.0, 5.0, 0.05), (5.0, 180.0, 0.25)):  # angular distance from the sun [deg]
        distances = np.arange(lo + 0.5 * step, hi, step)
        ring = np.arange(0.0, 360.0, 0.5) + 0.25
        d, a = np.meshgrid(distances, ring, indexing="ij")
        up = np.cross(np.cross(sun, [0.0, 1.0, 0.0]), sun)
        up /= np.linalg.norm(up)
        side = np.cross(sun, up)
        theta, phi = np.radians(d.reshape(-1))[:, None], np.radians(a.reshape(-1))[:, None]
        looks = np.cos(theta) * sun + np.sin(theta) * (np.cos(phi) * up + np.sin(phi) * side)
        values = lookup(phases, looks, device)
        solid = np.sin(np.radians(d.reshape(-1))) * math.radians(step) * math.radians(0.5)
        total += (values * solid[:, None]).sum(axis=0)
    np.testing.assert_allclose(total, 1.0, rtol=0.01)
