"""The warpsky command end to end: real stages in, real EXRs out; bad input exits 2 and writes nothing."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, write_stage
from conftest import run_cli as run

from warpsky.cli.main import main
from warpsky.output.exr import read_exr
from warpsky.render.header import EXR_CHANNELS


@pytest.fixture
def good_stage(tmp_path, homogeneous_npy):
    return write_stage(tmp_path / "good.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))


def test_render_writes_exr_with_channels_and_metadata(tmp_path, good_stage, capsys):
    out = tmp_path / "out" / "f.####.exr"
    code, stdout, _ = run(["render", good_stage, out, "--frames", "1:3", "--res", "16x12", "--device", "cpu",
                           "--png", "--technique", "single_scatter", "--set", "step_length=0.5"], capsys)
    assert code == 0
    for frame in (1, 2, 3):
        path = tmp_path / "out" / f"f.{frame:04d}.exr"
        assert str(path) in stdout and path.with_suffix(".png").is_file()
        image = read_exr(path)
        assert set(EXR_CHANNELS) <= set(image.channels)
        assert (image.width, image.height) == (16, 12)
        assert image.channels["R"].dtype == np.float16 and image.channels["depth.Z"].dtype == np.float32
        meta = image.metadata
        assert meta["stage"].endswith("good.usda") and meta["camera"] == "/World/Camera"
        assert meta["timeCode"] == float(frame) and meta["technique"] == "single_scatter"
        assert '"step_length": 0.5' in meta["settings"] and meta["device"] == "cpu"
        assert meta["renderSeconds"] > 0 and meta["version"]
        assert image.rgba()[..., 3].max() > 0.5  # the box is opaque enough to show
    assert not list((tmp_path / "out").glob(".*tmp*"))


def test_float_output_and_single_frame_without_placeholder(tmp_path, good_stage, capsys):
    out = tmp_path / "still.exr"
    code, _, _ = run(["render", good_stage, out, "--res", "8", "--float", "--device", "cpu"], capsys)
    assert code == 0
    image = read_exr(out)
    assert image.channels["R"].dtype == np.float32 and image.width == 8 and image.height == 8


def test_info_prints_stage_and_plan(good_stage, capsys):
    code, stdout, _ = run(["info", good_stage, "--device", "cpu"], capsys)
    assert code == 0
    for text in ("upAxis Y", "/World/Camera", "/World/Cloud", "technique   hybrid", "target_error=0.05",
                 "denoise=1", "ground      off"):
        assert text in stdout


# ------------------------------------------------------------------------------------------------- bad input
def _stage(tmp_path, **kw):
    return write_stage(tmp_path / "bad.usda", StageSpec(**kw))


def _npy(tmp_path, array, name="grid.npy"):
    path = tmp_path / name
    np.save(path, array)
    return path


def case_missing_stage(tmp_path):
    return tmp_path / "nope.usda", [], ["nope.usda", "does not exist"]


def case_no_camera(tmp_path):
    from pxr import Usd

    path = tmp_path / "nocam.usda"
    Usd.Stage.CreateNew(str(path)).Save()
    return path, [], ["nocam.usda", "no camera"]


def case_camera_not_a_camera(tmp_path):
    return _stage(tmp_path, volume_file=None), ["--camera", "/World/Sun"], ["/World/Sun", "not a Camera"]


def case_camera_missing_prim(tmp_path):
    return _stage(tmp_path), ["--camera", "/World/Nothing"], ["/World/Nothing"]


def case_field_file_missing(tmp_path):
    return _stage(tmp_path, volume_file=tmp_path / "missing.vdb"), [], ["/World/Cloud/density", "missing.vdb"]


def case_field_file_unreadable(tmp_path):
    garbage = tmp_path / "garbage.nvdb"
    garbage.write_bytes(b"this is not a grid at all")
    return _stage(tmp_path, volume_file=garbage), [], ["garbage.nvdb", "magic"]


def case_field_truncated_nvdb(tmp_path):
    import warp as wp

    volume = wp.Volume.load_from_numpy(np.ones((8, 8, 8), np.float32), bg_value=0.0, device="cpu")
    path = tmp_path / "cut.nvdb"
    volume.save_to_nvdb(str(path))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return _stage(tmp_path, volume_file=path), [], ["cut.nvdb", "truncated"]


def case_grid_name_missing(tmp_path):
    import warp as wp

    volume = wp.Volume.load_from_numpy(np.ones((4, 4, 4), np.float32), bg_value=0.0, device="cpu")
    path = tmp_path / "one.nvdb"
    volume.save_to_nvdb(str(path))
    return _stage(tmp_path, volume_file=path, field_name="temperature"), [], ["one.nvdb", "temperature"]


def case_nan_values(tmp_path):
    grid = np.ones((3, 3, 3), np.float32)
    grid[0, 0, 0] = np.nan
    grid[1, 1, 1] = np.inf
    grid[2, 2, 2] = -1.0
    path = _npy(tmp_path, grid, "nan.npy")
    return _stage(tmp_path, volume_file=path), [], ["nan.npy", "2 NaN/Inf", "1 negative"]


def case_zero_extent(tmp_path, lo=(0, 0, 0), hi=(1, 0, 1)):
    path = _npy(tmp_path, np.ones((2, 2, 2), np.float32))
    return _stage(tmp_path, volume_file=path, volume_extent=(lo, hi)), [], ["/World/Cloud", "extent"]


def case_inverted_extent(tmp_path):
    return case_zero_extent(tmp_path, lo=(1, 1, 1), hi=(-1, 2, 2))


def case_npy_not_3d(tmp_path):
    path = _npy(tmp_path, np.ones((4, 4), np.float32), "flat.npy")
    return _stage(tmp_path, volume_file=path), [], ["flat.npy", "3-D"]


def case_zero_aperture(tmp_path):
    return _stage(tmp_path, aperture=(0.0, 24.0)), [], ["/World/Camera", "horizontalAperture"]


def case_near_after_far(tmp_path):
    return _stage(tmp_path, clipping=(100.0, 10.0)), [], ["/World/Camera", "clippingRange"]


def case_bad_frame_spec(tmp_path):
    return _stage(tmp_path), ["--frames", "1:x"], ["1:x"]


def case_pattern_without_placeholder(tmp_path):
    return _stage(tmp_path), ["--frames", "1:3", "--output-override", "plain.exr"], ["plain.exr", "placeholder"]


def case_bad_phase_token(tmp_path, homogeneous_npy=None):
    path = _npy(tmp_path, np.ones((2, 2, 2), np.float32))
    return _stage(tmp_path, volume_file=path, phase="mie"), [], ["/World/Cloud", "warpsky:phase", "mie"]


CASES = [v for k, v in sorted(globals().items()) if k.startswith("case_")]


@pytest.mark.parametrize("case", CASES, ids=lambda f: f.__name__[5:])
def test_bad_input_exits_2_names_culprit_writes_nothing(tmp_path, case, capsys):
    stage, extra, expected = case(tmp_path)
    out_dir = tmp_path / "out"
    output = out_dir / "f.####.exr"
    if "--output-override" in extra:
        i = extra.index("--output-override")
        output = out_dir / extra[i + 1]
        extra = extra[:i] + extra[i + 2:]
    code, _, err = run(["render", stage, output, "--res", "8x8", "--device", "cpu", *extra], capsys)
    assert code == 2, err
    for text in expected:
        assert text in err, f"{text!r} not in: {err}"
    # the first frame is planned before anything is written: no directory, frame, temporary file or log
    assert not out_dir.exists(), sorted(p.name for p in out_dir.iterdir())


def test_usage_errors_exit_2(tmp_path, good_stage, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["render", str(good_stage), str(tmp_path / "a.exr"), "--res", "0x5"])
    assert exc.value.code == 2
    code, _, err = run(["render", good_stage, tmp_path / "a.png"], capsys)
    assert code == 2 and "a.png" in err
    code, _, err = run(["render", good_stage, tmp_path / "a.exr", "--technique", "slicing", "--set",
                        "slice_count=-1"], capsys)
    assert code == 2 and "slice_count" in err
    code, _, err = run(["render", good_stage, tmp_path / "a.exr", "--set", "bogus=1"], capsys)
    assert code == 2 and "bogus" in err


def test_failed_frame_keeps_finished_frames(tmp_path, capsys):
    """Frame 2's file is missing: frames 1 and 3 are written, the error names frame 2's file, exit 2."""
    from pxr import Sdf, Usd, UsdVol

    for frame in (1, 3):
        _npy(tmp_path, np.ones((2, 2, 2), np.float32), f"d.{frame}.npy")
    path = _stage(tmp_path, volume_file=tmp_path / "d.1.npy")
    stage = Usd.Stage.Open(str(path))
    attr = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Cloud/density")).GetFilePathAttr()
    attr.Clear()
    for frame in (1, 2, 3):
        attr.Set(Sdf.AssetPath(str(tmp_path / f"d.{frame}.npy")), float(frame))
    stage.Save()
    code, _, err = run(["render", path, tmp_path / "o.####.exr", "--frames", "1:3", "--res", "8", "--device", "cpu"],
                       capsys)
    assert code == 2 and "d.2.npy" in err
    assert (tmp_path / "o.0001.exr").is_file() and (tmp_path / "o.0003.exr").is_file()
    assert not (tmp_path / "o.0002.exr").exists()


# ------------------------------------------------------------------------------------------ techniques, settings
def test_every_technique_declares_the_protocol():
    import dataclasses

    from warpsky.core.settings import field_kinds
    from warpsky.render.registry import technique_class, technique_names

    for name in technique_names():
        cls = technique_class(name)
        assert cls.name == name == cls.Settings.owner
        assert isinstance(cls.traces_air, bool) and isinstance(cls.renders_layers, bool)
        assert set(field_kinds(cls.Settings)) == {f.name for f in dataclasses.fields(cls.Settings)}
        assert all(f.metadata["help"] for f in dataclasses.fields(cls.Settings)), name


def test_settings_are_parsed_by_their_declared_types(tmp_path, good_stage, capsys):
    from warpsky.core.settings import parse_settings
    from warpsky.techniques.path_tracer.path_tracer import PathTracerSettings
    from warpsky.techniques.slicing.slicing import LightEquation, SlicingSettings

    s = parse_settings(SlicingSettings, {"slice_count": "12", "low_albedo": "true", "light_equation": "eq24",
                                         "xi": "auto", "orders": "8.0"})
    assert (s.slice_count, s.low_albedo, s.light_equation, s.xi, s.orders) == (12, True, LightEquation.EQ24, 0.01, 8)
    assert type(s.slice_count) is int and type(s.orders) is int
    assert parse_settings(SlicingSettings, {"slice_count": "auto", "light_equation": "25"}).slice_count is None
    assert PathTracerSettings(spp=16.0, pixel_jitter=1) == PathTracerSettings(spp=16, pixel_jitter=True)
    for technique, text, message in (
        ("path_tracer", "spp=2.5", "setting spp must be a whole number >= 1, got 2.5"),
        ("path_tracer", "seed=x", "setting seed: expected a whole number, got 'x'"),
        ("slicing", "low_albedo=2", "setting low_albedo must be 0 or 1, got 2"),
        ("slicing", "light_equation=23", "setting light_equation must be 0, 24 or 25"),
        ("slicing", "stratiform.radiosity_detail=5", "setting stratiform.radiosity_detail must be a whole number "
         "in 0..4, got 5"),
        ("slicing", "stratiform.radiosity_detail=2", None),  # no layers: unused, reported by info
    ):
        code, _, err = run(["render", good_stage, tmp_path / "a.exr", "--res", "4", "--device", "cpu", "--technique",
                            technique, "--set", text], capsys)
        if message is None:
            assert code == 0, err
        else:
            assert code == 2 and message in err, err


def test_help_settings_all_lists_every_setting_with_its_metadata(capsys):
    import dataclasses

    from warpsky.passes.stratiform.stratiform import StratiformSettings
    from warpsky.render.registry import technique_class, technique_names

    with pytest.raises(SystemExit):
        main(["render", "--help-settings", "all"])
    out = capsys.readouterr().out
    for name in technique_names():
        assert all(f.name in out for f in dataclasses.fields(technique_class(name).Settings))
    assert all(f"stratiform.{f.name}" in out for f in dataclasses.fields(StratiformSettings))
    assert "256 texel" in out and "samples (paths) per pixel" in out and "auto: 8 on the CPU" in out


@pytest.mark.parametrize("flags,message", [
    (["--target-error", "0"], "--target-error"), (["--target-error", "nan"], "--target-error"),
    (["--target-error", "1"], "--target-error"), (["--target-error", "-0.1"], "--target-error"),
    (["--time-budget", "0"], "--time-budget"), (["--time-budget", "-3"], "--time-budget"),
    (["--technique", "slicing", "--target-error", "0.1"], "--target-error applies to technique hybrid only"),
])


def test_bad_target_flags_exit_2_naming_the_flag(tmp_path, good_stage, capsys, flags, message):
    out = tmp_path / "out" / "f.exr"
    try:
        code = main([str(a) for a in ["render", good_stage, out, "--res", "8", "--device", "cpu", *flags]])
    except SystemExit as stop:  # argparse rejects a bad value itself
        code = stop.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_default_render_is_hybrid_with_its_figures_in_the_header(tmp_path, good_stage, capsys):
    out = tmp_path / "h.exr"
    code, _, _ = run(["render", good_stage, out, "--res", "16", "--device", "cpu", "--target-error", "0.2",
                      "--float"], capsys)
    assert code == 0
    meta = read_exr(out).metadata
    assert meta["technique"] == "hybrid" and meta["stoppedBy"] in ("target", "spp")
    assert meta["targetError"] == pytest.approx(0.2) and meta["spp"] >= 2 and meta["cappedPaths"] == 0
    assert meta["errorEstimate"] <= 0.2 or meta["stoppedBy"] == "spp"
