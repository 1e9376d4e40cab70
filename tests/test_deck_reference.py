"""The path-traced reference for Max 1986 height-field cloud decks: the deck voxelised with exact column optical
depths (warpsky.media.deck.deck_voxels), traced by the path tracer against the deck pass's single scattering,
and through ``warpsky render`` / ``info`` / ``bench error-vs-time``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import look_rotation, run_cli

from warpsky.core.errors import UsageError
from warpsky.media.deck.deck_voxels import deck_grid, sub_column_offsets, voxelize_deck
from warpsky.model.deck import CloudDeck, HazeSpec, surface_heights
from warpsky.model.scene import Camera, PhaseKind, Scene, Sun


def wavy_deck(**kwargs) -> CloudDeck:
    """Four random waves of 700 m about a nearly flat pattern: about 40 % of the columns clear."""
    rng = np.random.default_rng(7)
    k = rng.normal(size=(4, 2)) * 2.0 * math.pi / 700.0
    args = dict(rounding=40.0, bottom_depth=60.0, density=0.02, haze=HazeSpec(np.full(3, 1e-4), floor=-50.0))
    args.update(kwargs)
    return CloudDeck("/World/Deck", 1000.0, [5.0], k, rng.uniform(10, 30, 4), rng.uniform(0, 6, 4),
                             rng.uniform(-0.01, 0.01, 4), **args)


def column_depth(medium) -> np.ndarray:
    """(n_x, n_z) vertical optical depth through each column centre of the medium's trilinear field (piecewise
    linear between voxel centres, edge values out to the box: the trapezoid rule on the nodes is exact)."""
    dy = medium.voxel_size[1]
    d = medium.density.astype(np.float64)
    inner = 0.5 * (d[:, 1:, :] + d[:, :-1, :]).sum(axis=1) * dy
    return medium.extinction_scale[1] * (inner + 0.5 * dy * (d[:, 0, :] + d[:, -1, :]))


# ------------------------------------------------------------------------------------------------ voxelisation
@pytest.mark.parametrize("supersample", [1, 4])
def test_columns_carry_the_deck_optical_depth(supersample):
    """Every column's optical depth is rho (g - h) at its centre (s = 1) or the mean of rho (g - h) over its s x s
    sub-columns (s = 4), to float precision, whatever the voxel size, at the time the waves have moved to; the
    haze is one homogeneous box from its floor to the cloud base over the same square."""
    clouds = wavy_deck()
    t = 30.0
    for width, height in ((20.0, 7.0), (45.0, 30.0)):
        cloud, haze = voxelize_deck(clouds, t, (3.0e4, -2.0e3), 800.0, width, height, supersample=supersample)
        xs, zs = (cloud.world_from_index[a, 3] + np.arange(cloud.shape[a]) * cloud.voxel_size[a] for a in (0, 2))
        offsets = sub_column_offsets(cloud.voxel_size[0], supersample)
        x, z = (xs[:, None] + offsets).reshape(-1), (zs[:, None] + offsets).reshape(-1)
        f = clouds.pattern(x[:, None], z[None, :], t)
        g, h = surface_heights(f, clouds.rounding, clouds.bottom_depth)
        thickness = np.where(f > 0.0, g - h, 0.0).reshape(len(xs), supersample, len(zs), supersample)
        expected = clouds.density * thickness.mean(axis=(1, 3))
        assert 0.2 < np.mean(expected == 0.0) < 0.6  # gaps are voxelised as gaps
        np.testing.assert_allclose(column_depth(cloud), expected, rtol=1e-5, atol=1e-7)
        assert cloud.density.min() >= 0.0 and cloud.density.max() <= 1.0
        assert cloud.phase.kind == PhaseKind.HG and cloud.phase.g == pytest.approx(0.85)
        low, high = clouds.band
        corners = cloud.world_corners()
        assert corners[:, 1].min() == pytest.approx(low) and high <= corners[:, 1].max() < high + height
        assert np.all(haze.density == 1.0) and haze.world_corners()[:, 1].min() == pytest.approx(-50.0)
        assert haze.world_corners()[:, 1].max() == pytest.approx(low)
        np.testing.assert_allclose(haze.world_corners()[:, [0, 2]].min(axis=0), corners[:, [0, 2]].min(axis=0))
    still = voxelize_deck(clouds, 0.0, (3.0e4, -2.0e3), 800.0, 45.0, 30.0, supersample=supersample)[0]
    assert np.abs(column_depth(still) - column_depth(cloud)).max() > 0.1  # the waves moved


def test_deck_grid_over_the_budget_is_refused_naming_the_setting():
    clouds = wavy_deck()
    with pytest.raises(UsageError, match=r"^height-field clouds /World/Deck: deck_voxel 1 m x 1 m .* over the budget"):
        voxelize_deck(clouds, 0.0, (0.0, 0.0), 2.0e4, 1.0, 1.0, setting="deck_voxel")
    assert deck_grid(clouds, (0.0, 0.0), 2.0e4, 1.0, 1.0, max_voxels=2**62).voxels > 2**27  # nothing allocated


# ---------------------------------------------------------------------------------- against the deck pass
def thin_deck() -> tuple[CloudDeck, Camera]:
    """An optically thin deck (density 0.002 1/m, tau <= 0.3, albedo 1) 1.5 km up with haze of 2e-4 /m, and a
    camera 300 m up looking at it from below."""
    k = np.array([[2.0 * math.pi / 700.0, 0.0], [0.0035, 0.0060]])
    clouds = CloudDeck("/World/Deck", 1500.0, [2.0], k, [20.0, 14.0], [0.3, 1.7], rounding=100.0,
                               bottom_depth=80.0, density=0.002, g=0.85, haze=HazeSpec(np.full(3, 2e-4), g=0.7))
    look = np.array([0.2, 1.0, -0.4]) / math.sqrt(1.2)
    camera = Camera("cam", np.array([40.0, 300.0, -20.0]), look_rotation(look), 24.0, 36.0, 24.0, near=1.0,
                    far=1.0e5)
    return clouds, camera


def test_thin_deck_single_scattering_matches_the_deck_pass(device):
    """An optically thin deck (density 0.002 1/m, tau <= 0.3, albedo 1) with haze, sun overhead, seen from below:
    the path tracer limited to single scattering (max_bounces = 1) and the deck pass (exact mode) agree on
    the mean radiance within noise (z < 4, 0.3 % for the voxels in quadrature; measured on the CPU with 4096 spp:
    -0.09 % +- 0.27 %), and the noise is small enough (< 1 %) for a 5 % error to fail. All orders of scattering
    add about 15 % here."""
    from warpsky.passes.deck.deck import Deck
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    clouds, camera = thin_deck()
    scene = Scene(camera, Sun(np.array([0.0, 1.0, 0.0]), np.ones(3)), decks=(clouds,))
    expected = float(Deck(device=device).render(scene, 24, 16).radiance[..., 1].mean())
    settings = PathTracerSettings(spp=2048, seed=5, max_bounces=1, deck_extent=2500.0)
    out = PathTracer(settings, device=device).render(scene, 24, 16)
    measured = float(out.radiance[..., 1].mean())
    noise = math.sqrt(float(out.aovs["variance"][..., 1].sum())) / out.radiance[..., 1].size
    print(f"thin deck: path tracer (single scattering) {measured:.5f} +- {noise:.5f}, deck pass "
          f"{expected:.5f}")
    assert noise < 0.01 * expected
    assert abs(measured - expected) / math.hypot(noise, 0.003 * expected) < 4.0


# ------------------------------------------------------------------------------------------ through the tools
def test_render_and_info_trace_the_deck(tmp_path, capsys):
    """``warpsky render --technique path_tracer`` on the deck stage writes finite, non-negative pixels with the
    deck in them, and ``info`` says it is voxelised and how; with a Mesh too it traces both (no surfaces pass)."""
    from evaluation.deck_stage import write_deck_stage
    from warpsky.output.exr import read_exr

    stage = str(write_deck_stage(tmp_path / "deck.usda"))
    code, out, _ = run_cli(["info", stage, "--technique", "path_tracer", "--res", "24", "--device", "cpu"], capsys)
    assert code == 0 and "passes      media -> composite" in out
    assert "Max 1986 deck voxelised for the path tracer at t = 0 s over a square of half-size" in out
    assert "(deck_extent, deck_voxel_width, deck_voxel auto)" in out and "traced with the voxelised deck" in out
    exr = tmp_path / "pt.exr"
    settings = ["--set", "spp=2", "--set", "deck_extent=3000", "--set", "deck_voxel_width=50"]
    code, _, err = run_cli(["render", stage, exr, "--technique", "path_tracer", "--res", "24", *settings,
                            "--device", "cpu"], capsys)
    assert code == 0, err
    rgba = read_exr(exr).rgba()
    assert np.all(np.isfinite(rgba)) and rgba[..., :3].min() >= 0.0 and rgba[..., :3].max() > 0.0
    code, _, err = run_cli(["render", stage, exr, "--technique", "path_tracer", "--set", "deck_voxel=-1"], capsys)
    assert code == 2 and "setting deck_voxel must be a number > 0 [m] or auto, got -1" in err
    mesh = """    def Mesh "Hill"
    {
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(-100, 0, -100), (100, 0, -100), (0, 50, 100)]
    }
