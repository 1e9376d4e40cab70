"""The validation family: a deterministic generator whose stages open and hit their optical depth, and the family
benchmark on a two-stage subset."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from evaluation.family import (
    family_reference_key,
    family_reference_path,
    format_family_table,
    make_family,
    run_family,
    write_family_outputs,
)
from evaluation.family_shapes import KINDS
from evaluation.family_stages import ALBEDOS, LIGHTING, PHASES
from warpsky.cli.main import main
from warpsky.usd.stage import StageReader


@pytest.fixture(scope="module")
def family(tmp_path_factory):
    """The default 24-member family on 16^3-sized grids (small, same parameters)."""
    out = tmp_path_factory.mktemp("family")
    make_family(out, seed=2026, count=24, resolution=16)
    return out


def test_generator_is_deterministic(family, tmp_path):
    again = tmp_path / "again"
    make_family(again, seed=2026, count=24, resolution=16)
    assert (again / "family.json").read_bytes() == (family / "family.json").read_bytes()
    members = json.loads((family / "family.json").read_text())["members"]
    for m in members:
        np.testing.assert_array_equal(np.load(again / m["field"]), np.load(family / m["field"]))
    other = tmp_path / "other"
    make_family(other, seed=7, count=24, resolution=16)
    assert (other / "family.json").read_bytes() != (family / "family.json").read_bytes()
    first_other = json.loads((other / "family.json").read_text())["members"][0]["field"]
    assert not np.array_equal(np.load(other / first_other), np.load(family / members[0]["field"]))


def test_halves_alternate_and_span_every_value(family):
    members = json.loads((family / "family.json").read_text())["members"]
    assert len(members) == 24
    assert [m["half"] for m in members] == ["tune", "test"] * 12
    for half in ("tune", "test"):
        chosen = [m for m in members if m["half"] == half]
        assert {m["kind"] for m in chosen} == set(KINDS)
    assert {m["albedo"] for m in members} == set(ALBEDOS)
    assert {m["phase"] for m in members} == set(PHASES)
    assert {m["lighting"] for m in members} == set(LIGHTING)
    assert {m["ground"] for m in members} == {True, False} and {m["atmosphere"] for m in members} == {True, False}
    elevations = [m["sun_elevation_deg"] for m in members]
    assert min(elevations) == pytest.approx(2.0) and max(elevations) == pytest.approx(90.0)
    depths = [m["optical_depth"] for m in members]
    assert min(depths) == pytest.approx(0.1, rel=1e-5) and max(depths) == pytest.approx(300.0, rel=1e-5)


def test_every_stage_opens_and_hits_its_optical_depth(family):
    for m in json.loads((family / "family.json").read_text())["members"]:
        scene = StageReader(family / m["stage"]).scene_at(None)
        assert scene.camera is not None and scene.sun is not None and len(scene.media) == 1, m["name"]
        assert scene.camera.horizontal_aperture == scene.camera.vertical_aperture and scene.resolution == (128, 128)
        assert scene.sun.direction[1] > 0.0 and (scene.ground is not None) == m["ground"]
        assert (scene.atmosphere is not None) == m["atmosphere"]
        medium = scene.media[0]
        assert medium.species == ("cloud" if m["phase"] == "cloud" else None)
        np.testing.assert_allclose(medium.albedo, m["albedo"], rtol=1e-6)
        # closed form: extinction scale x max density x chord, and the line integral through the stage's own grid
        closed = m["extinction_scale"] * m["max_density"] * m["chord_m"]
        assert closed == pytest.approx(m["optical_depth_target"], rel=0.05)
        edges = np.linalg.norm(medium.world_from_index[:3, :3], axis=0)
        column = max(float(medium.density.sum(axis=a, dtype=np.float64).max()) * edges[a] for a in range(3))
        assert float(medium.extinction_scale[0]) * column == pytest.approx(m["optical_depth_target"], rel=0.05)
        if m["kind"] == "inside":  # the camera sits in the cloud
            index = np.linalg.solve(medium.world_from_index, [*scene.camera.position, 1.0])[:3]
            assert medium.density[tuple(np.rint(index).astype(int))] > 0.1


def test_family_bench_on_two_stages(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path / "cache"))
    make_family(tmp_path / "fam", seed=2026, count=2, resolution=16)
    logs = []
    report = run_family(tmp_path / "fam", ["single_scatter", "path_tracer"], 12, 12, "cpu", half="all",
                        reference_spp=16, budget_per_stage=1.0, log=logs.append)
    assert {r.stage for r in report.rows} == {"00_cumulus", "01_cumulus"} and not any(r.error for r in report.rows)
    assert {r.half for r in report.rows} == {"tune", "test"}
    first = [a for a in report.aggregate if a["rung"] == 0]
    assert [a["technique"] for a in first] == ["single_scatter", "path_tracer"]
    for a in first:
        assert a["stages"] == 2
        assert a["median_rel_rmse"] <= a["p90_rel_rmse"] <= a["worst_rel_rmse"]
        assert {"median_bias", "mean_bias", "median_seconds", "worst_stage"} <= set(a)
    assert "median" in format_family_table(report).splitlines()[1]
    paths = write_family_outputs(report, tmp_path / "out")
    assert [p.suffix for p in paths] == [".csv", ".json", ".png"] and all(p.stat().st_size > 0 for p in paths)
    with open(paths[0]) as handle:
        header = next(csv.reader(handle))
    assert header[:7] == ["stage", "half", "kind", "technique", "setting", "rung", "seconds"]
    assert "rel_rmse" in header and "bias" in header
    blob = json.loads(paths[1].read_text())
    assert len(blob["rows"]) == len(report.rows) and blob["aggregate"][0]["technique"] == "single_scatter"
    # the references were cached by content, not by device: both members are found again, whatever the device
    cached = sorted((tmp_path / "cache" / "reference" / "family").glob("*.npz"))
    assert len(cached) == 2
    again = run_family(tmp_path / "fam", ["single_scatter"], 12, 12, "cuda:0", half="test", reference_spp=16,
                       references_only=True, log=logs.append)
    assert [r["cached"] for r in again.references] == [True] and not again.rows


def test_reference_key_ignores_the_device_and_the_location(tmp_path):
    import shutil

    make_family(tmp_path / "a", seed=3, count=2, resolution=8)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    scene_a = StageReader(tmp_path / "a" / "00_cumulus.usda").scene_at(None)
    scene_b = StageReader(tmp_path / "b" / "00_cumulus.usda").scene_at(None)
    key = family_reference_key(scene_a, 16, 16, 64, 1)
    assert family_reference_key(scene_b, 16, 16, 64, 1) == key
    assert family_reference_key(scene_a, 16, 16, 128, 1) != key
    assert family_reference_path(key).parent.name == "family"


def test_cli_needs_exactly_one_of_stage_and_family(tmp_path, capsys):
    stage = tmp_path / "s.usda"
    assert main(["bench", "error-vs-time", str(stage), "--family", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "STAGE" in err and "--family" in err and str(stage) in err
    assert main(["bench", "error-vs-time"]) == 2
    assert "neither" in capsys.readouterr().err
    assert main(["bench", "error-vs-time", "--family", str(tmp_path / "nowhere")]) == 2
    assert "family.json" in capsys.readouterr().err


def test_thick_profile_storms_carry_three_species_at_their_optical_depths(tmp_path):
    from evaluation.family_stages import PROFILES, RAIN_OPTICAL_DEPTH

    make_family(tmp_path / "thick", seed=2027, count=12, resolution=16, profile="thick")
    blob = json.loads((tmp_path / "thick" / "family.json").read_text())
    assert blob["profile"] == "thick" and blob["image_size"] == 64
    members = blob["members"]
    for half in ("tune", "test"):
        assert {m["kind"] for m in members if m["half"] == half} == set(PROFILES["thick"].kinds)
    depths = [m["optical_depth"] for m in members]
    assert min(depths) == pytest.approx(100.0, rel=1e-5) and max(depths) == pytest.approx(1000.0, rel=1e-5)
    storms = [m for m in members if m["kind"] == "storm"]
    assert storms and all(m["phase"] == "cloud" for m in storms)
    for m in storms:
        scene = StageReader(tmp_path / "thick" / m["stage"]).scene_at(None)
        assert scene.resolution == (64, 64)
        by_species = {medium.species: medium for medium in scene.media}
        assert set(by_species) == {"cloud", "ice", "rain"}
        cloud, ice, rain = by_species["cloud"], by_species["ice"], by_species["rain"]
        # droplets and ice share the cell's grid and add up to its field; the ice sits in the anvil, above
        np.testing.assert_allclose(cloud.density + ice.density, np.load(tmp_path / "thick" / m["field"]) +
                                   np.load(tmp_path / "thick" / m["ice_field"]), rtol=1e-6)
        heights = np.arange(cloud.density.shape[1])
        assert (ice.density.sum(axis=(0, 2)) @ heights / ice.density.sum()
                > cloud.density.sum(axis=(0, 2)) @ heights / cloud.density.sum())
        edges = np.linalg.norm(rain.world_from_index[:3, :3], axis=0)
        column = max(float(rain.density.sum(axis=a, dtype=np.float64).max()) * edges[a] for a in range(3))
        assert float(rain.extinction_scale[0]) * column == pytest.approx(RAIN_OPTICAL_DEPTH, rel=1e-5)
        assert rain.world_from_index[1, 3] < m["base_m"]  # the shaft hangs below the cell's base
