"""Deep EXR output: samples built from the composited layers flatten, by OpenEXR's rule, to the flat frame."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, write_stage
from conftest import run_cli as run

from warpsky.core.image import ImageLayer
from warpsky.output.deep import deep_from_layers, deep_path, flatten
from warpsky.output.exr import read_exr
from warpsky.passes.composite import composite

FAR = 1.0e5
FAST = ["--device", "cpu", "--technique", "single_scatter", "--set", "step_length=1"]


def layer(radiance, transmittance, depth, shape=(2, 3)) -> ImageLayer:
    h, w = shape
    return ImageLayer(radiance=np.broadcast_to(np.asarray(radiance, np.float32), (h, w, 3)).copy(),
                      transmittance=np.broadcast_to(np.asarray(transmittance, np.float32), (h, w, 3)).copy(),
                      depth=np.broadcast_to(np.asarray(depth, np.float32), (h, w)).copy())


def test_flattening_gives_back_the_composite_with_coloured_transmittance():
    """Three layers with strongly coloured transmittance (a blue-tinting haze, a reddish cloud, an opaque ground),
    one out of depth order and one showing nothing: flattened colour and alpha equal the composite to float
    precision, depths never decrease along a pixel, and a layer that shows nothing (or is hidden) has no sample."""
    rng = np.random.default_rng(4)
    shape = (5, 7)
    haze = layer(rng.uniform(0, 0.2, shape + (3,)), [0.9, 0.7, 0.4], rng.uniform(10, 20, shape), shape)
    empty = layer(0.0, 1.0, FAR, shape)
    cloud = layer(rng.uniform(0, 2.0, shape + (3,)), rng.uniform(0.05, 0.9, shape + (3,)), 5.0, shape)  # nearer
    ground = layer([0.3, 0.25, 0.2], 0.0, 500.0, shape)
    sky = layer([0.1, 0.2, 0.5], 1.0, FAR, shape)  # behind the opaque ground: hidden
    layers = [haze, empty, cloud, ground, sky]
    deep = deep_from_layers(layers, FAR)
    flat = composite(layers, FAR).rgba
    np.testing.assert_allclose(flatten(deep), flat, rtol=1e-5, atol=1e-6)
    assert np.all(deep.counts == 3)  # haze, cloud, ground
    z = deep.channels["Z"].reshape(-1, 3)
    assert np.all(np.diff(z, axis=1) >= 0.0) and np.array_equal(deep.channels["Z"], deep.channels["ZBack"])
    assert np.all((deep.channels["A"] >= 0.0) & (deep.channels["A"] <= 1.0))
    np.testing.assert_allclose(deep.channels["A"].reshape(-1, 3)[:, 2], 1.0, atol=1e-6)  # the ground is opaque


def test_a_colour_matrix_commutes_with_flattening():
    rng = np.random.default_rng(5)
    shape = (3, 4)
    layers = [layer(rng.uniform(0, 1, shape + (3,)), rng.uniform(0.1, 1, shape + (3,)), 3.0, shape),
              layer([0.2, 0.3, 0.4], 1.0, FAR, shape)]
    m = np.array([[0.61, 0.34, 0.05], [0.07, 0.92, 0.01], [0.02, 0.11, 0.87]])
    flat = composite(layers, FAR).rgba
    np.testing.assert_allclose(flatten(deep_from_layers(layers, FAR, m))[..., :3], flat[..., :3] @ m.T, rtol=1e-5,
                               atol=1e-6)


def read_deep(path) -> dict:
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        header = dict(exr.header())
        channels = {name: ch.pixels for name, ch in exr.channels().items()}
    return header, channels


@pytest.mark.parametrize("colorspace", ["lin_rec709", "ACEScg"])
def test_render_writes_a_deep_exr_that_flattens_to_the_frame(tmp_path, homogeneous_npy, capsys, colorspace):
    """warpsky render --deep --deep-samples 5: beside the flat frame a deep scanline EXR whose samples, read back
    with OpenEXR and flattened, give the frame's RGBA within 1e-3 (its 32-bit floats), with the frame's header
    attributes; the box is at most 5 volume samples per pixel (and the ground a point behind them)."""
    from warpsky.output.deep import DeepPixels

    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40),
                                                       ground=(-12.0, 0.3)))
    out = tmp_path / "f.exr"
    code, _, err = run(["render", stage, out, "--res", "24x16", "--deep", "--deep-samples", "5", "--float",
                        "--colorspace", colorspace, *FAST], capsys)
    assert code == 0, err
    header, channels = read_deep(deep_path(out))
    assert str(header["type"]).endswith("deepscanline") and sorted(channels) == ["A", "B", "G", "R", "Z", "ZBack"]
    assert header["warpsky/colorspace"] == colorspace and "worldToCamera" in header and "chromaticities" in header
    assert header["warpsky/deepSamples"] == 5
    counts = np.vectorize(lambda samples: 0 if samples is None else len(samples), otypes=[int])(channels["A"])
    volume = np.vectorize(lambda z, back: 0 if z is None else int(np.sum(z < back)), otypes=[int])(channels["Z"],
                                                                                                 channels["ZBack"])
    assert volume.max() == 5 and counts.max() == 6
    flat = read_exr(out)
    rgba = np.stack([flat.channels[c].astype(np.float64) for c in "RGBA"], axis=-1)
    assert counts.shape == (16, 24) and np.all(counts[rgba.max(axis=-1) > 0.0] >= 1)  # a sample wherever it shows
    deep = DeepPixels(counts, {name: np.concatenate([v for v in values.reshape(-1) if v is not None])
                               for name, values in channels.items()})
    np.testing.assert_allclose(flatten(deep), rgba, atol=1e-3 * rgba[..., :3].max())


def test_without_deep_no_deep_file_and_an_unchanged_settings_hash(tmp_path, homogeneous_npy, capsys):
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    out = tmp_path / "f.exr"
    code, _, err = run(["render", stage, out, "--res", "8", *FAST], capsys)
    assert code == 0 and not (tmp_path / "f.deep.exr").exists(), err
    flat_hash = read_exr(out).metadata["settingsHash"]
    code, _, err = run(["render", stage, out, "--res", "8", "--deep", *FAST], capsys)  # not up to date: re-rendered
    assert code == 0 and (tmp_path / "f.deep.exr").exists(), err
    assert read_exr(out).metadata["settingsHash"] != flat_hash


def test_merged_layers_are_samples_of_their_own_in_depth_order_and_the_air_spans_to_them():
    """A merge of two layers whose depths cross between pixels gives one sample each, nearer first in every
    pixel; the air in front (no depth) is a volume sample from the camera to the first of them, the sky a point at
    the far clip; flattening still gives the composite."""
    from warpsky.passes.composite import merge_by_depth

    shape = (1, 2)
    a = layer([0.5, 0.4, 0.3], [0.5, 0.6, 0.7], np.array([[10.0, 30.0]]), shape)
    b = layer([0.1, 0.2, 0.3], [0.2, 0.3, 0.4], np.array([[20.0, 15.0]]), shape)
    air = layer([0.01, 0.02, 0.05], [0.95, 0.9, 0.8], FAR, shape)
    sky = layer([0.1, 0.2, 0.4], 1.0, FAR, shape)
    layers = [air, merge_by_depth([a, b], FAR), sky]
    deep = deep_from_layers(layers, FAR)
    assert list(deep.counts.reshape(-1)) == [4, 4]
    np.testing.assert_allclose(deep.channels["Z"], [0, 10, 20, FAR, 0, 15, 30, FAR])
    np.testing.assert_allclose(deep.channels["ZBack"], [10, 10, 20, FAR, 15, 15, 30, FAR])
    np.testing.assert_allclose(flatten(deep), composite(layers, FAR).rgba, rtol=1e-5, atol=1e-7)
    alone = deep_from_layers([air, sky], FAR)  # nothing bounded: the air is a point at the far clip
    np.testing.assert_allclose(alone.channels["Z"], FAR)


def test_light_already_seen_through_a_layer_is_a_clear_sample_ahead_of_it():
    """A layer's ``front`` light (paths already attenuated to the eye, as hybrid's over fog and terrain) is a
    sample of alpha 0 at the group's nearest depth, after the air in front: flattening gives the composite, merged
    or not."""
    from warpsky.passes.composite import merge_by_depth

    shape = (1, 2)
    air = layer([0.01, 0.02, 0.05], [0.95, 0.9, 0.8], FAR, shape)
    fog = layer([0.2, 0.2, 0.2], [0.4, 0.4, 0.4], np.array([[30.0, 50.0]]), shape)
    fog.front = layer([0.3, 0.25, 0.2], 1.0, FAR, shape)
    terrain = layer([0.1, 0.1, 0.1], 0.0, np.array([[40.0, 45.0]]), shape)
    for layers in ([air, merge_by_depth([fog, terrain], FAR)], [air, fog, terrain]):
        deep = deep_from_layers(layers, FAR)
        np.testing.assert_allclose(flatten(deep), composite(layers, FAR).rgba, rtol=1e-5, atol=1e-7)
    deep = deep_from_layers([air, merge_by_depth([fog, terrain], FAR)], FAR)
    assert list(deep.counts.reshape(-1)) == [4, 3]  # air, the paths' light, the parts (the fog behind the terrain
    # in the second pixel is hidden)
    np.testing.assert_allclose(deep.channels["A"][[1, 5]], 0.0)
    np.testing.assert_allclose(deep.channels["Z"][:4], [0.0, 30.0, 30.0, 40.0])


def test_a_missing_deep_file_renders_the_frame_again(tmp_path, homogeneous_npy, capsys):
    """A batch with --deep resumes a frame whose flat EXR is up to date but whose deep EXR is gone."""
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    args = ["render", stage, tmp_path / "f.####.exr", "--frames", "1", "--res", "8", "--deep", *FAST]
    code, _, err = run(args, capsys)
    deep = tmp_path / "f.0001.deep.exr"
    assert code == 0 and deep.is_file(), err
    stamp = (tmp_path / "f.0001.exr").stat().st_mtime_ns
    deep.unlink()
    code, _, err = run(args, capsys)
    assert code == 0 and deep.is_file() and (tmp_path / "f.0001.exr").stat().st_mtime_ns != stamp, err


def test_a_deep_raster_product_is_a_deep_exr_that_flattens_to_its_raster_sibling(tmp_path, homogeneous_npy,
                                                                                  capsys, monkeypatch):
    """A RenderProduct of productType deepRaster (as Solaris writes for Nuke) is written as a deep scanline EXR at
    its productName, with no flat file: it flattens to the raster product of the same camera within 1e-3, a
    RenderVar a deep image cannot hold is named in one warning, its int warpsky:deepSamples sets the volume samples
    per pixel, and a second run finds the frame up to date."""
    from test_usd_render import add_render

    from warpsky.output.deep import DeepPixels

    monkeypatch.chdir(tmp_path)
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40),
                                                       ground=(-12.0, 0.3)))
    add_render(stage, {
        "Beauty": ("out/beauty.$F4.exr", None, None, [("color", "color", "color4f", "raw")], None),
        "Deep": ("out/deep.$F4.exr", None, None, [("color", "color", "color4f", "raw"),
                                                  ("tau", "transmittance", "color3f", "raw")],
                 {"productType": "deepRaster"}),
    }, second_camera=False)
    from pxr import Sdf, Usd

    usd = Usd.Stage.Open(str(stage))
    usd.GetPrimAtPath("/Render/Deep").CreateAttribute("warpsky:deepSamples", Sdf.ValueTypeNames.Int).Set(3)
    usd.Save()
    code, stdout, err = run(["render", stage, "--frames", "1", "--float", *FAST], capsys)
    assert code == 0, err
    assert "RenderVar /Render/Deep/tau (transmittance): a deep product holds" in err
    assert not (tmp_path / "out/deep.0001.deep.exr").exists()
    header, channels = read_deep(tmp_path / "out/deep.0001.exr")
    assert str(header["type"]).endswith("deepscanline") and sorted(channels) == ["A", "B", "G", "R", "Z", "ZBack"]
    counts = np.vectorize(lambda samples: 0 if samples is None else len(samples), otypes=[int])(channels["A"])
    deep = DeepPixels(counts, {name: np.concatenate([v for v in values.reshape(-1) if v is not None])
                               for name, values in channels.items()})
    assert header["warpsky/deepSamples"] == 3 and np.sum(deep.channels["Z"] < deep.channels["ZBack"]) > 0
    assert np.max(np.add.reduceat((deep.channels["Z"] < deep.channels["ZBack"]).astype(int),
                                  np.cumsum(counts.reshape(-1)) - counts.reshape(-1))[counts.reshape(-1) > 0]) == 3
    flat = read_exr(tmp_path / "out/beauty.0001.exr")
    rgba = np.stack([flat.channels[c].astype(np.float64) for c in "RGBA"], axis=-1)
    np.testing.assert_allclose(flatten(deep), rgba, atol=1e-3 * rgba[..., :3].max())
    code, _, err = run(["render", stage, "--frames", "1", "--float", *FAST], capsys)
    assert code == 0 and err.count("1 skipped") == 2, err


def test_an_unknown_product_type_names_the_product_and_what_is_written(tmp_path, homogeneous_npy, capsys):
    from test_usd_render import add_render

    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    add_render(stage, {"Cryptomatte": (str(tmp_path / "c.exr"), None, None, [("color", "color", "color4f", "raw")],
                                       {"productType": "cryptomatte"})}, second_camera=False)
    code, _, err = run(["render", stage, *FAST], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "/Render/Cryptomatte.productType 'cryptomatte'" in err and "'deepRaster'" in err


def test_averaged_deep_images_flatten_to_the_mean_of_their_flattenings():
    """Three deep images of random samples (opaque, translucent and empty ones, coincident depths between
    images, pixels without samples): their average flattens, front to back, to the mean of their flattenings
    within 1e-6, with every alpha in [0, 1] and depths non-decreasing along each pixel."""
    from warpsky.output.deep import DeepPixels, average_deep

    rng = np.random.default_rng(11)
    deeps = []
    for _ in range(3):
        counts = rng.integers(0, 4, size=(4, 5))
        total = int(counts.sum())
        z = np.concatenate([np.sort(rng.choice([5.0, 10.0, 20.0, 40.0], n)) for n in counts.reshape(-1)])
        alpha = rng.choice([0.0, 0.3, 0.9, 1.0], total)
        channels = {c: rng.uniform(0, 1, total).astype(np.float32) for c in "RGB"}
        channels.update(A=alpha.astype(np.float32), Z=z.astype(np.float32), ZBack=z.astype(np.float32))
        deeps.append(DeepPixels(counts, channels))
    mean = np.mean([flatten(d) for d in deeps], axis=0)
    merged = average_deep(deeps)
    np.testing.assert_allclose(flatten(merged), mean, atol=1e-6)
    assert np.all((merged.channels["A"] >= 0.0) & (merged.channels["A"] <= 1.0))
    start = np.cumsum(merged.counts.reshape(-1)) - merged.counts.reshape(-1)
    for s, n in zip(start, merged.counts.reshape(-1), strict=True):
        assert np.all(np.diff(merged.channels["Z"][s:s + n]) >= 0.0)
