"""Input errors a user meets first: unreadable stage files reported by USD's parser (file:line:column, one line),
and errors every frame shares reported once, before any output directory or log exists."""

from __future__ import annotations

import json

import pytest
from conftest import StageSpec, write_stage

from warpsky.cli.main import main
from warpsky.output.exr import read_exr

#: A stage whose line 18 holds a doubled ``def``: USD's parser stops at column 9.
SYNTAX_ERROR_STAGE = """#usda 1.0
(
    upAxis = "Y"
)

def Xform "World"
{
    def Camera "Camera"
    {
        float focalLength = 50
    }

    def Xform "Cloud"
    {
        double3 xformOp:translate = (0, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
        def def Xform "Broken"
    {
    }
}
"""


def _render(capfd, stage, out, *extra):
    """Run ``warpsky render``; returns (exit code, stderr as the terminal sees it, USD's own output included)."""
    code = main(["render", str(stage), str(out), "--res", "8x8", "--device", "cpu", *map(str, extra)])
    return code, capfd.readouterr().err


def _one_readable_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "pxrInternal" not in err and ".cpp" not in err and ".h :" not in err, err
    assert lines[0].isprintable(), err
    return lines[0]


@pytest.fixture
def good_stage(tmp_path, homogeneous_npy):
    return write_stage(tmp_path / "good.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))


# ------------------------------------------------------------------------------------------- unreadable stages
def test_syntax_error_names_file_line_and_column(tmp_path, capfd):
    stage = tmp_path / "syntax.usda"
    stage.write_text(SYNTAX_ERROR_STAGE)
    code, err = _render(capfd, stage, tmp_path / "out" / "f.exr")
    assert code == 2
    line = _one_readable_line(err)
    assert "syntax.usda:18:9:" in line and "Expected" in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["garbage.usda", "garbage.usdc", "garbage.usd"])
def test_binary_garbage_is_one_readable_line(tmp_path, capfd, name):
    stage = tmp_path / name
    stage.write_bytes(bytes(range(256)) * 4)
    code, err = _render(capfd, stage, tmp_path / "f.exr")
    assert code == 2
    assert name in _one_readable_line(err)


def test_broken_sublayer_names_its_own_file_and_line(tmp_path, capfd):
    (tmp_path / "broken.usda").write_text(SYNTAX_ERROR_STAGE)
    stage = tmp_path / "shot.usda"
    stage.write_text('#usda 1.0\n(\n    subLayers = [@./broken.usda@]\n)\n')
    code, err = _render(capfd, stage, tmp_path / "f.exr")
    assert code == 2
    line = _one_readable_line(err)
    assert "broken.usda:18:9:" in line and "sublayer of" in line and "shot.usda" in line


def test_broken_reference_names_its_own_file_and_line(tmp_path, capfd, good_stage):
    (tmp_path / "broken.usda").write_text(SYNTAX_ERROR_STAGE)
    stage = tmp_path / "shot.usda"
    stage.write_text(f'#usda 1.0\n(\n    subLayers = [@./{good_stage.name}@]\n)\n\n'
                     'def Xform "Extra" (\n    references = @./broken.usda@</World>\n)\n{\n}\n')
    code, err = _render(capfd, stage, tmp_path / "f.exr")
    assert code == 2
    line = _one_readable_line(err)
    assert "broken.usda:18:9:" in line and "referenced by" in line and "shot.usda" in line


def test_missing_sublayer_and_reference_are_named(tmp_path, capfd, good_stage):
    stage = tmp_path / "shot.usda"
    stage.write_text(f'#usda 1.0\n(\n    subLayers = [@./{good_stage.name}@, @./gone.usda@]\n)\n')
    code, err = _render(capfd, stage, tmp_path / "f.exr")
    assert code == 2 and "gone.usda" in _one_readable_line(err) and "does not exist" in err
    stage.write_text(f'#usda 1.0\n(\n    subLayers = [@./{good_stage.name}@]\n)\n\n'
                     'def Xform "Extra" (\n    references = @./lost.usda@\n)\n{\n}\n')
    code, err = _render(capfd, stage, tmp_path / "f.exr")
    assert code == 2 and "error: stage" in err and "lost.usda" in err.strip().splitlines()[-1]
    assert not list(tmp_path.glob("f*"))


# ------------------------------------------------------------------------------- validated before any output
def test_bad_setting_in_a_batch_is_reported_once_and_writes_nothing(tmp_path, capfd, good_stage):
    out = tmp_path / "out" / "f.####.exr"
    code, err = _render(capfd, good_stage, out, "--frames", "1:4", "--set", "no_such_setting=1")
    assert code == 2
    assert err.count("no_such_setting") == 1, err
    assert not (tmp_path / "out").exists()


def test_missing_camera_leaves_no_directory_and_no_log(tmp_path, capfd):
    from pxr import Usd, UsdGeom

    stage_path = tmp_path / "nocam.usda"
    stage = Usd.Stage.CreateNew(str(stage_path))
    UsdGeom.Xform.Define(stage, "/World")
    stage.Save()
    log = tmp_path / "logs" / "shot.log.json"
    before = sorted(p.name for p in tmp_path.iterdir())
    code, err = _render(capfd, stage_path, tmp_path / "out" / "f.####.exr", "--frames", "1:2", "--log", log)
    assert code == 2 and "no camera" in err and err.count("no camera") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == before


# ------------------------------------------------------------------------------------------------- capped paths
@pytest.mark.parametrize("technique", ["path_tracer", "hybrid"])
def test_capped_paths_warn_and_reach_header_and_log(tmp_path, capfd, homogeneous_npy, technique):
    """A box of optical depth 1000 at albedo 1: with at most 4 scattering events nearly every path that enters it
    is stopped, far above the 0.1% that warns."""
    stage = write_stage(tmp_path / "thick.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40),
                                                           extinction_scale=50.0, albedo=1.0))
    out = tmp_path / "thick.exr"
    code, err = _render(capfd, stage, out, "--technique", technique, "--spp", 2, "--set", "max_bounces=4",
                        *(["--set", "target_error=0"] if technique == "hybrid" else []))
    assert code == 0, err
    meta = read_exr(out).metadata
    assert meta["paths"] > 0 and meta["cappedPaths"] > 0.001 * meta["paths"]
    warnings = [line for line in err.splitlines() if "max_bounces" in line]
    assert len(warnings) == 1 and "warning" in warnings[0] and "max_bounces = 4" in warnings[0], err
    assert f"{meta['cappedPaths']:,} of {meta['paths']:,} paths" in warnings[0] and "%" in warnings[0]
    frame = json.loads((tmp_path / "thick.log.json").read_text())["runs"][-1]["frames"][-1]
    assert frame["quality"]["capped_paths"] == meta["cappedPaths"] and frame["warnings"] == [warnings[0][
        warnings[0].index("warning: ") + len("warning: "):]]


def test_no_capped_paths_warning_below_the_threshold(tmp_path, capfd, good_stage):
    out = tmp_path / "thin.exr"
    code, err = _render(capfd, good_stage, out, "--technique", "path_tracer", "--spp", 2)
    assert code == 0 and "max_bounces" not in err
    meta = read_exr(out).metadata
    assert meta["cappedPaths"] == 0 and meta["paths"] == 8 * 8 * 2
