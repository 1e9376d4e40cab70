"""The path-traced reference for stratiform layers: a layer voxelised with exact column optical depths
(warpsky.media.stratiform.stratiform_voxels), traced by the path tracer against a plane-parallel slab solution,
converged in the voxel size, and through ``warpsky render`` / ``info`` / ``bench error-vs-time``."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.core.errors import UsageError
from warpsky.media.stratiform.stratiform_voxels import VOXEL_BUDGET, layer_grid, voxelize_layer
from warpsky.media.stratiform.thickness import procedural_thickness, sample_thickness, signed_thickness
from warpsky.model.lights import Sun
from warpsky.model.scene import Camera, Scene
from warpsky.model.stratiform import StratiformLayer, ThicknessAdvection

KAPPA = 3.0e8 * math.pi * 7.0e-6**2  # the default layer's extinction [1/m]


def holey_layer(**kwargs) -> StratiformLayer:
    """A 16 x 16 texel procedural layer, 40 % clear, over 3.2 x 2.4 km (texels 200 x 150 m) away from the origin."""
    thickness = procedural_thickness(16, cover=0.6, max_thickness=300.0, seed=2, feature_texels=3.0)
    return StratiformLayer(thickness, 1500.0, (1.0e4, -3.0e3), (3200.0, 2400.0), **kwargs)


def column_depth(medium) -> np.ndarray:
    """(n_x, n_z) vertical optical depth through each column centre of the medium's trilinear field: piecewise
    linear between voxel centres, the edge values out to the box, integrated by the trapezoid rule on those nodes
    (exact for a piecewise linear function)."""
    dy = medium.voxel_size[1]
    d = medium.density.astype(np.float64)
    inner = 0.5 * (d[:, 1:, :] + d[:, :-1, :]).sum(axis=1) * dy
    ends = 0.5 * dy * (d[:, 0, :] + d[:, -1, :])
    return medium.extinction_scale[1] * (inner + ends)


# ------------------------------------------------------------------------------------------------ voxelisation
def test_columns_carry_the_exact_optical_depth():
    """Every column's optical depth is κ × thickness at its centre (float precision), whatever the voxel size, on a
    map with holes; the grid's top is the voxel row holding the highest column, densities are fractions in [0, 1]."""
    layer = holey_layer()
    for width, height in ((70.0, 300.0 / 7), (45.0, 9.0), (500.0, 120.0)):
        medium = voxelize_layer(layer, 0.0, width, vertical=height)
        xs, zs = (medium.world_from_index[a, 3] + np.arange(n) * medium.voxel_size[a]
                  for a, n in ((0, medium.shape[0]), (2, medium.shape[2])))
        X, Z = np.meshgrid(xs, zs, indexing="ij")
        expected = KAPPA * sample_thickness(signed_thickness(layer.thickness), layer.origin, layer.size, X, Z)
        assert 0.3 < np.mean(expected == 0.0) < 0.6  # holes are sampled as holes
        np.testing.assert_allclose(column_depth(medium), expected, rtol=2e-6, atol=1e-9)
        assert medium.density.min() >= 0.0 and medium.density.max() == 1.0
        top = medium.world_corners()[:, 1].max() - layer.base_altitude
        assert expected.max() / KAPPA <= top < expected.max() / KAPPA + height
        assert medium.species == "stratus" and np.all(medium.albedo == 1.0)
        assert medium.voxel_size[1] == pytest.approx(height)
        assert np.all(medium.voxel_size[[0, 2]] <= width * (1 + 1e-9))


def test_extinction_volume_equals_the_map_integral():
    """Without holes the map is bilinear between texel centres with constant outer half texels, so its integral is
    exactly texel area × Σ t_ij; voxel columns of half and a quarter texel (midpoint rule on bilinear patches) give
    the same extinction volume κ ∫ t dA to float precision."""
    i, j = np.meshgrid(np.arange(12), np.arange(9), indexing="ij")
    thickness = (120.0 + 60.0 * np.sin(i / 2.0) * np.cos(j / 3.0)).astype(np.float32)
    layer = StratiformLayer(thickness, 800.0, (-600.0, 400.0), (1200.0, 900.0))
    exact = KAPPA * 100.0 * 100.0 * float(thickness.astype(np.float64).sum())
    for width in (50.0, 25.0):
        medium = voxelize_layer(layer, 0.0, width, vertical=13.0)
        volume = float(np.prod(medium.voxel_size)) * float(medium.density.astype(np.float64).sum())
        assert KAPPA * volume == pytest.approx(exact, rel=1e-6)


