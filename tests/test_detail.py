"""Animated density detail of voxel media: USD attributes, the has_detail kernel specialisations of
half-angle slicing and single scattering, random access in time through the whole render path, far from the
origin."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, write_stage

from warpsky.core.errors import SceneError
from warpsky.media.voxels import detail as detail_module
from warpsky.model.scene import DetailSpec
from warpsky.techniques.single_scatter.single_scatter import SingleScatter, SingleScatterSettings
from warpsky.techniques.slicing.slicing import Slicing, SlicingSettings
from warpsky.usd.stage import StageReader

SIZE = 16
#: Detail features of 15 m on a 160 m blob: a tile of 480 m.
SPEC = DetailSpec(amplitude=0.5, scale=15.0, wind=(6.0, 0.0, 2.0), curl_speed=2.0, period=1.0, seed=3)


def blob(path, size: int = 24):
    """A smooth Gaussian blob filling a size^3 grid."""
    x = np.linspace(-1.0, 1.0, size)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    np.save(path, np.exp(-3.0 * (X**2 + Y**2 + Z**2)).astype(np.float32))
    return path


def detail_stage(tmp_path, spec: DetailSpec | None = SPEC, *, offset=(0.0, 0.0, 0.0), name="cloud.usda"):
    """A blob of 160 m seen from 400 m, with ``warpsky:detail:*`` from ``spec`` on its Volume; 24 time codes/s."""
    from pxr import Sdf, Usd

    offset = np.asarray(offset, dtype=np.float64)
    stage_spec = StageSpec(volume_file=blob(tmp_path / "blob.npy"), volume_extent=((-80.0,) * 3, (80.0,) * 3),
                           volume_translate=tuple(offset.tolist()), extinction_scale=0.05,
                           camera_position=tuple((offset + [0.0, 30.0, 400.0]).tolist()),
                           camera_rotation=look_rotation((0.0, -0.075, -1.0)), sun_direction=(0.5, 0.7, 0.4),
                           phase="hg", g=0.8, clipping=(1.0, 1.0e4))
    path = write_stage(tmp_path / name, stage_spec)
    stage = Usd.Stage.Open(str(path))
    stage.SetTimeCodesPerSecond(24.0)
    if spec is not None:
        prim = stage.GetPrimAtPath("/World/Cloud")
        f = Sdf.ValueTypeNames
        for attr, kind, value in (("amplitude", f.Float, spec.amplitude), ("scale", f.Float, spec.scale),
                                  ("wind", f.Float3, spec.wind), ("curlSpeed", f.Float, spec.curl_speed),
                                  ("period", f.Float, spec.period), ("seed", f.Int, spec.seed)):
            prim.CreateAttribute(f"warpsky:detail:{attr}", kind).Set(value)
    stage.Save()
    return path


def slicing(device):
    return Slicing(SlicingSettings(slice_count=16, light_resolution=16), device=device)


def render(technique, stage_path, time_code: float):
    return technique.render(StageReader(stage_path).scene_at(time_code), SIZE, SIZE)


def test_detail_attributes_are_read_in_metres_seconds_and_stage_axes(tmp_path):
    from pxr import Usd, UsdGeom

    scene = StageReader(detail_stage(tmp_path)).scene_at(48.0)
    assert scene.time_s == pytest.approx(2.0)
    spec = scene.media[0].detail
    assert dataclasses.replace(spec, name=SPEC.name) == SPEC
    # a Z-up stage in centimetres: the wind turns into warpsky's Y-up axes and stays in m/s
    path = detail_stage(tmp_path, name="z.usda")
    stage = Usd.Stage.Open(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.GetPrimAtPath("/World/Cloud").GetAttribute("warpsky:detail:wind").Set((1.0, 2.0, 3.0))
    stage.Save()
    np.testing.assert_allclose(StageReader(path).scene_at(1.0).media[0].detail.wind, (1.0, 3.0, -2.0))


@pytest.mark.parametrize("attr, kind, value, expected", [
    ("amplitude", "Float", 1.5, r"warpsky:detail:amplitude must lie in \[0, 1\], got 1.5"),
    ("amplitude", "Float", -0.1, r"warpsky:detail:amplitude must lie in \[0, 1\]"),
    ("scale", "Float", 0.0, r"warpsky:detail:scale must be a positive length \[m\], got 0"),
    ("period", "Float", -2.0, r"warpsky:detail:period must be a positive duration \[s\]"),
    ("curlSpeed", "Float", float("inf"), r"warpsky:detail:curlSpeed must be a finite float"),
    ("seed", "Int", -4, r"warpsky:detail:seed must be an int >= 0, got -4"),
    ("seed", "Float", 2.5, r"warpsky:detail:seed must be an int >= 0, got 2.5"),
    ("wind", "Float", 3.0, r"warpsky:detail:wind must be a float3 \[m/s\]"),
    ("wind", "Float3", (1.0, float("nan"), 0.0), r"warpsky:detail:wind must be 3 finite speeds"),
    ("windSpeed", "Float", 3.0, r"unknown attribute\(s\) warpsky:detail:windSpeed"),
])
def test_bad_detail_attributes_name_the_prim_and_attribute(tmp_path, attr, kind, value, expected):
    from pxr import Sdf, Usd

    path = detail_stage(tmp_path)
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/World/Cloud")
    prim.RemoveProperty(f"warpsky:detail:{attr}")
    prim.CreateAttribute(f"warpsky:detail:{attr}", getattr(Sdf.ValueTypeNames, kind)).Set(value)
    stage.Save()
    with pytest.raises(SceneError, match=r"/World/Cloud.*" + expected):
        StageReader(path).scene_at(1.0)


def set_edge(path, edge: float, prim_path: str = "/World/Cloud/density"):
    """Author ``warpsky:detail:edge`` [1/m] on ``prim_path`` of the stage at ``path``."""
    from pxr import Sdf, Usd

    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath(prim_path).CreateAttribute("warpsky:detail:edge", Sdf.ValueTypeNames.Float).Set(edge)
    stage.Save()
    return path


def test_the_edge_is_read_per_field_and_its_mistakes_are_named(tmp_path):
    """``warpsky:detail:edge`` on a field prim joins the Volume's detail for that field; on the Volume, negative,
    or without the Volume's detail it is refused with the prim and what to do."""
    from pxr import Usd

    path = set_edge(detail_stage(tmp_path), 0.01)
    spec = StageReader(path).scene_at(7.0).media[0].detail
    assert spec.edge == pytest.approx(0.01) and dataclasses.replace(spec, edge=0.0, name=SPEC.name) == SPEC
    with pytest.raises(SceneError, match=r"/World/Cloud/density: warpsky:detail:edge must be a finite extinction"):
        StageReader(set_edge(detail_stage(tmp_path, name="neg.usda"), -0.01)).scene_at(7.0)
    with pytest.raises(SceneError, match=r"Volume /World/Cloud: warpsky:detail:edge goes on each field prim"):
        StageReader(set_edge(detail_stage(tmp_path, name="vol.usda"), 0.01, "/World/Cloud")).scene_at(7.0)
    off = set_edge(detail_stage(tmp_path, name="off.usda"), 0.01)
    stage = Usd.Stage.Open(str(off))
    stage.GetPrimAtPath("/World/Cloud").GetAttribute("warpsky:detail:amplitude").Set(0.0)
    stage.Save()
    with pytest.raises(SceneError, match=r"density.warpsky:detail:edge = 0.01.* needs the Volume's detail"):
        StageReader(off).scene_at(7.0)


