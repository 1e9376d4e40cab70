"""Terrain meshes and analytic fog on real USD stages through ``warpsky render`` and ``warpsky info``: the plan
leaves out what a stage lacks, the fog is composited in front of the terrain it is cut by, and bad input names the
prim and attribute."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli

from warpsky.output.exr import read_exr
from warpsky.passes.frame import depth_layers
from warpsky.render.plan import make_plan
from warpsky.usd.stage import StageReader

SUN_AND_CAMERA = """
    def Camera "Camera"
    {
        float focalLength = 24
        float horizontalAperture = 36
        float verticalAperture = 24
        float2 clippingRange = (1, 20000)
        double3 xformOp:translate = (0, 30, 400)
        float xformOp:rotateX = -8
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateX"]
    }
    def DistantLight "Sun"
    {
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = (-30, 20, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }
"""

TERRAIN = """
    def Mesh "Ground"
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-3000, 0, -3000), (-3000, 0, 3000), (3000, 0, 3000), (3000, 0, -3000)]
        color3f warpsky:albedo = (0.2, 0.3, 0.1)
    }
"""

FOG = """
    def Xform "Fog"
    {
        uniform token warpsky:kind = "analyticFog"
        float warpsky:fog:constant = 0.002
        float[] warpsky:fog:cosine:amplitudes = [0.001]
        float3[] warpsky:fog:cosine:waveVectors = [(0.01, 0, 0.02)]
        float warpsky:fog:floor = -10
        float warpsky:fog:top = 60
        vector3f warpsky:fog:wind = (2, 0, 0)
    }
"""


def write_stage(tmp_path, *parts, name="scene.usda") -> str:
    path = tmp_path / name
    path.write_text('#usda 1.0\n(\n    defaultPrim = "World"\n    upAxis = "Y"\n    metersPerUnit = 1\n)\n'
                    'def Xform "World"\n{\n' + SUN_AND_CAMERA + "".join(parts) + "}\n")
    return str(path)


def test_info_plans_only_the_passes_a_stage_needs(tmp_path, capsys):
    code, out, _ = run_cli(["info", write_stage(tmp_path, TERRAIN, FOG)], capsys)
    assert code == 0
    assert "passes      surfaces -> media -> fog -> composite" in out
    assert "hybrid path traces the multiple scattering of the fog and the meshes" in out
    assert "meshes      1 mesh(es) (/World/Ground), 2 triangles: one Warp BVH" in out
    assert "fog         /World/Fog: 1 constant, 1 cosine; slab -10 .. 60 m, wind [2.0, 0.0, 0.0] m/s" in out
    code, out, _ = run_cli(["info", write_stage(tmp_path, FOG, name="fog_only.usda")], capsys)
    assert code == 0
    assert "passes      media -> fog -> composite" in out and "no BVH built" in out
    code, out, _ = run_cli(["info", write_stage(tmp_path, TERRAIN, name="terrain_only.usda")], capsys)
    assert "passes      surfaces -> media -> composite" in out
    assert 'none (no prim with warpsky:kind = "analyticFog")' in out


def test_fog_is_composited_in_front_of_the_terrain_that_cuts_it(tmp_path, capsys):
    """The frame is the fog's radiance plus its transmittance times the terrain's (rendered by the passes alone),
    plus the hybrid's paths' light in front of both (already attenuated to the eye); the media layer holds no voxel
    media. The fog layer ends at the terrain: nearer rays (lower in the image) see less fog."""
    path = write_stage(tmp_path, TERRAIN, FOG)
    out = tmp_path / "frame.exr"
    code, _, err = run_cli(["render", path, out, "--res", "32", "--float"], capsys)
    assert code == 0, err
    image = read_exr(out)
    rgb = np.stack([image.channels[c] for c in "RGB"], axis=-1)
    reader = StageReader(path)
    scene = reader.scene_at(None)
    plan = make_plan(scene, resolution=(32, None))
    surfaces, media, fog = depth_layers(plan, scene)
    assert np.all(media.radiance == 0.0) and np.all(media.transmittance == 1.0)
    assert media.front is not None and media.front.radiance.mean() > 0.0
    expected = media.front.radiance + fog.radiance + fog.transmittance * surfaces.radiance
    np.testing.assert_allclose(rgb, expected, rtol=1e-4, atol=1e-7)
    assert np.all(surfaces.transmittance[-1] == 0.0)  # the bottom row sees the ground
    column = fog.transmittance[:, 16, 1]
    assert column[-1] > column[len(column) // 2]  # shorter fog path to the ground nearby
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0.0


def test_path_tracer_traces_fog_and_terrain_itself(tmp_path, capsys):
    """The path tracer traces analytic fog and the terrain mesh itself (no fog or surfaces pass): a fog-only stage
    and the fog over terrain render, finite and non-negative."""
    from warpsky.output.exr import read_exr

    code, out, _ = run_cli(["info", write_stage(tmp_path, FOG, name="fog_only.usda"), "--technique", "path_tracer"],
                           capsys)
    assert code == 0 and "passes      media -> composite" in out and "traced by path_tracer" in out
    for name, parts in (("fog_only", (FOG,)), ("terrain_fog", (TERRAIN, FOG))):
        out_path = tmp_path / f"{name}.exr"
        code, _, err = run_cli(["render", write_stage(tmp_path, *parts, name=f"{name}.usda"), out_path,
                                "--technique", "path_tracer", "--res", "16", "--spp", "2", "--float"], capsys)
        assert code == 0, err
        rgba = np.stack([read_exr(out_path).channels[c] for c in "RGBA"], axis=-1)
        assert np.all(np.isfinite(rgba)) and rgba.min() >= 0.0 and rgba[..., :3].max() > 0.0


def test_fog_attribute_on_a_prim_of_another_kind_is_named(tmp_path, capsys):
    stray = """
    def Xform "NotFog"
    {
        float warpsky:fog:constant = 0.01
    }