def test_bounds_keep_the_same_columns_and_the_budget_is_refused():
    layer = holey_layer(name="/World/Deck")
    full = voxelize_layer(layer, 0.0, 100.0, vertical=30.0)
    part = voxelize_layer(layer, 0.0, 100.0, vertical=30.0, bounds=((1.08e4, -2.55e3), (1.15e4, -1.9e3)))
    # columns 8..15 (x) and 4..11 (z) of 100 m from the layer's corner at (1e4, -3e3): the rectangle snapped outwards
    first = np.round((part.world_from_index[[0, 2], 3] - full.world_from_index[[0, 2], 3]) / 100.0).astype(int)
    assert first.tolist() == [8, 4] and part.shape[0] == 7 and part.shape[2] == 7
    rows = part.shape[1]
    np.testing.assert_array_equal(part.density, full.density[8:15, :rows, 4:11])
    assert not full.density[8:15, rows:, 4:11].any()  # the part's top is its own highest column
    with pytest.raises(UsageError, match=r"^stratiform layer /World/Deck: layer_voxel 1 m x 1 m .* over the budget"):
        voxelize_layer(layer, 0.0, 1.0, setting="layer_voxel")
    assert layer_grid(layer, 1.0, max_voxels=2**62).voxels > VOXEL_BUDGET  # counted, nothing allocated
    with pytest.raises(UsageError, match="do not overlap"):
        voxelize_layer(layer, 0.0, 100.0, bounds=((0.0, 0.0), (10.0, 10.0)))


def test_advected_layer_is_voxelised_at_its_time():
    """A wind-only advected map at t: the columns carry the thickness the stratiform pass samples at t."""
    from warpsky.media.stratiform.thickness import at_time

    layer = holey_layer(advection=ThicknessAdvection(wind_m_s=(12.0, -4.0)))
    t = 37.0
    medium = voxelize_layer(layer, t, 100.0, vertical=20.0)
    shown = at_time(dataclasses.replace(layer, time_s=t))
    xs = medium.world_from_index[0, 3] + np.arange(medium.shape[0]) * 100.0
    zs = medium.world_from_index[2, 3] + np.arange(medium.shape[2]) * 100.0
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    expected = KAPPA * sample_thickness(signed_thickness(shown.thickness), layer.origin, layer.size, X, Z)
    np.testing.assert_allclose(column_depth(medium), expected, rtol=2e-6, atol=1e-9)
    still = voxelize_layer(layer, 0.0, 100.0, vertical=20.0)
    assert np.abs(column_depth(still) - expected).max() > 0.1  # it moved


# --------------------------------------------------------------------------------------------- against a slab
def delta_m_slab(tau: float, view_mu) -> tuple[np.ndarray, np.ndarray]:
    """(reflected, diffusely transmitted) radiance of a conservative slab of the ``stratus`` droplets at normal
    incidence by adding-doubling (tests/adding_doubling.py) with the tabulated phase function, delta-M truncated:
    the diffraction peak below 5° (a fraction f of the scattering) is counted as unscattered light, so the slab has
    optical depth (1 - f) τ and the rest of the table renormalised. Checked against the photon Monte Carlo of the
    unmodified table (evaluation.stratiform_reference, 4e6 photons, τ = 2): the bins' radiances agree within
    0.5 %, from 5 to 10° cuts alike."""
    from adding_doubling import slab_radiance

    from warpsky.optics.grid import angle_grid, sphere_integral
    from warpsky.optics.tables import phase_table

    table, theta = phase_table("stratus")[1], angle_grid()
    cut = math.radians(5.0)
    truncated = np.where(theta < cut, np.interp(cut, theta, table), table)
    kept = float(sphere_integral(truncated[None])[0])  # 1 - f

    def phase(cosine):
        return np.interp(np.arccos(np.clip(cosine, -1.0, 1.0)), theta, truncated / kept)

    return slab_radiance(phase, tau * kept, 1.0, view_mu, nodes=96)