def test_the_edge_takes_its_extinction_off_the_detailed_field(tmp_path, device):
    """Baked on the same fine voxels, the field with an edge of 0.01 1/m (extinction 0.05 per unit: 0.2 in field
    units) is the field without it less 0.2, floored at zero, voxel for voxel: the fringe clears, the peak stays."""
    from warpsky.media.voxels.detail_bake import baked_media

    fine = dataclasses.replace(SPEC, scale=6.0)
    scene = StageReader(set_edge(detail_stage(tmp_path, fine), 0.01)).scene_at(7.0)
    (medium,) = scene.media
    plain = dataclasses.replace(medium, detail=dataclasses.replace(medium.detail, edge=0.0))
    (with_edge,) = baked_media(scene.media, scene.time_s, scene.camera.position, device)
    (without,) = baked_media((plain,), scene.time_s, scene.camera.position, device)
    expected = np.maximum(without.density - 0.01 / 0.05, 0.0)
    np.testing.assert_allclose(with_edge.density, expected, rtol=1e-5, atol=1e-6)
    assert (without.density > 0.0).mean() > 2.0 * (with_edge.density > 0.0).mean()  # the fringe is most voxels
    assert with_edge.density.max() > 0.5 * without.density.max()


def test_amplitude_zero_is_bit_identical_to_no_detail(tmp_path, device):
    """Amplitude 0 on a Volume turns detail off; inside the has_detail kernels a medium of amplitude 0 keeps its
    coarse density exactly (a second, empty medium with detail selects those kernels)."""
    from pxr import Usd

    path = detail_stage(tmp_path)
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath("/World/Cloud").GetAttribute("warpsky:detail:amplitude").Set(0.0)
    stage.Save()
    scene = StageReader(path).scene_at(7.0)
    assert scene.media[0].detail is None
    plain = scene.media[0]
    empty = dataclasses.replace(plain, name="empty", density=np.zeros_like(plain.density))
    without = dataclasses.replace(scene, media=(plain, empty))
    with_kernels = dataclasses.replace(scene, media=(dataclasses.replace(plain, detail=dataclasses.replace(
        SPEC, amplitude=0.0)), dataclasses.replace(empty, detail=SPEC)))
    for technique in (slicing(device), SingleScatter(SingleScatterSettings(step_length=8.0,
                                                                           shadow_step_length=16.0), device=device)):
        a = technique.render(without, SIZE, SIZE)
        b = technique.render(with_kernels, SIZE, SIZE)
        assert a.radiance.max() > 0.0
        np.testing.assert_array_equal(b.radiance, a.radiance)
        np.testing.assert_array_equal(b.transmittance, a.transmittance)


