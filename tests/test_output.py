"""EXR and PNG writers: round trips, refusal of bad data, atomicity; frame specs and output placeholders."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.batch.frames import FramePattern, parse_frame_spec
from warpsky.core.errors import OutputError, UsageError
from warpsky.output.exr import read_exr, validate_exr, write_exr
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


def test_counts_beyond_an_exr_int_are_kept_as_floats(tmp_path):
    rgba, trans, depth = frame()
    meta = {"lookups": 2_794_000_000, "count": -2**31}  # a 1080p march's lookups pass 2^31
    image = read_exr(write_exr(tmp_path / "a.exr", rgba, transmittance=trans, depth=depth, metadata=meta))
    assert image.metadata["lookups"] == pytest.approx(2_794_000_000, rel=1e-7)  # not wrapped below zero
    assert image.metadata["count"] == -2**31


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
        assert image.text["warpsky:exposure"] == "0.5" and "sRGB - Display" in image.text["warpsky:view"]


def test_previews_go_through_the_filmic_view_with_an_automatic_exposure(tmp_path):
    """The default view is OpenColorIO's ACES SDR view: monotone, mid grey well below white, highlights rolling off
    towards it without clipping; the automatic exposure puts the 99.5th-percentile luminance at 3 (87 % of white),
    so a frame of a bright cloud in a dimmer sky shows the cloud near white with under 1 % of pixels clipped; the
    simple view is the old curve; an unknown view is refused with the choices."""
    pytest.importorskip("PyOpenColorIO")
    from warpsky.core.errors import UsageError
    from warpsky.output.png import AUTO_LEVEL, DEFAULT_VIEW, SIMPLE_VIEW, auto_exposure, check_view, encode, views

    assert DEFAULT_VIEW in views() and SIMPLE_VIEW in views()
    x = np.geomspace(1e-3, 1e3, 200)[:, None, None] * np.ones((1, 1, 3))
    y = encode(x)[:, 0, 0].astype(int)
    assert np.all(np.diff(y) >= 0) and y[-1] >= 250
    assert 70 < encode(np.full((1, 1, 3), 0.18))[0, 0, 0] < 110  # mid grey
    rng = np.random.default_rng(1)
    frame = np.broadcast_to([0.02, 0.04, 0.08], (64, 64, 3)).copy()  # a blue sky
    frame[20:40, 20:40] = rng.uniform(0.5, 1.0, (20, 20, 1)) * np.array([1.0, 1.0, 0.98])  # a sunlit cloud
    exposure = auto_exposure(frame)
    lum = frame @ np.array([0.2126, 0.7152, 0.0722])
    assert exposure * np.percentile(lum, 99.5) == pytest.approx(AUTO_LEVEL)
    shown = encode(frame, exposure=exposure)
    assert shown[20:40, 20:40].max() >= 0.85 * 255 and np.mean(shown.max(axis=-1) >= 255) < 0.01
    assert shown[0, 0, 2] > shown[0, 0, 0] + 20  # the sky stays blue
    np.testing.assert_array_equal(encode(frame, exposure=2.0, view=SIMPLE_VIEW), tonemap(frame, exposure=2.0))
    with pytest.raises(UsageError, match="--view 'Filmic'.*choose one of"):
        check_view("Filmic")


def test_the_default_view_needs_no_opencolorio(monkeypatch):
    """Without OpenColorIO the default view is accepted (shown through the simple curve, so ``warpsky info`` and a
    render without --view work on a machine without the color extra); OpenColorIO's other views are refused."""
    from warpsky.core.errors import UsageError
    from warpsky.output import png

    monkeypatch.setattr(png, "color_installed", lambda: False)
    assert png.check_view(png.DEFAULT_VIEW) == png.DEFAULT_VIEW
    assert png.shown_view(png.DEFAULT_VIEW) == png.SIMPLE_VIEW
    frame = np.full((2, 2, 3), 0.3)
    np.testing.assert_array_equal(png.encode(frame), tonemap(frame))
    with pytest.raises(UsageError, match="OpenColorIO is not installed"):
        png.check_view("Un-tone-mapped")


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