@pytest.mark.slow
def test_flat_layer_against_the_slab_solution(device):
    """A flat stratiform layer 10 m thick, 20 km wide, κ chosen for τ = 2, sun at the zenith: the path-traced
    radiance reflected at 60° from the vertical and transmitted at 45.6° (μ = 0.5, 0.7) equals the delta-M
    adding-doubling slab within noise (z < 4, the reference's 0.5 % added in quadrature; measured on the CPU:
    -0.6 % +- 2.1 % and +1.3 % +- 1.2 %), and the noise is small enough (< 3 %) for a 13 % error to fail."""
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    tau, height = 2.0, 10.0
    layer = StratiformLayer(np.full((2, 2), height, np.float32), 0.0, (-1.0e4, -1.0e4), (2.0e4, 2.0e4),
                            number_density=tau / height / (math.pi * 7.0e-6**2))
    reflected, transmitted = delta_m_slab(tau, [0.5, 0.7])
    views = {"reflected": (math.sin(math.radians(60.0)), 0.5, reflected[0]),
             "transmitted": (math.sqrt(1 - 0.7**2), -0.7, transmitted[1])}
    for name, (sideways, mu, expected) in views.items():
        look = np.array([sideways, -mu, 0.0])  # mu > 0: from above looking down; < 0: from below looking up
        camera = Camera("camera", -look * 40.0 + np.array([0.0, 5.0, 0.0]), look_rotation(look), 2000.0, 36.0, 36.0,
                        near=0.1, far=1.0e5)
        scene = Scene(camera, Sun(np.array([0.0, 1.0, 0.0]), np.ones(3)), stratiform_layers=(layer,))
        out = PathTracer(PathTracerSettings(spp=8192, seed=11), device=device).render(scene, 16, 16)
        measured = float(out.radiance[..., 1].mean())
        noise = math.sqrt(float(out.aovs["variance"][..., 1].sum())) / out.radiance[..., 1].size
        print(f"flat layer tau={tau} {name}: path tracer {measured:.5f} +- {noise:.5f}, slab {expected:.5f}")
        assert noise < 0.03 * expected
        z = (measured - expected) / math.hypot(noise, 0.005 * expected)
        assert abs(z) < 4.0, (name, measured, expected, noise)


# ----------------------------------------------------------------------------------------- voxel convergence
@pytest.mark.slow
def test_halving_the_voxels_changes_a_cloudy_region_by_under_5_percent(device):
    """A broken 100 m deck (τ up to 4.6) seen from the ground, the sun 50° up: halving both automatic voxel edges
    (62.5 m x 3.125 m) changes the mean radiance of the pixels the cloud covers by less than 5 % (measured on the
    CPU: -0.2 % +- 1.1 %); the standard error of the difference stays below a third of that."""
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings
    from warpsky.techniques.path_tracer.stratiform_media import layer_voxel_sizes

    thickness = procedural_thickness(32, cover=0.9, max_thickness=100.0, seed=5, feature_texels=6.0)
    layer = StratiformLayer(thickness, 1000.0, (-2000.0, -2000.0), (4000.0, 4000.0))
    look = np.array([0.0, 1.0, -0.5]) / math.sqrt(1.25)
    camera = Camera("camera", np.array([0.0, 0.0, 300.0]), look_rotation(look), 36.0, 36.0, 36.0, near=1.0,
                    far=1.0e5)
    sun = np.array([-0.3, 0.77, -0.56])
    scene = Scene(camera, Sun(sun / np.linalg.norm(sun), np.ones(3)), stratiform_layers=(layer,))
    width, height = layer_voxel_sizes(layer, PathTracerSettings())
    assert (width, height) == (62.5, 3.125)  # half a texel, max thickness / 32
    means, errors = [], []
    for factor in (1.0, 0.5):
        settings = PathTracerSettings(spp=8192, seed=3, layer_voxel_width=width * factor, layer_voxel=height * factor)
        out = PathTracer(settings, device=device).render(scene, 16, 16)
        if factor == 1.0:
            cloudy = out.transmittance[..., 1] < 0.5
            assert cloudy.sum() > 150
        means.append(float(out.radiance[..., 1][cloudy].mean()))
        errors.append(math.sqrt(float(out.aovs["variance"][..., 1][cloudy].sum())) / cloudy.sum())
    change = means[1] / means[0] - 1.0
    change_error = math.hypot(*errors) / means[0]
    print(f"halving the layer voxels: {change:+.4f} +- {change_error:.4f}")
    assert change_error < 0.05 / 3
    assert abs(change) < 0.05


