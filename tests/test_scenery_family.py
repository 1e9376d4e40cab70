"""The scenery family: a deterministic generator of terrain stages with fog, a deck, a ridge cloud or fog under a
stratocumulus layer, split into disjoint halves that each hold every kind, whose stages ``warpsky info`` plans with
the path tracer and the default technique. Nothing is rendered."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

from evaluation.scenery_family import (
    FOG_OPTICAL_DEPTH,
    FOGGY,
    KINDS,
    TERRAIN_CELLS,
    Terrain,
    make_scenery_family,
    plan_scenery,
)
from warpsky.usd.stage import StageReader


@pytest.fixture(scope="module")
def family(tmp_path_factory):
    out = tmp_path_factory.mktemp("scenery")
    make_scenery_family(out, seed=2028, count=12, layered=4)
    return out


def _members(family):
    return json.loads((family / "family.json").read_text())["members"]


def test_generator_is_deterministic_for_a_seed(family, tmp_path):
    make_scenery_family(tmp_path / "again", seed=2028, count=12, layered=4)
    assert (tmp_path / "again" / "family.json").read_bytes() == (family / "family.json").read_bytes()
    for m in _members(family):
        assert (tmp_path / "again" / m["stage"]).read_bytes() == (family / m["stage"]).read_bytes()
        for key in ("field", "layer_map"):
            if key in m:
                np.testing.assert_array_equal(np.load(tmp_path / "again" / m[key]), np.load(family / m[key]))
    assert plan_scenery(7, 12) != plan_scenery(2028, 12)
    assert plan_scenery(2028, 12, 4)[:12] == plan_scenery(2028, 12)  # the layered members leave the others alone
    points, triangles = Terrain(3).mesh()
    assert len(triangles) == 2 * TERRAIN_CELLS**2 and np.array_equal(points, Terrain(3).mesh()[0])


def test_halves_are_disjoint_and_each_holds_every_kind(family):
    members = _members(family)
    tune = {m["stage"] for m in members if m["half"] == "tune"}
    test = {m["stage"] for m in members if m["half"] == "test"}
    assert not tune & test and len(tune) + len(test) == len(members) == 16
    for half in ("tune", "test"):
        chosen = [m for m in members if m["half"] == half]
        assert {m["kind"] for m in chosen} == set(KINDS)
        assert {m["air"] for m in chosen} == {True, False}
    for m in members:
        if m["kind"] == "layer_fog":
            assert 0.3 - 1e-9 <= m["optical_depth"] <= 5.0 + 1e-9
            assert m["layer_base_m"] - m["fog_top_m"] > 400.0 and m["layer_max_thickness_m"] <= 260.0
        if m["kind"] in FOGGY:
            lo, hi = FOG_OPTICAL_DEPTH.get(m["kind"], (0.3, 5.0))
            assert lo - 1e-9 <= m["optical_depth"] <= hi + 1e-9
            assert 0.9 <= m["albedo"] <= 1.0 and 0.7 <= m["g"] <= 0.9
            assert m["camera_position"][1] > m["fog_top_m"]  # looking down on the fog
    depths = sorted(m["optical_depth"] for m in members if m["kind"] in FOG_OPTICAL_DEPTH)
    assert depths[0] == pytest.approx(0.3) and depths[-1] == pytest.approx(5.0)


def test_stages_read_back_with_their_scenery(family):
    for m in _members(family):
        scene = StageReader(family / m["stage"]).scene_at(None)
        assert len(scene.meshes) == 1 and scene.ground is not None
        assert (scene.atmosphere is not None) == m["air"]
        assert bool(scene.fogs) == (m["kind"] in FOGGY)
        assert bool(scene.stratiform_layers) == (m["kind"] == "layer_fog")
        assert bool(scene.decks) == (m["kind"] == "deck_haze")
        assert bool(scene.media) == (m["kind"] == "ridge_cloud")
        assert scene.resolution == (96, 64)


@pytest.mark.parametrize("technique", [None, "path_tracer"])
def test_info_plans_every_kind(family, technique, capsys):
    """One stage of each kind plans with the default technique and with the path tracer, which traces it all."""
    first = {}
    for m in _members(family):
        first.setdefault(m["kind"], m)
    for m in first.values():
        args = ["info", family / m["stage"]] + (["--technique", technique] if technique else [])
        code, out, err = run_cli(args, capsys)
        assert code == 0, err
        assert f"technique   {technique or 'hybrid'}" in out
        assert "3,200 triangles" in out
        if technique == "path_tracer":
            assert "traced by path_tracer inside its paths" in out


def test_sun_disk_pixels_are_left_out_of_the_measured_ones(family):
    """A sun straight ahead marks the few pixels round the image centre, a sun behind the camera none."""
    import dataclasses

    from evaluation.error_vs_time import sun_disk_pixels

    scene = StageReader(family / _members(family)[0]["stage"]).scene_at(None)
    forward = -np.asarray(scene.camera.rotation, dtype=np.float64).reshape(3, 3)[:, 2]
    ahead = dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, direction=forward))
    marked = sun_disk_pixels(ahead, 96, 64)
    assert 1 <= marked.sum() <= 16 and marked[31:33, 47:49].all()
    behind = dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, direction=-forward))
    assert not sun_disk_pixels(behind, 96, 64).any()


def test_error_vs_time_measures_a_fog_stage_without_media(family, tmp_path, monkeypatch):
    """bench error-vs-time accepts fog over terrain (no voxel media): the passes' rows against the traced fog,
    over every pixel but open sky, at 16 x 12."""
    from evaluation.error_vs_time import run_report

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    fog = next(m for m in _members(family) if m["kind"] == "thick_fog" and not m["air"])
    scene = StageReader(family / fog["stage"]).scene_at(None)
    report = run_report(scene, techniques=["single_scatter", "path_tracer"], width=16, height=12, device="cpu",
                        budget=0.2, reference_spp=16, log=lambda _: None)
    assert {r.technique for r in report.rows} == {"single_scatter", "path_tracer"}
    assert 0 < report.reference["covered_pixels"] < 16 * 12  # the sky above the hills is left out
    assert all(np.isfinite(r.rel_rmse) for r in report.rows)
