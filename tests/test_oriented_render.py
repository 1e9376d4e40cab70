"""Oriented ice crystals in a stage and in the renderers: the ``warpsky:ice:*`` attributes, the sundog where the
camera model and Bravais' index put it, random orientation unchanged, and the techniques against each other."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpsky.core.errors import SceneError
from warpsky.optics.grid import angle_grid
from warpsky.optics.ice import ice_refractive_index
from warpsky.optics.oriented_phase import frame_slices, oriented_media
from warpsky.render.plan import make_plan
from warpsky.usd.stage import StageReader

SUN_ELEVATION = 10.0  # deg
WIDTH, HEIGHT = 96, 64


def sheet_stage(path, *, attributes: str = "", field: str = "ice", extinction: float = 0.0004,
                pitch: float = SUN_ELEVATION, sun: float = SUN_ELEVATION, height: float = 0.0) -> str:
    """A homogeneous ice sheet 1000-1020 m up, 40 km wide, the sun 10° up straight ahead of a camera on the
    ground pitched up by ``pitch`` [deg] (focal 30 mm on a 36 x 24 mm film: 62° x 44°)."""
    np.save(path.parent / "sheet.npy", np.ones((4, 2, 4), dtype=np.float32))
    path.write_text(f"""#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "World"
{{
    def Camera "Camera"
    {{
        float focalLength = 30
        float horizontalAperture = 36
        float verticalAperture = 24
        float2 clippingRange = (1, 100000)
        double3 xformOp:translate = (0, {height}, 0)
        float3 xformOp:rotateXYZ = ({pitch}, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }}

    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = ({-sun}, 180, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }}

    def Volume "Sheet"
    {{
        float3[] extent = [(-20000, 1000, -20000), (20000, 1020, 20000)]
        rel field:{field} = </World/Sheet/{field}>

        def OpenVDBAsset "{field}"
        {{
            asset filePath = @./sheet.npy@
            token fieldName = ""
            float warpsky:extinctionScale = {extinction}
            {attributes}
        }}
    }}
}}
""")
    return str(path)


PLATES = 'token warpsky:ice:orientation = "plate"\n            float warpsky:ice:tilt = 0.3'


def render(stage: str, technique: str, device: str, settings: dict | None = None, *, supersample: int = 1):
    """(scene, radiance at WIDTH x HEIGHT); ``supersample`` renders n times larger and averages n x n blocks (the
    pixel's area rather than its centre)."""
    scene = StageReader(stage).scene_at(None)
    width, height = WIDTH * supersample, HEIGHT * supersample
    plan = make_plan(scene, technique=technique, settings=settings or {}, resolution=(width, height), device=device)
    radiance = plan.renderer.render(scene, width, height).radiance
    return scene, radiance.reshape(HEIGHT, supersample, WIDTH, supersample, 3).mean(axis=(1, 3))


def render_layer(stage: str, technique: str, device: str, settings: dict | None = None):
    """(radiance, variance of each pixel's mean or zeros) at WIDTH x HEIGHT."""
    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique=technique, settings=settings or {}, resolution=(WIDTH, HEIGHT), device=device)
    layer = plan.renderer.render(scene, WIDTH, HEIGHT)
    return layer.radiance, layer.aovs.get("variance", np.zeros_like(layer.radiance))


def parhelion_columns(scene) -> tuple[float, float]:
    """Image x [pixels] of the two parhelia for green light: elevation e, azimuth +-da from the sun with
    da = 2 asin(n' / 2) - 60° and Bravais' index n' = sqrt(n^2 - sin^2 e) / cos e."""
    e = math.radians(SUN_ELEVATION)
    n = float(ice_refractive_index(550e-9))
    bravais = math.sqrt(n * n - math.sin(e) ** 2) / math.cos(e)
    da = 2.0 * math.asin(bravais / 2.0) - math.radians(60.0)
    camera = scene.camera.conformed(WIDTH, HEIGHT)
    columns = []
    for sign in (-1.0, 1.0):
        world = np.array([math.sin(sign * da) * math.cos(e), math.sin(e), -math.cos(sign * da) * math.cos(e)])
        local = camera.rotation.T @ world
        columns.append((local[0] / -local[2] * camera.focal_length / camera.horizontal_aperture + 0.5) * WIDTH)
    return columns[0], columns[1]