# ------------------------------------------------------------------------------------------ through the tools
@pytest.mark.slow  # its render builds the stratus phase table
def test_render_and_info_trace_the_layer(tmp_path, capsys):
    """``warpsky render --technique path_tracer`` on a stage with a layer (sky, ground, albedo map) writes finite,
    non-negative pixels with the cloud in them; ``info`` says the layer is voxelised and how."""
    from test_stratiform_scene import run, write_layer_stage

    from warpsky.output.exr import read_exr

    stage = write_layer_stage(tmp_path / "layer.usda")
    code, out, _ = run(["info", stage, "--technique", "path_tracer", "--device", "cpu"], capsys)
    assert code == 0 and "passes      media -> composite" in out
    assert "voxelised for the path tracer: 312.5 x 312.5 x " in out and "(layer_voxel_width, layer_voxel auto)" in out
    assert "phase tables for stratus" in out and "traced with the voxelised layers" in out
    exr = tmp_path / "pt.exr"
    code, _, err = run(["render", stage, exr, "--technique", "path_tracer", "--res", "24", "--set", "spp=4",
                        "--device", "cpu"], capsys)
    assert code == 0, err
    image = read_exr(exr)
    rgba = image.rgba()
    assert np.all(np.isfinite(rgba)) and rgba[..., :3].min() >= 0.0
    assert rgba[..., :3].max() > 0.0 and rgba[..., 3].max() > 0.9  # the cloud covers some pixels
    code, _, err = run(["render", stage, exr, "--technique", "path_tracer", "--set", "layer_voxel=-1"], capsys)
    assert code == 2 and "setting layer_voxel must be a number > 0 [m] or auto, got -1" in err


@pytest.mark.slow  # builds the stratus modified Mie table (about 10 s)
def test_error_vs_time_judges_the_stratiform_pass(tmp_path, monkeypatch):
    """On a stage of a layer alone the report's rows name the stratiform pass and the reference path-traces the
    voxelised layer; the ground's albedo map is left out of both sides."""
    from test_stratiform_scene import write_layer_stage

    from evaluation import error_vs_time
    from evaluation.error_vs_time import STRATIFORM_ROW, format_table, run_report
    from warpsky.usd.stage import StageReader

    monkeypatch.setattr(error_vs_time, "cache_dir", lambda: tmp_path / "cache")  # the reference only: not the optics
    scene = StageReader(write_layer_stage(tmp_path / "layer.usda")).scene_at(None)
    logs = []
    report = run_report(scene, techniques=["single_scatter", "slicing", "path_tracer"], width=12, height=8,
                        device="cpu", budget=1.0, reference_spp=16, log=logs.append)
    names = [r.technique for r in report.rows]
    assert names[0] == STRATIFORM_ROW and "path_tracer" in names and "slicing" not in names
    assert names.count(STRATIFORM_ROW) >= 1 and report.rows[0].setting == "radiosity_detail=0"
    assert any("albedo map left out" in line for line in logs)
    assert all(np.isfinite(r.rel_rmse) and np.isfinite(r.bias) for r in report.rows)
    assert STRATIFORM_ROW in format_table(report)
