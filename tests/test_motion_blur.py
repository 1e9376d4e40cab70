"""Motion blur over the camera's shutter: the average of sub-frames at the midpoints of the shutter's parts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import run_cli as run

import warpsky
from warpsky.core.errors import SceneError
from warpsky.output.exr import read_exr
from warpsky.render.motion import sub_frame_technique, sub_frame_times

FAST = {"technique": "single_scatter", "resolution": (24, 16), "device": "cpu", "settings": {"step_length": "1"}}


def moving_stage(path, npy, *, shutter: str = "double shutter:open = 0\n        double shutter:close = 1") -> str:
    """A 20 m box of unit density moving 30 m along +x between frames 1 and 2, seen from 60 m."""
    path.write_text(f"""#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
    startTimeCode = 1
    endTimeCode = 2
)

def Xform "World"
{{
    def Camera "Camera"
    {{
        float focalLength = 20
        float horizontalAperture = 36
        float verticalAperture = 24
        {shutter}
        double3 xformOp:translate = (0, 0, 60)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}

    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = (-45, 30, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }}

    def Volume "Box"
    {{
        float3[] extent = [(-10, -10, -10), (10, 10, 10)]
        double3 xformOp:translate.timeSamples = {{1: (-15, 0, 0), 2: (15, 0, 0)}}
        uniform token[] xformOpOrder = ["xformOp:translate"]
        rel field:density = </World/Box/density>

        def OpenVDBAsset "density"
        {{
            asset filePath = @{npy}@
            float warpsky:extinctionScale = 0.1
        }}
    }}
}}
""")
    return str(path)


def test_a_blurred_frame_is_the_average_of_its_sub_frames(tmp_path, homogeneous_npy):
    """Shutter [0, 1] frame, 4 sub-frames: the frame equals the mean of the unblurred renders at 1.125, 1.375,
    1.625 and 1.875 (to float precision), differs from the frame at its own time code (the box moved 30 m), and
    keeps alpha in [0, 1]; its depth is the nearest of the sub-frames'."""
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy)
    blurred = warpsky.render_stage(stage, 1.0, motion_samples=4, **FAST)
    times = sub_frame_times(1.0, (0.0, 1.0), 4)
    assert times == [1.125, 1.375, 1.625, 1.875]
    subs = [warpsky.render_stage(stage, t, shutter=(0.0, 0.0), **FAST) for t in times]
    np.testing.assert_allclose(blurred.frame.rgba, np.mean([s.frame.rgba for s in subs], axis=0), atol=1e-7)
    np.testing.assert_array_equal(blurred.frame.depth, np.min([s.frame.depth for s in subs], axis=0))
    still = warpsky.render_stage(stage, 1.0, shutter=(0.0, 0.0), **FAST)
    assert np.abs(blurred.frame.rgba - still.frame.rgba).max() > 0.05
    covered = lambda image: (image.frame.rgba[..., 3] > 0.01).sum()  # noqa: E731
    assert covered(blurred) > 1.5 * covered(still)  # the smear covers more of the frame
    assert 0.0 <= blurred.frame.rgba[..., 3].min() and blurred.frame.rgba[..., 3].max() <= 1.0
    assert blurred.metadata["shutterOpen"] == 0.0 and blurred.metadata["motionSamples"] == 4


def test_a_closed_shutter_renders_once_as_before(tmp_path, homogeneous_npy, capsys):
    """USD's default shutter (open = close = 0) renders the frame at its time code: no shutter in the header and
    the same settings hash as --shutter 0:0; --shutter on the command line opens it."""
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy, shutter="")
    args = ["render", stage, tmp_path / "a.exr", "--frames", "1", "--res", "24x16", "--float", "--device", "cpu",
            "--technique", "single_scatter", "--set", "step_length=1"]
    code, _, err = run(args, capsys)
    assert code == 0, err
    plain = read_exr(tmp_path / "a.exr")
    assert "shutterOpen" not in plain.metadata
    code, _, err = run([*args[:2], tmp_path / "b.exr", *args[3:], "--shutter", "0:0"], capsys)
    assert code == 0 and read_exr(tmp_path / "b.exr").metadata["settingsHash"] == plain.metadata["settingsHash"]
    for name in ("R", "A"):
        np.testing.assert_array_equal(read_exr(tmp_path / "b.exr").channels[name], plain.channels[name])
    code, _, err = run([*args[:2], tmp_path / "c.exr", *args[3:], "--shutter=-0.5:0.5", "--motion-samples", "2"],
                       capsys)
    blurred = read_exr(tmp_path / "c.exr")
    assert code == 0 and blurred.metadata["shutterClose"] == 0.5 and blurred.metadata["motionSamples"] == 2, err
    assert blurred.metadata["settingsHash"] != plain.metadata["settingsHash"]
    code, stdout, _ = run(["info", stage, "--device", "cpu"], capsys)
    assert code == 0 and "motion blur off (shutter closed)" in stdout
    code, stdout, _ = run(["info", stage, "--device", "cpu", "--shutter=-0.5:0.5"], capsys)
    assert "motion blur shutter -0.5 .. 0.5 frames, 8 sub-frames" in stdout