def test_a_frame_rendered_cold_equals_the_frame_reached_by_playback(tmp_path, device):
    """Random access through the whole render path: frame 30 after a cleared cache equals frame 30 after frames
    1..29 (which cross layer regenerations every 8 frames)."""
    path = detail_stage(tmp_path)
    technique = slicing(device)
    detail_module.clear_cache()
    cold = render(technique, path, 30.0)
    detail_module.clear_cache()
    for frame in range(1, 30):
        render(technique, path, float(frame))
    warm = render(technique, path, 30.0)
    np.testing.assert_array_equal(warm.radiance, cold.radiance)
    np.testing.assert_array_equal(warm.transmittance, cold.transmittance)


def relative_change(a, b) -> float:
    return float(np.abs(a.radiance - b.radiance).max() / a.radiance.max())


def test_detail_moves_with_wind_and_curl_and_stands_still_without(tmp_path, device):
    technique = slicing(device)
    coarse = render(technique, detail_stage(tmp_path, None, name="coarse.usda"), 1.0)
    windy = detail_stage(tmp_path, name="windy.usda")
    first, later = render(technique, windy, 1.0), render(technique, windy, 25.0)
    print(f"detail vs coarse: {relative_change(coarse, first):.3f}, windy frame 1 vs 25: "
          f"{relative_change(first, later):.3f}")
    assert relative_change(coarse, first) > 0.05  # the detail is visible
    assert relative_change(first, later) > 0.05  # and moves: 24 frames of wind carry it 6 m = 0.4 features
    curl_only = detail_stage(tmp_path, dataclasses.replace(SPEC, wind=(0.0, 0.0, 0.0), curl_speed=30.0),
                             name="curl.usda")
    curl_frames = [render(technique, curl_only, t) for t in (1.0, 13.0, 25.0)]
    print(f"curl only, frame 1 vs 13: {relative_change(curl_frames[0], curl_frames[1]):.3f}")
    assert relative_change(curl_frames[0], curl_frames[1]) > 0.004  # measured 0.011
    # a steady curl flow without wind restarts every layer identically: the detail repeats every period (24 frames)
    np.testing.assert_array_equal(curl_frames[2].radiance, curl_frames[0].radiance)
    still = detail_stage(tmp_path, dataclasses.replace(SPEC, wind=(0.0, 0.0, 0.0), curl_speed=0.0), name="s.usda")
    frames = [render(technique, still, t) for t in (1.0, 13.0, 500.0)]  # layers regenerate, the pattern stays
    assert relative_change(coarse, frames[0]) > 0.05
    for frame in frames[1:]:
        np.testing.assert_array_equal(frame.radiance, frames[0].radiance)
    # single scattering sees the same detail (view and shadow rays)
    march = SingleScatter(SingleScatterSettings(step_length=4.0, shadow_step_length=8.0), device=device)
    assert relative_change(render(march, windy, 1.0), render(march, windy, 25.0)) > 0.05


def test_a_scene_100_km_from_the_origin_renders_the_same_detail(tmp_path, device):
    """Camera and cloud moved 100.32 km (a whole number of 480 m detail tiles): same image to float32 precision."""
    technique = slicing(device)
    near = render(technique, detail_stage(tmp_path, name="near.usda"), 20.0)
    shift = (209 * 480.0, 0.0, -209 * 480.0)
    far = render(technique, detail_stage(tmp_path, offset=shift, name="far.usda"), 20.0)
    for values in (far.radiance, far.transmittance):
        assert np.all(np.isfinite(values))
    np.testing.assert_allclose(far.radiance, near.radiance, rtol=0, atol=2e-3 * near.radiance.max())
    np.testing.assert_allclose(far.transmittance, near.transmittance, rtol=0, atol=2e-3)


