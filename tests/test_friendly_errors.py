"""Mistakes a user makes while typing a command, each answered in one line with what was meant: a resolution that
starts with a minus, a misspelt setting, technique or camera path, and a setting given to a technique or pass that
does not have it. Every one exits 2 and leaves no file or directory."""

from __future__ import annotations

import pytest
from conftest import StageSpec, write_stage

from warpsky.cli.main import main
from warpsky.cli.options import join_dash_values
from warpsky.core.errors import did_you_mean


@pytest.fixture
def two_camera_stage(tmp_path, homogeneous_npy):
    """A box of medium seen by /World/Camera, plus a second camera /World/CloseUp."""
    from pxr import Usd, UsdGeom

    path = write_stage(tmp_path / "shot.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    stage = Usd.Stage.Open(str(path))
    UsdGeom.Camera.Define(stage, "/World/CloseUp")
    stage.Save()
    return path


def _one_line(tmp_path, capsys, stage, *flags, command="render") -> str:
    """Run ``warpsky COMMAND`` in-process with ``flags``; asserts exit 2, one line on stderr and nothing written
    into ``tmp_path`` beside what was there; returns the line."""
    before = sorted(p.name for p in tmp_path.iterdir())
    out = [str(tmp_path / "out" / "f.####.exr")] if command == "render" else []
    try:
        code = main([command, str(stage), *out, "--device", "cpu", *map(str, flags)])
    except SystemExit as stop:  # argparse exits itself
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    return lines[0]


@pytest.mark.parametrize("value", ["-96x64", "-96"])
def test_a_negative_resolution_is_a_bad_resolution(tmp_path, capsys, two_camera_stage, value):
    line = _one_line(tmp_path, capsys, two_camera_stage, "--res", value)
    assert "argument --res: resolution must be positive" in line and repr(value) in line
    assert "expected one argument" not in line


def test_only_a_dash_value_after_res_is_joined():
    assert join_dash_values(["render", "s.usda", "--res", "-96x64", "--png"]) == \
        ["render", "s.usda", "--res=-96x64", "--png"]
    assert join_dash_values(["info", "s.usda", "--res", "96", "--camera", "-1x1"]) == \
        ["info", "s.usda", "--res", "96", "--camera", "-1x1"]
    assert join_dash_values(["render", "--res", "--png"]) == ["render", "--res", "--png"]
    assert join_dash_values(["render", "--", "--res", "-1x1"]) == ["render", "--", "--res", "-1x1"]


@pytest.mark.parametrize("command", ["render", "info"])
def test_a_misspelt_setting_gets_a_did_you_mean(tmp_path, capsys, two_camera_stage, command):
    line = _one_line(tmp_path, capsys, two_camera_stage, "--set", "target_eror=0.1", command=command)
    assert "unknown setting target_eror for hybrid; did you mean target_error?" in line
    line = _one_line(tmp_path, capsys, two_camera_stage, "--set", "fog.node=3", command=command)
    assert "unknown setting fog.node for fog; did you mean fog.nodes?" in line


@pytest.mark.parametrize("flags, expected", [
    (["--set", "slice_count=64"],
     "setting slice_count is not a setting of hybrid; it belongs to the slicing technique "
     "(use --technique slicing --set slice_count=64)"),
    (["--set", "radiosity=0"],
     "setting radiosity is not a setting of hybrid; it belongs to the stratiform pass "
     "(use --set stratiform.radiosity=0)"),
    (["--technique", "single_scatter", "--set", "fog.step_length=3"],
     "setting fog.step_length is not a setting of fog; it belongs to the deck pass (use --set deck.step_length=3) "
     "or the hybrid technique (use --technique hybrid --set step_length=3) or the single_scatter technique "
     "(use --set step_length=3)"),
])
def test_a_setting_of_another_technique_or_pass_names_its_owner(tmp_path, capsys, two_camera_stage, flags,
                                                                expected):
    assert _one_line(tmp_path, capsys, two_camera_stage, *flags).endswith(expected)


def test_a_wrong_camera_lists_the_stages_cameras(tmp_path, capsys, two_camera_stage):
    line = _one_line(tmp_path, capsys, two_camera_stage, "--camera", "/World/Camra")
    assert "no prim at camera path /World/Camra" in line
    assert line.endswith("did you mean /World/Camera? the stage's cameras: /World/Camera, /World/CloseUp")
    line = _one_line(tmp_path, capsys, two_camera_stage, "--camera", "/World/Sun", command="info")
    assert "prim /World/Sun is a DistantLight, not a Camera" in line
    assert "the stage's cameras: /World/Camera, /World/CloseUp" in line


def test_an_unknown_technique_gets_a_did_you_mean(tmp_path, capsys, two_camera_stage):
    line = _one_line(tmp_path, capsys, two_camera_stage, "--technique", "hybird")
    assert "argument --technique: unknown technique 'hybird'; did you mean hybrid? available: " in line
    assert "slicing" in line and "--help" in line
    line = _one_line(tmp_path, capsys, two_camera_stage, "--technique", "glow", command="info")
    assert "unknown technique 'glow'; available: " in line


def test_did_you_mean_offers_only_close_names():
    assert did_you_mean("target_eror", ["target_error", "time_budget"]) == "did you mean target_error? "
    assert did_you_mean("zzz", ["target_error", "time_budget"]) == ""