@pytest.mark.parametrize("flags,words", [(["--shutter", "1:0"], "CLOSE >= OPEN"), (["--shutter", "soon"], "OPEN:CLOSE"),
                                         (["--motion-samples", "0"], "sub-frames")])
def test_bad_shutter_flags_are_one_line(tmp_path, homogeneous_npy, capsys, flags, words):
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy)
    with pytest.raises(SystemExit) as stop:
        run(["render", stage, tmp_path / "x.exr", *flags], capsys)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and len(err.strip().splitlines()) == 1 and words in err, err
    assert not (tmp_path / "x.exr").exists()


def test_a_shutter_closing_before_it_opens_is_named(tmp_path, homogeneous_npy):
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy,
                         shutter="double shutter:open = 0.5\n        double shutter:close = 0.25")
    with pytest.raises(SceneError, match="camera /World/Camera: shutter:close must be at or after shutter:open"):
        warpsky.render_stage(stage, 1.0, **FAST)


def test_a_blurred_frame_has_deep_samples_that_flatten_to_it(tmp_path, homogeneous_npy):
    """--deep with an open shutter: every sub-frame's samples, weighted so that flattening them front to back
    gives the blurred frame (to float32 precision), alpha included."""
    from warpsky.output.deep import flatten

    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy)
    blurred = warpsky.render_stage(stage, 1.0, motion_samples=4, deep=True, **FAST)
    still = warpsky.render_stage(stage, 1.0, shutter=(0.0, 0.0), deep=True, **FAST)
    assert blurred.deep.counts.sum() > 3 * still.deep.counts.sum()
    np.testing.assert_allclose(flatten(blurred.deep), blurred.frame.rgba, atol=1e-5 * blurred.frame.rgba.max())
    a = blurred.deep.channels["A"]
    assert np.all((a >= 0.0) & (a <= 1.0))


def test_monte_carlo_sub_frames_take_their_own_seeds():
    """A sub-frame's technique has the frame's resolved, typed settings with the seed moved on by its index (no
    text parsed again); a technique without a seed is the frame's own."""
    from warpsky.core.settings import parse_settings
    from warpsky.render.registry import technique_classes

    seeded = [cls for cls in technique_classes() if "seed" in {f.name for f in dataclasses.fields(cls.Settings)}]
    unseeded = [cls for cls in technique_classes() if cls not in seeded]
    assert seeded and unseeded
    technique = seeded[0](parse_settings(seeded[0].Settings, {"seed": "7", "spp": "16"}))
    subs = [sub_frame_technique(technique, k) for k in range(3)]
    assert [s.settings.seed for s in subs] == [7, 8, 9]
    assert all(dataclasses.replace(s.settings, seed=7) == technique.settings for s in subs)
    assert all(type(s) is type(technique) and s.device == technique.device for s in subs)
    plain = unseeded[0]()
    assert sub_frame_technique(plain, 2) is plain


def test_a_blurred_frame_is_planned_once(tmp_path, homogeneous_npy, monkeypatch):
    """An 8-sub-frame blurred frame makes its plan once (technique and passes built, settings resolved) and reads
    the stage once at its time code and once per sub-frame."""
    from warpsky.render import planned
    from warpsky.usd.stage import StageReader

    calls = {"make_plan": 0, "scene_at": []}
    make_plan, scene_at = planned.make_plan, StageReader.scene_at

    def counted_plan(*args, **kwargs):
        calls["make_plan"] += 1
        return make_plan(*args, **kwargs)

    def counted_read(self, time=None, **kwargs):
        calls["scene_at"].append(time)
        return scene_at(self, time, **kwargs)

    monkeypatch.setattr(planned, "make_plan", counted_plan)
    monkeypatch.setattr(StageReader, "scene_at", counted_read)
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy)
    image = warpsky.render_stage(stage, 1.0, motion_samples=8, **FAST)
    assert image.metadata["motionSamples"] == 8
    assert calls["make_plan"] == 1
    assert calls["scene_at"] == [1.0, *sub_frame_times(1.0, (0.0, 1.0), 8)]


def test_a_blurred_path_traced_frame_averages_sub_frames_seeded_in_turn(tmp_path, homogeneous_npy):
    """Path traced with seed 3 over 2 sub-frames: the frame is the mean of the unblurred renders at the sub-frame
    times with seeds 3 and 4, as when each sub-frame was planned from its own settings text."""
    stage = moving_stage(tmp_path / "m.usda", homogeneous_npy)
    traced = {**FAST, "technique": "path_tracer", "settings": {"spp": "2", "seed": "3"}}
    blurred = warpsky.render_stage(stage, 1.0, motion_samples=2, **traced)
    subs = [warpsky.render_stage(stage, t, shutter=(0.0, 0.0), **{**traced, "settings": {"spp": "2",
                                                                                          "seed": str(3 + k)}})
            for k, t in enumerate(sub_frame_times(1.0, (0.0, 1.0), 2))]
    np.testing.assert_array_equal(blurred.frame.rgba, np.mean([s.frame.rgba for s in subs], axis=0)
                                  .astype(np.float32))
    assert not np.array_equal(subs[0].frame.rgba, subs[1].frame.rgba)
