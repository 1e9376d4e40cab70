"""EXR and PNG writers: round trips, refusal of bad data, atomicity; frame specs and output placeholders."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.batch.frames import FramePattern, parse_frame_spec
from warpsky.errors import UsageError
from warpsky.output.exr import OutputError, read_exr, validate_exr, write_exr
from warpsky.output.png import tonemap, write_png


def frame(h=6, w=7, seed=0):
    rng = np.random.default_rng(seed)
    return rng.random((h, w, 4)).astype(np.float32), rng.random((h, w, 3)).astype(np.float32), rng.random((h, w))


@pytest.mark.parametrize("half", [True, False])
def test_exr_round_trip(tmp_path, half):
    rgba, trans, depth = frame()
    meta = {"stage": "a.usda", "count": 3, "seconds": 1.25}
    path = write_exr(tmp_path / "a.exr", rgba, transmittance=trans, depth=depth, metadata=meta, half=half)
    image = read_exr(path)
    assert image.channels["R"].dtype == (np.float16 if half else np.float32)
    assert image.channels["transmittance.G"].dtype == np.float32 and image.channels["depth.Z"].dtype == np.float32
    np.testing.assert_allclose(image.rgba(), rgba, rtol=1e-3 if half else 0, atol=1e-3 if half else 0)
    np.testing.assert_array_equal(image.transmittance(), trans)
    np.testing.assert_array_equal(image.depth(), depth.astype(np.float32))
    assert image.metadata == meta
    assert validate_exr(path, required_channels=["R", "depth.Z"], metadata_expect={"count": 3})
    assert not validate_exr(path, required_channels=["R"], metadata_expect={"count": 4})


def test_written_files_get_normal_permissions(tmp_path):
    import os
    import stat

    rgba, _, _ = frame()
    mask = os.umask(0o022)
    os.umask(mask)
    for path in (write_exr(tmp_path / "a.exr", rgba), write_png(tmp_path / "a.png", rgba[..., :3])):
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask


def test_exr_refuses_nan_and_writes_nothing(tmp_path):
    rgba, trans, depth = frame()
    trans[1, 2, 0] = np.nan
    with pytest.raises(OutputError, match="transmittance.*1 NaN"):
        write_exr(tmp_path / "a.exr", rgba, transmittance=trans, depth=depth)
    assert not any(tmp_path.iterdir())


def test_half_float_overflow_is_clamped_with_a_warning(tmp_path, capsys):
    """Radiance beyond half float's largest value (65504: a frame looking into the sun) is written as 65504 with
    one warning line, not refused as Inf; 32-bit float keeps it; a color4h RenderVar does the same."""
    from warpsky.output.products import OutputVar, frame_channels

    rgba, trans, depth = frame()
    rgba[2, 3, 0] = 1.5e5
    path = write_exr(tmp_path / "a.exr", rgba, transmittance=trans, depth=depth)
    image = read_exr(path)
    assert image.channels["R"][2, 3] == np.float16(65504.0) and np.all(np.isfinite(image.rgba()))
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "65504" in err and "1 value" in err
    full = read_exr(write_exr(tmp_path / "b.exr", rgba, half=False))
    assert full.channels["R"][2, 3] == np.float32(1.5e5)

    class Frame:
        pass

    f = Frame()
    f.rgba, f.transmittance, f.depth, f.aovs = rgba, trans, depth, {}
    channels = frame_channels(f, [OutputVar("", "color", "RGBA", True)])
    assert channels["R"].dtype == np.float16 and channels["R"][2, 3] == np.float16(65504.0)
    assert "channel R" in capsys.readouterr().err


def test_exr_unwritable_directory(tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a directory")
    rgba, _, _ = frame()
    with pytest.raises(OutputError, match="file.txt"):
        write_exr(blocker / "a.exr", rgba)


def test_truncated_exr_is_detected(tmp_path):
    rgba, trans, depth = frame(64, 64)
    path = write_exr(tmp_path / "a.exr", rgba, transmittance=trans, depth=depth)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    assert not validate_exr(path, required_channels=["R"])
    with pytest.raises(OutputError, match="a.exr"):
        read_exr(path)


def test_failed_write_keeps_the_previous_file(tmp_path):
    rgba, _, _ = frame()
    path = write_exr(tmp_path / "a.exr", rgba, metadata={"run": 1})
    with pytest.raises(OutputError):
        write_exr(path, rgba, metadata={"run": object()})
    assert read_exr(path).metadata == {"run": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["a.exr"]


def test_tonemap_is_bounded_monotone_and_safe():
    x = np.linspace(0, 50, 200)[:, None, None] * np.ones((1, 1, 3))
    y = tonemap(x)[:, 0, 0].astype(int)
    assert y[0] == 0 and y[-1] == 255 and np.all(np.diff(y) >= 0)
    bad = np.array([[[np.nan, -1.0, np.inf]]])
    assert tonemap(bad).tolist() == [[[0, 0, 0]]]


def test_png_written(tmp_path):
    from PIL import Image

    path = write_png(tmp_path / "p.png", np.ones((5, 9, 3)), exposure=0.5)
    with Image.open(path) as image:
        assert image.size == (9, 5)


@pytest.mark.parametrize("spec,expected", [
    ("1", [1.0]), ("1:5", [1.0, 2.0, 3.0, 4.0, 5.0]), ("1:6x2", [1.0, 3.0, 5.0]), ("1:2x0.5", [1.0, 1.5, 2.0]),
    ("1,3,5:6", [1.0, 3.0, 5.0, 6.0]), ("-2:0", [-2.0, -1.0, 0.0]),
])
def test_frame_specs(spec, expected):
    assert parse_frame_spec(spec) == expected


@pytest.mark.parametrize("spec", ["1:x", "abc", "", "1,,2", "5:1x0"])
def test_malformed_frame_specs(spec):
    with pytest.raises(UsageError, match="--frames"):
        parse_frame_spec(spec)


def test_placeholders():
    assert str(FramePattern("out/f.####.exr").path_for(12)) == "out/f.0012.exr"
    assert str(FramePattern("out/f.####.exr").path_for(-3)) == "out/f.-003.exr"
    assert str(FramePattern("f.###.##.exr").path_for(1.5)) == "f.001.50.exr"
    assert str(FramePattern("f.#.exr").path_for(123)) == "f.123.exr"
    with pytest.raises(UsageError, match="subframe"):
        FramePattern("f.####.exr").path_for(1.5)
    with pytest.raises(UsageError, match="placeholders"):
        FramePattern("a.##.b.##.exr")
    with pytest.raises(UsageError, match="placeholder"):
        FramePattern("plain.exr").require_placeholder(2)
    FramePattern("plain.exr").require_placeholder(1)
    with pytest.raises(UsageError, match=r"\.exr"):
        FramePattern("f.####.tif")
