"""Continuing paths through oriented ice: the directional table's sampler draws what the table holds, its weights
average to the phase's integral, and the path tracer keeps a white furnace white with oriented plates."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_oriented_render import PLATES

from warpsky.optics import oriented_sampling
from warpsky.optics.oriented_sampling import OrientedTables, directional_sample, directional_value
from warpsky.usd.stage import StageReader

ELEVATIONS = (0.0, 30.0, 60.0, 90.0)
PHOTONS = 300_000


@pytest.fixture
def small_tables(monkeypatch):
    """Continuation tables at four elevations and few photons (the sampler does not care how noisy they are)."""
    monkeypatch.setattr(oriented_sampling, "SAMPLING_ELEVATIONS", ELEVATIONS)
    monkeypatch.setattr(oriented_sampling, "SAMPLING_PHOTONS", PHOTONS)


@wp.kernel
def draw_kernel(tables: OrientedTables, d: wp.vec3, seed: int, sources: wp.array(dtype=wp.vec3),
                ratios: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    s, state = directional_sample(tables, 0, d, state)
    value = directional_value(tables, 0, -d, -s)
    sources[i] = s
    ratios[i] = value / wp.max(value[1], 1.0e-30)


def plate_tables(tmp_path, device):
    from test_oriented_render import sheet_stage

    scene = StageReader(sheet_stage(tmp_path / "plates.usda", attributes=PLATES)).scene_at(None)
    return oriented_sampling.continuation_tables(scene, device)


@pytest.mark.parametrize("elevation", [-35.0, 8.0, 45.0])
def test_sampler_draws_the_table_and_its_weights_integrate_the_phase(tmp_path, device, optics_cache, small_tables,
                                                                    elevation):
    """A path arriving along d (from above, nearly level, from below): the sources it draws fall into coarse sky
    cells as often as the table's green energy there (chi-square), and T_c / T_green averages to
    the integral of T_c, which is 1 in every channel."""
    from warpsky.optics.oriented_ice import SkyBins

    tables = plate_tables(tmp_path, device)
    e = np.radians(elevation)
    d = np.array([0.3 * np.cos(e), -np.sin(e), -np.sqrt(0.91) * np.cos(e)])  # travelling downwards for e > 0
    d /= np.linalg.norm(d)
    n = 400_000
    sources = wp.zeros(n, dtype=wp.vec3, device=device)
    ratios = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(draw_kernel, dim=n, inputs=[tables, wp.vec3(*d.tolist()), 7, sources, ratios], device=device)
    ratio = ratios.numpy()
    mean, error = ratio.mean(axis=0), ratio.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(mean - 1.0) < 4.0 * error + 2e-3), (mean, error)
    # expected cell frequencies: the table's green energy, linear between its two slices around -d's elevation
    looks = -sources.numpy().astype(np.float64)
    source = -d
    horizontal = np.array([source[0], 0.0, source[2]]) / np.hypot(source[0], source[2])
    frame = np.stack([horizontal, [0.0, 1.0, 0.0], np.cross(horizontal, [0.0, 1.0, 0.0])])
    local = looks @ frame.T
    if source[1] < 0.0:
        local[:, 1] *= -1.0
    grid = SkyBins()
    rows, columns = grid.bins_of(local)
    values = tables.values.numpy().reshape(len(ELEVATIONS), grid.elevation_bins, grid.azimuth_bins, 3)
    x = np.degrees(np.arcsin(abs(source[1]))) / 30.0
    k = min(int(x), len(ELEVATIONS) - 2)
    t = x - k
    energy = ((1.0 - t) * values[k, ..., 1] + t * values[k + 1, ..., 1]) * grid.solid_angles()
    cells = (rows // 10) * 100 + columns // 20  # coarse cells of 10° x 10°
    counts = np.bincount(cells, minlength=2000)
    expected = np.bincount(((np.arange(grid.elevation_bins) // 10)[:, None] * 100
                            + (np.arange(grid.azimuth_bins) // 20)[None, :]).reshape(-1),
                           weights=energy.reshape(-1), minlength=2000) * n
    used = expected > 20.0
    chi2 = float((((counts - expected) ** 2)[used] / expected[used]).sum())
    dof = int(used.sum()) - 1
    assert chi2 < dof + 5.0 * np.sqrt(2.0 * dof), (chi2, dof)
    sparse = expected[~used].sum()  # the cells too sparse for the chi-square, together
    assert abs(counts[~used].sum() - sparse) < 5.0 * np.sqrt(sparse) + 5.0


@pytest.mark.slow
def test_white_furnace_with_oriented_plates(tmp_path, device, optics_cache, small_tables):
    """Oriented plates of albedo 1 in a uniform white environment, no sun: every path's weight averages to one, so
    every pixel sees the environment, through as many oriented scatterings as the box takes."""
    from conftest import path_traced

    np.save(tmp_path / "box.npy", np.ones((4, 4, 4), dtype=np.float32))
    (tmp_path / "box.usda").write_text(f"""#usda 1.0
(
    defaultPrim = "World"
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "World"
{{
    def Camera "Camera"
    {{
        float focalLength = 50
        float horizontalAperture = 36
        float verticalAperture = 36
        float2 clippingRange = (0.1, 1000)
        double3 xformOp:translate = (0, 0, 32)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}

    def Volume "Box"
    {{
        float3[] extent = [(-10, -10, -10), (10, 10, 10)]
        rel field:ice = </World/Box/ice>

        def OpenVDBAsset "ice"
        {{
            asset filePath = @./box.npy@
            token fieldName = ""
            float warpsky:extinctionScale = 0.15
            {PLATES}
        }}
    }}
}}
""")
    layer = path_traced(str(tmp_path / "box.usda"), device, 8, spp=1024, environment=1.0)
    seen = layer.radiance + layer.transmittance
    # every channel's mean within 4 standard errors (and 0.5%); red and blue are noisier than green, whose
    # distribution is drawn (where the halos' dispersion leaves green dim, red and blue carry large weights):
    # at 256 paths per pixel red's mean ranged 0.971-1.028 over five seeds
    error = np.sqrt(layer.aovs["variance"].reshape(-1, 3).sum(axis=0)) / seen[..., 0].size
    assert np.all(np.abs(seen.mean(axis=(0, 1)) - 1.0) < 4.0 * error + 0.005), (seen.mean(axis=(0, 1)), error)
    # per pixel: the small tables' noisy cells give the weights a heavy tail, whose sample variance falls short of
    # the true one in most runs, so pixels stray further than a Gaussian would (at 256 paths a max |z| < 5 held for
    # 2 of 7 seeds, before and after the tracker's changes; at 1024, median |z| 0.8-1.1 and max 3.8-4.8 over six);
    # a pixel biased by 5% would stand at |z| ~ 5
    z = np.abs(seen[..., 1] - 1.0) / np.sqrt(layer.aovs["variance"][..., 1] + 1e-30)
    assert np.median(z) < 1.5 and np.max(z) < 8.0, (np.median(z), np.max(z))  # Gaussian: median 0.67
    assert layer.transmittance.mean() < 0.5  # the box is optically thick: most paths scatter, many times