def test_ice_attributes_are_read_and_bad_ones_named(tmp_path):
    scene = StageReader(sheet_stage(tmp_path / "a.usda", attributes=PLATES + "\n            float "
                                    "warpsky:ice:fraction = 0.25")).scene_at(None)
    ice = scene.media[0].ice
    assert (ice.orientation, ice.habit, ice.tilt_deg, ice.fraction) == ("plate", "plate", pytest.approx(0.3),
                                                                        pytest.approx(0.25))
    bad = {
        'token warpsky:ice:orientation = "sideways"': "warpsky:ice:orientation",
        'token warpsky:ice:orientation = "plate"\n            token warpsky:ice:habit = "column"':
            "warpsky:ice:orientation",
        "float warpsky:ice:tilt = -2": "warpsky:ice:tilt",
        "float warpsky:ice:fraction = 1.5": "warpsky:ice:fraction",
        "float warpsky:ice:wobble = 1": "warpsky:ice:wobble",
    }
    for k, (text, attribute) in enumerate(bad.items()):
        with pytest.raises(SceneError, match=f"/World/Sheet/ice.{attribute}"):
            StageReader(sheet_stage(tmp_path / f"bad{k}.usda", attributes=text)).scene_at(None)
    with pytest.raises(SceneError, match="warpsky:ice:orientation.*field:ice"):
        StageReader(sheet_stage(tmp_path / "cloud.usda", attributes=PLATES, field="cloud")).scene_at(None)


@pytest.mark.slow
def test_slice_mixes_oriented_and_random_crystals_by_number_and_area(tmp_path, optics_cache, species_phase):
    """A fraction of oriented crystals weighs their table by number times surface; the slice stays normalised."""
    from warpsky.optics.ice import HABITS

    full = StageReader(sheet_stage(tmp_path / "f.usda", attributes=PLATES)).scene_at(None)
    part = StageReader(sheet_stage(tmp_path / "p.usda", attributes=PLATES + "\n            float "
                                   "warpsky:ice:fraction = 0.6")).scene_at(None)
    none = StageReader(sheet_stage(tmp_path / "n.usda", attributes=PLATES + "\n            float "
                                   "warpsky:ice:fraction = 0")).scene_at(None)
    plate, column = HABITS["plate"].surface_area, HABITS["column"].surface_area
    expected = {0: 0.0, 1: 0.4 * column / (0.6 * plate + 0.4 * column), 2: 1.0}
    for k, scene in enumerate((full, part, none)):
        values, shares, slice_of, grid = frame_slices(scene, photons=1_000_000)
        assert slice_of == [0]
        assert np.allclose((values[0] * grid.solid_angles()[..., None]).sum(axis=(0, 1)), 1.0, atol=2e-3)
        assert shares[0] == pytest.approx(expected[k], abs=1e-6)  # the fraction is a USD float
    values, _, _, grid = frame_slices(full, photons=1_000_000)
    # the plates' parhelion 22.6-23° beside the sun, far above the random columns' phase at that angle
    row = int(round((SUN_ELEVATION + 90.0) / grid.elevation_step_deg))
    columns = slice(int(round(22.6 / grid.azimuth_step_deg)), int(round(23.2 / grid.azimuth_step_deg)))
    theta = np.radians(np.linspace(22.0, 23.0, 11))  # the parhelion's angular distance from a 10° sun
    random = np.interp(theta, angle_grid(), species_phase("ice")[1]).max()
    assert values[0, row, columns, 1].max() > 20.0 * random


@pytest.mark.slow
def test_random_orientation_renders_exactly_as_without_attributes(tmp_path, device, optics_cache):
    plain = sheet_stage(tmp_path / "plain.usda")
    random = sheet_stage(tmp_path / "random.usda", attributes='token warpsky:ice:orientation = "random"')
    assert oriented_media(StageReader(random).scene_at(None).media) == []
    a = render(plain, "single_scatter", device)[1]
    b = render(random, "single_scatter", device)[1]
    assert np.array_equal(a, b)


@pytest.mark.slow
def test_sundogs_sit_where_bravais_puts_them_on_both_sides(tmp_path, device, optics_cache):
    scene, image = render(sheet_stage(tmp_path / "dogs.usda", attributes=PLATES), "single_scatter", device)
    luminance = image @ np.array([0.2126, 0.7152, 0.0722])
    row = HEIGHT // 2  # the camera is pitched to the sun's elevation: its row is the middle one
    band = luminance[row - 1:row + 1].mean(axis=0)
    predicted = parhelion_columns(scene)
    centre = WIDTH / 2.0
    for side, guess in zip(("left", "right"), predicted, strict=True):
        window = np.arange(WIDTH)
        window = window[(np.abs(window + 0.5 - guess) < 6.0) & (np.abs(window + 0.5 - centre) > 8.0)]
        peak = window[np.argmax(band[window])] + 0.5
        assert abs(peak - guess) <= 1.5, f"{side} sundog at x = {peak}, predicted {guess:.2f}"
        assert band[int(peak)] > 3.0 * np.median(band), side