"""
    code, _, err = run_cli(["info", write_stage(tmp_path, stray)], capsys)
    assert code == 2
    assert "/World/NotFog: has warpsky:fog:constant but warpsky:kind is None" in err
    assert 'warpsky:kind = "analyticFog"' in err


@pytest.mark.parametrize("time", [0.0, 24.0])
def test_wind_moves_the_rendered_fog_as_a_camera_moved_against_it(tmp_path, time):
    """A frame at time t (24 time codes = 1 s; wind 2 m/s along x) equals the frame at 0 seen from a camera moved
    by -wind t, fog only (the terrain does not move with the wind)."""
    import dataclasses

    from warpsky.passes.fog.fog import Fog

    reader = StageReader(write_stage(tmp_path, FOG))
    later = reader.scene_at(time)
    still = reader.scene_at(0.0)
    shift = np.array([2.0, 0.0, 0.0]) * later.time_s
    moved = dataclasses.replace(still, camera=dataclasses.replace(still.camera,
                                                                  position=still.camera.position - shift))
    a = Fog().render(later, 16, 12)
    b = Fog().render(moved, 16, 12)
    np.testing.assert_allclose(a.radiance, b.radiance, rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(a.transmittance, b.transmittance, rtol=1e-5)


def test_stratiform_layer_shadows_points_below_it_along_the_slant_path():
    """A flat 100 m layer at 1000 m, sun at 30 deg: a point below is dimmed by exp(-kappa 100 / sin 30 deg); a point
    whose ray towards the sun passes beside the map, or above the base, is not."""
    import math

    from warpsky.media.stratiform.thickness import layer_sun_transmittance
    from warpsky.model.stratiform import StratiformLayer

    layer = StratiformLayer(np.full((8, 8), 100.0, np.float32), 1000.0, (-500.0, -500.0), (1000.0, 1000.0))
    sun = np.array([math.cos(math.radians(30.0)), 0.5, 0.0])
    points = np.array([[-500.0, 500.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1200.0, 0.0], [-1000.0, 990.0, 0.0]])
    got = layer_sun_transmittance(layer, points, sun)
    dimmed = math.exp(-layer.extinction * 100.0 / 0.5)
    np.testing.assert_allclose(got[:, 0], [dimmed, 1.0, 1.0, 1.0], rtol=1e-6)


def test_scenery_pass_settings_come_from_set_and_bad_ones_are_named(tmp_path, capsys):
    path = write_stage(tmp_path, TERRAIN, FOG)
    code, out, _ = run_cli(["info", path, "--set", "fog.nodes=2", "--set", "fog.cut_depth=20"], capsys)
    assert code == 0 and "fog.nodes=2, fog.min_pieces=4, fog.max_pieces=64, fog.cut_depth=20" in out
    code, _, err = run_cli(["info", path, "--set", "fog.node=2"], capsys)
    assert code == 2 and ("unknown setting fog.node for fog; did you mean fog.nodes? known: fog.nodes, fog.min_pieces"
                          in err)
    code, _, err = run_cli(["info", path, "--set", "fog.nodes=two"], capsys)
    assert code == 2 and "setting fog.nodes: expected a whole number, got 'two'" in err
    code, _, err = run_cli(["info", path, "--set", "fog.max_pieces=2"], capsys)
    assert code == 2 and "setting fog.max_pieces must be a whole number >= fog.min_pieces (4), got 2" in err
    code, _, err = run_cli(["info", path, "--set", "deck.mode=fast"], capsys)
    assert code == 2 and "mode" in err and "fast" in err
    code, _, err = run_cli(["info", path, "--set", "heightfield.mode=max"], capsys)  # the deck pass's old name
    assert code == 2 and "setting heightfield.mode: the heightfield pass is now called deck; use deck.mode" in err
    reader = StageReader(path)
    scene = reader.scene_at(None)
    coarse = make_plan(scene, resolution=(16, None), settings={"fog.nodes": "1", "fog.max_pieces": "4"})
    fine = make_plan(scene, resolution=(16, None))
    assert coarse.settings_json() != fine.settings_json()
    a = depth_layers(coarse, scene)[-1]
    b = depth_layers(fine, scene)[-1]
    assert a.stats["nodes"] == 1 and b.stats["nodes"] == 4


@pytest.mark.parametrize("stage", ["valley_fog", pytest.param("sunbeams", marks=pytest.mark.slow)])
def test_shipped_stages_plan_and_render(tmp_path, capsys, stage):
    """The two stages as shipped, over a coarse terrain made by the tool as ``make terrain`` makes it: their plans
    hold the passes they are for, and a tiny frame renders finite, non-negative and not black."""
    import shutil
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "tools"))
    import make_terrain

    (tmp_path / "usd_scenes").mkdir()
    shutil.copy(root / "usd_scenes" / f"{stage}.usda", tmp_path / "usd_scenes")
    (tmp_path / "data").mkdir()
    make_terrain.make_terrain_stage(tmp_path / "data" / "terrain.usda", resolution=33, seed=1, valley_angle=90.0)
    path = tmp_path / "usd_scenes" / f"{stage}.usda"
    code, out, err = run_cli(["info", path], capsys)
    assert code == 0, err
    passes = {"valley_fog": "surfaces -> media -> fog -> sky",
              "sunbeams": "surfaces -> media -> deck -> sky"}[stage]
    assert f"passes      {passes} -> composite" in out
    code, _, err = run_cli(["render", path, tmp_path / "f.####.exr", "--frames", "1", "--res", "16", "--float"],
                           capsys)
    assert code == 0, err
    image = read_exr(tmp_path / "f.0001.exr")
    rgb = np.stack([image.channels[c] for c in "RGB"], axis=-1)
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0.0 and rgb.mean() > 1e-3


def test_the_analytic_sky_lights_surfaces_in_shadow_and_the_fog():
    """Under an atmosphere, a floor in a wall's shadow receives only the analytic sky: its radiance is albedo x E/pi
    of the sky's upper hemisphere (the Riley sky integrated over it); the fog's sky light is albedo L (1 - T) with
    L the isotropic mean; without an atmosphere both are zero, as before. (The passes' single scattering alone:
    with hybrid's multiple scattering on, its paths carry the sky's light instead.)"""
    import math

    from conftest import look_rotation

    from warpsky.light.dome import isotropic_ambient
    from warpsky.light.sky import sky_hemisphere, sky_light
    from warpsky.model.scene import Atmosphere, Camera, Scene, Sun
    from warpsky.model.terrain import TerrainMesh

    floor = TerrainMesh("floor", np.array([[-500.0, 0, -500], [-500, 0, 500], [500, 0, 500], [500, 0, -500]]),
                        np.array([[0, 1, 2], [0, 2, 3]]), np.full(3, 0.5))
    wall = TerrainMesh("wall", np.array([[0.0, 0, -500], [0, 400, -500], [0, 400, 500], [0, 0, 500]]),
                       np.array([[0, 1, 2], [0, 2, 3]]), np.full(3, 0.5))
    sun = Sun(np.array([math.cos(math.radians(30.0)), 0.5, 0.0]), np.ones(3))
    camera = Camera("down", np.array([-100.0, 50.0, 0.0]), look_rotation((0.0, -1.0, 0.0)), 50.0, 20.0, 20.0,
                    near=0.5, far=1e4, projection="orthographic")
    scene = Scene(camera=camera, sun=sun, atmosphere=Atmosphere(), meshes=(floor, wall))
    sky = sky_light(scene, analytic=True)
    mean, e_over_pi = sky_hemisphere(scene)
    assert np.all(e_over_pi > 0.0) and e_over_pi[2] > e_over_pi[0]  # a blue sky
    single = {"multiple_scattering": "0"}
    (surfaces,) = depth_layers(make_plan(scene, resolution=(8, 8), settings=single), scene)
    np.testing.assert_allclose(surfaces.radiance, np.broadcast_to(0.5 * e_over_pi, (8, 8, 3)), rtol=1e-5)
    dark = Scene(camera=camera, sun=sun, meshes=(floor, wall))
    (unlit,) = depth_layers(make_plan(dark, resolution=(8, 8), settings=single), dark)
    assert np.all(unlit.radiance == 0.0)
    np.testing.assert_allclose(isotropic_ambient(scene, sky), 0.5 * (mean + 0.5 * e_over_pi))


def test_terrain_shadows_the_sunlit_fog():
    """A 400 m wall with the sun 30 deg up behind it: fog in its shadow scatters no sunlight (nothing else lights
    it here), the same fog without the wall does, and fog the shadow does not reach is unchanged (the fog pass
    alone: hybrid's multiple scattering off)."""
    import math

    from conftest import look_rotation

    from warpsky.model.fog import AnalyticFog, ConstantTerm
    from warpsky.model.scene import Camera, Scene, Sun
    from warpsky.model.terrain import TerrainMesh

    wall = TerrainMesh("wall", np.array([[0.0, -10, -500], [0, 400, -500], [0, 400, 500], [0, -10, 500]]),
                       np.array([[0, 1, 2], [0, 2, 3]]), np.full(3, 0.5))
    fog = AnalyticFog("fog", (ConstantTerm(0.01),), floor=0.0, top=40.0)
    sun = Sun(np.array([math.cos(math.radians(30.0)), 0.5, 0.0]), np.ones(3))
    results = {}
    for x in (-100.0, 2000.0):  # in the wall's shadow (it reaches x = -693 m at the ground), and far beside it
        camera = Camera("down", np.array([x, 60.0, 0.0]), look_rotation((0.0, -1.0, 0.0)), 50.0, 10.0, 10.0,
                        near=0.5, far=1e4, projection="orthographic")
        for meshes in ((wall,), ()):
            scene = Scene(camera=camera, sun=sun, meshes=meshes, fogs=(fog,))
            plan = make_plan(scene, resolution=(4, 4), settings={"multiple_scattering": "0"})
            assert plan.passes == (("surfaces", "fog") if meshes else ("fog",))
            parts = depth_layers(plan, scene)
            results[x, bool(meshes)] = parts[-1].radiance
    assert np.all(results[-100.0, True] == 0.0) and np.all(results[-100.0, False] > 1e-4)
    np.testing.assert_array_equal(results[2000.0, True], results[2000.0, False])