"""
    terrain = tmp_path / "terrain.usda"
    terrain.write_text(open(stage).read().replace('    def Xform "Deck"', mesh + '    def Xform "Deck"'))
    code, out, err = run_cli(["info", str(terrain), "--technique", "path_tracer", "--res", "24"], capsys)
    assert code == 0, err
    assert "passes      media -> composite" in out and "traced by path_tracer inside its paths" in out
    code, _, err = run_cli(["render", str(terrain), exr, "--technique", "path_tracer", "--res", "24", *settings,
                            "--device", "cpu"], capsys)
    assert code == 0, err
    with_hill = read_exr(exr).rgba()
    assert np.all(np.isfinite(with_hill)) and with_hill[..., :3].min() >= 0.0


def test_error_vs_time_judges_the_deck_pass(tmp_path, monkeypatch):
    """On a deck stage the report's rows name the deck pass, one family per mode along its step length,
    against the path-traced deck; single scattering shows as a negative bias."""
    from evaluation import error_vs_time
    from evaluation.deck_stage import deck_scene
    from evaluation.error_vs_time import HEIGHTFIELD_ROW, format_table, run_report

    monkeypatch.setattr(error_vs_time, "cache_dir", lambda: tmp_path / "cache")
    scene = deck_scene(tmp_path / "deck.usda", haze=5.0e-3)  # a square of about 1 km: a small grid
    report = run_report(scene, techniques=["single_scatter", "slicing"], width=12, height=8, device="cpu",
                        budget=0.5, reference_spp=64)
    names = [r.technique for r in report.rows]
    for mode in ("exact", "max", "sexp"):
        assert HEIGHTFIELD_ROW.format(mode=mode) in names
    assert "slicing" not in names and "single_scatter" not in names
    assert report.rows[0].setting.startswith("step_length=")
    assert all(np.isfinite(r.rel_rmse) and np.isfinite(r.bias) for r in report.rows)
    assert report.rows[0].bias < 0.0  # single scattering misses the multiply scattered light
    assert HEIGHTFIELD_ROW.format(mode="exact") in format_table(report)