@pytest.mark.slow
@pytest.mark.parametrize("technique,settings,tolerance", [
    ("path_tracer", {"spp": "512", "seed": "1"}, 0.1),  # tolerance: the window mean's noise it must reach
    ("slicing", {"low_albedo": "true", "light_resolution": "64"}, 0.15),
])
def test_techniques_agree_with_the_march_on_a_thin_sheet(tmp_path, device, optics_cache, technique, settings,
                                                         tolerance, monkeypatch):
    """A sheet thin enough (vertical optical depth 0.02) that single scattering is nearly all there is: the
    path tracer's sun events and slicing's first order show the sundogs the march shows (averaged over a window
    wider than a sundog; every technique samples the pixel centres, which matters: a parhelion of plates tilted
    0.3° is narrower than a row of this frame, and averaged over 4 x 4 points per pixel the window holds 1.8 times
    what the centres see), and not what random crystals show."""
    from warpsky.optics import oriented_sampling

    # light scattered twice is a few per cent here: a coarse continuation table is enough
    monkeypatch.setattr(oriented_sampling, "SAMPLING_ELEVATIONS", (0.0, 30.0, 60.0, 90.0))
    monkeypatch.setattr(oriented_sampling, "SAMPLING_PHOTONS", 300_000)
    stage = sheet_stage(tmp_path / "thin.usda", attributes=PLATES, extinction=0.001)
    monte_carlo = technique == "path_tracer"
    scene, march = render(stage, "single_scatter", device)
    other, variance = render_layer(stage, technique, device, settings)
    random = render(sheet_stage(tmp_path / "r.usda", extinction=0.001), "single_scatter", device)[1]
    left, right = (int(c) for c in parhelion_columns(scene))
    rows = slice(HEIGHT // 2 - 3, HEIGHT // 2 + 3)
    for column in (left, right):
        window = (rows, slice(column - 3, column + 4))
        expected = march[window].mean(axis=(0, 1))
        assert np.all(expected > 2.0 * random[window].mean(axis=(0, 1)))
        measured = other[window].mean(axis=(0, 1))
        if monte_carlo:  # the window mean's own noise: z-test
            sigma = np.sqrt(variance[window].sum(axis=(0, 1))) / variance[window][..., 0].size
            assert np.all(np.abs(measured - expected) < 4.0 * sigma), (measured, expected, sigma)
            assert np.all(sigma < tolerance * expected)  # and enough paths for the test to mean something
        else:
            assert np.allclose(measured, expected, rtol=tolerance)


@pytest.mark.slow
@pytest.mark.parametrize("sun,tilt,height,pitch", [
    (0.0, 0.3, 0.0, 10.0),  # the sun on the horizon
    (90.0, 0.3, 0.0, 60.0),  # the sun at the zenith: no sundogs
    (10.0, 0.0, 0.0, 10.0),  # perfectly aligned plates
    (10.0, 0.3, 1010.0, 0.0),  # inside the sheet, seen edge-on
])
def test_extreme_suns_alignment_and_edge_on_sheets_stay_finite(tmp_path, device, optics_cache, sun, tilt, height,
                                                                pitch):
    attributes = f'token warpsky:ice:orientation = "plate"\n            float warpsky:ice:tilt = {tilt}'
    stage = sheet_stage(tmp_path / "x.usda", attributes=attributes, sun=sun, height=height, pitch=pitch)
    for technique in ("single_scatter", "slicing"):
        image = render(stage, technique, device)[1]
        assert np.all(np.isfinite(image)) and image.min() >= 0.0, technique
        assert image.max() > 0.0, technique
    if sun == 90.0:
        # plates under a zenith sun have no sundog: nothing 15-30° from the sun, where random crystals put the
        # 22° halo (rows: look elevations 60-75°)
        values, _, _, grid = frame_slices(StageReader(stage).scene_at(None))
        rows = slice(int(round(150.0 / grid.elevation_step_deg)), int(round(166.0 / grid.elevation_step_deg)))
        assert values[0, rows].max() < 1e-6 * values[0].max()