@pytest.mark.parametrize("edge", [0.0, 0.01])
def test_the_path_tracer_renders_detail_without_bias(tmp_path, device, edge):
    """With one bounce the path tracer estimates single scattering: through the detailed density (majorants scaled
    by the detail's bound 1 + 3a) it agrees with the single-scattering march of the same detailed field, and both
    differ clearly from the coarse field (with an edge: from the detail without it)."""
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    stage = detail_stage(tmp_path)
    scene = StageReader(set_edge(stage, edge) if edge > 0.0 else stage).scene_at(7.0)
    coarse = dataclasses.replace(scene, media=tuple(
        dataclasses.replace(m, detail=dataclasses.replace(m.detail, edge=0.0) if edge > 0.0 else None)
        for m in scene.media))
    march = SingleScatter(SingleScatterSettings(step_length=0.5, shadow_step_length=1.0, min_transmittance=0.0),
                          device=device)
    reference, plain = march.render(scene, 12, 12), march.render(coarse, 12, 12)
    layer = PathTracer(PathTracerSettings(spp=512, max_bounces=1, seed=5), device=device).render(scene, 12, 12)
    variance = np.maximum(layer.aovs["variance"][..., 1], 1e-30)
    lit = variance > 1e-20
    chi2 = float(np.mean((layer.radiance[..., 1] - reference.radiance[..., 1])[lit] ** 2 / variance[lit]))
    chi2_coarse = float(np.mean((layer.radiance[..., 1] - plain.radiance[..., 1])[lit] ** 2 / variance[lit]))
    sigma = np.sqrt(layer.aovs["variance"][..., 1].sum())
    z = (layer.radiance[..., 1].sum() - reference.radiance[..., 1].sum()) / sigma
    print(f"{lit.sum()} pixels: chi2/N against the detailed march {chi2:.2f}, against the coarse march "
          f"{chi2_coarse:.2f}; z of the total {z:+.2f}")
    assert abs(z) < 4.0
    assert chi2 < 1.6  # per pixel consistent within its noise (1 expected; 4 standard errors at 144 pixels ~1.5)
    assert chi2_coarse > 3.0 * chi2  # while the coarse field is not: the test tells detail from no detail


def test_baked_detail_resamples_the_detailed_field(tmp_path, device):
    """``bake_detail``: the detailed field resampled on a grid within a detail texel (6 m features, 3 m texels, on
    6.7 m coarse voxels: 3 fine voxels per coarse edge), whose fine voxel 1 of each triple sits on the coarse centre;
    the detail raises the peak within its bound; single scattering traced through it stays within 3% of the march
    through the procedural field."""
    from warpsky.media.voxels.detail_bake import baked_media, refinement
    from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings

    fine_spec = dataclasses.replace(SPEC, scale=6.0)
    scene = StageReader(detail_stage(tmp_path, fine_spec)).scene_at(7.0)
    (medium,) = scene.media
    r = refinement(medium)
    (baked,) = baked_media(scene.media, scene.time_s, scene.camera.position, device)
    assert r == 3 and baked.detail is None and baked.shape == tuple(3 * n for n in medium.shape)
    np.testing.assert_allclose(baked.world_from_index @ [1.0, 1.0, 1.0, 1.0],
                               medium.world_from_index @ [0.0, 0.0, 0.0, 1.0], atol=1e-9)
    ratio = baked.density.max() / medium.density.max()
    assert 1.0 < ratio <= 1.0 + 3.0 * fine_spec.amplitude + 1e-6  # the detail raises the peak, within its bound
    march = SingleScatter(SingleScatterSettings(step_length=0.5, shadow_step_length=1.0, min_transmittance=0.0),
                          device=device)
    reference = march.render(scene, 12, 12)
    layer = PathTracer(PathTracerSettings(spp=512, max_bounces=1, seed=5, bake_detail=True),
                       device=device).render(scene, 12, 12)
    sigma = np.sqrt(layer.aovs["variance"][..., 1].sum())
    total, expected = layer.radiance[..., 1].sum(), reference.radiance[..., 1].sum()
    print(f"baked: {total:.4f} +- {sigma:.4f} against the procedural march {expected:.4f}")
    assert abs(total - expected) < 0.03 * expected + 3.0 * sigma
