"""Previews people look at: a 3-D stage overview (pyvista offscreen, EGL) and contact sheets of frames."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, write_stage

from warpsky.cli.main import main


def _png(path):
    from PIL import Image

    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


@pytest.fixture
def stage(tmp_path):
    x = np.linspace(-1, 1, 12)
    blob = np.exp(-3.0 * (x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)).astype(np.float32)
    np.save(tmp_path / "blob.npy", blob)
    spec = StageSpec(volume_file=tmp_path / "blob.npy", camera_position=(0.0, 5.0, 60.0),
                     camera_rotation=look_rotation((0.0, -0.1, -1.0)), ground=(-15.0, 0.3))
    return write_stage(tmp_path / "blob.usda", spec)


def test_stage_preview_draws_something(stage, tmp_path, capsys):
    pytest.importorskip("pyvista", reason="the preview extra (pyvista) is not installed")
    out = tmp_path / "preview.png"
    try:
        code = main(["preview", str(stage), "-o", str(out), "--size", "320x240"])
    except RuntimeError as exc:  # VTK raises when no EGL/OpenGL context can be made
        pytest.skip(f"no offscreen OpenGL (EGL) context on this machine: {exc}")
    assert code == 0 and str(out) in capsys.readouterr().out
    image = _png(out)
    assert image.shape == (240, 320, 3)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50  # background gradient, isosurface, frustum, legend


def test_preview_legend_lies_inside_the_image(stage, tmp_path, capsys):
    """The legend's dark box keeps a margin to every edge (pyvista's own placement ran off the right edge)."""
    pytest.importorskip("pyvista", reason="the preview extra (pyvista) is not installed")
    out = tmp_path / "preview.png"
    try:
        assert main(["preview", str(stage), "-o", str(out), "--size", "400x300"]) == 0
    except RuntimeError as exc:
        pytest.skip(f"no offscreen OpenGL (EGL) context on this machine: {exc}")
    image = _png(out).astype(int)
    box = np.abs(image - np.array([20, 23, 26])).max(axis=-1) <= 2  # the legend's background (0.08, 0.09, 0.1)
    rows, columns = np.nonzero(box)
    assert columns.size > 0  # the legend is there
    assert columns.min() >= 2 and rows.min() >= 2 and columns.max() <= 400 - 3 and rows.max() <= 300 - 3
    assert columns.max() - columns.min() >= 0.4 * 400  # at its full width, not clipped


def test_contact_sheet_tiles_frames_and_flags_broken_ones(stage, tmp_path, capsys):
    out = tmp_path / "out" / "f.####.exr"
    assert main(["render", str(stage), str(out), "--frames", "1:3", "--res", "16x12", "--device", "cpu",
                 "--technique", "slicing", "--set", "slice_count=8", "--set", "orders=8"]) == 0
    broken = tmp_path / "out" / "f.0004.exr"
    broken.write_bytes((tmp_path / "out" / "f.0003.exr").read_bytes()[:100])
    sheet = tmp_path / "sheet.png"
    assert main(["contact-sheet", str(out), "-o", str(sheet), "--columns", "2", "--tile-width", "64"]) == 0
    image = _png(sheet)
    assert image.shape == (2 * (48 + 18), 128, 3)
    assert image[..., 0].max() > 0 and image[48 + 18 + 10, 64 + 10].tolist() == [0x7A, 0x10, 0x10]  # 4th: red
    assert main(["contact-sheet", str(tmp_path / "none.####.exr"), "-o", str(sheet)]) == 2
