"""Motion blur over the camera's shutter: the average of sub-frames at the midpoints of the shutter's parts."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli as run

import warpsky
from warpsky.core.errors import SceneError
from warpsky.output.exr import read_exr
from warpsky.render.frame import RenderOptions
from warpsky.render.motion import sub_frame_options, sub_frame_times

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
    options = RenderOptions(settings={"seed": "7", "spp": "16"}, shutter=(-0.5, 0.5))
    subs = [sub_frame_options(options, k, seeded=True) for k in range(3)]
    assert [s.settings["seed"] for s in subs] == ["7", "8", "9"] and all(s.shutter == (0.0, 0.0) for s in subs)
    assert sub_frame_options(options, 2, seeded=False).settings == options.settings
