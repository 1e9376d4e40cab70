"""The paths' sun lobe: a second direction toward the next event, sharing its sunlight by the balance heuristic.

The lobe changes which paths carry a pixel's light, never its expectation: per-pixel and image-sum z-tests against
the same estimator without it, on the Henyey-Greenstein and the tabulated (hero-sampled) mixtures, with a ground,
the forward cut and the hybrid's multiple-scattering-only paths."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, add_field, image_sum_sigma, look_rotation, path_traced, write_stage

from warpsky.render.plan import make_plan
from warpsky.techniques.path_tracer.sun_lobe import NO_LOBE, lobe_asymmetry
from warpsky.usd.stage import StageReader


@pytest.fixture
def blob(tmp_path):
    """A 16^3 Gaussian puff of optical depth ~8 across its core, camera along -z, sun from the side (+x)."""
    axis = (np.arange(16) + 0.5) / 16 - 0.5
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    grid = tmp_path / "puff.npy"
    np.save(grid, np.exp(-(x**2 + y**2 + z**2) / 0.06).astype(np.float32))

    def make(**overrides):
        spec = StageSpec(volume_file=grid, extinction_scale=0.4, camera_position=(0.0, 0.0, 32.0),
                         camera_rotation=look_rotation((0.0, 0.0, -1.0)), sun_direction=(1.0, 0.15, 0.05),
                         phase="hg", g=0.85)
        for key, value in overrides.items():
            setattr(spec, key, value)
        return write_stage(tmp_path / f"puff{len(list(tmp_path.glob('*.usda')))}.usda", spec)

    return make


def z_scores(a, b) -> tuple[float, float]:
    """(largest per-pixel |z| over the pixels with light, image-sum z) of two independent estimates."""
    variance = a.aovs["variance"] + b.aovs["variance"]
    lit = variance > 0.0
    z = (a.radiance - b.radiance)[lit] / np.sqrt(variance[lit])
    return float(np.max(np.abs(z))), float((a.radiance - b.radiance).sum() / image_sum_sigma(variance))


def hybrid(stage, device, size, **settings):
    scene = StageReader(stage).scene_at(None)
    values = {"target_error": 0, "denoise": 0, "step_length": 0.05, "shadow_step_length": 0.05} | settings
    plan = make_plan(scene, technique="hybrid", settings={k: str(v) for k, v in values.items()},
                     resolution=(size, size), device=device)
    return plan.renderer.render(scene, size, size)


def test_the_lobe_keeps_a_side_lit_clouds_light_and_cuts_its_variance(blob, device):
    """The hybrid's multiple-scattering paths with and without the lobe, and the path tracer with it."""
    stage = blob()
    plain = hybrid(stage, device, 12, spp=512, seed=1, sun_lobe=-1)
    lobed = hybrid(stage, device, 12, spp=512, seed=2)  # auto: the medium's g, 0.85
    largest, total = z_scores(plain, lobed)
    assert largest < 5.0 and abs(total) < 4.0  # ~400 values: a false alarm has probability ~2e-4
    lit = plain.aovs["variance"] > 0.0
    assert lit.sum() > 100
    # the paths that turn toward the sun carried the variance; the lobe finds those directions every time
    assert lobed.aovs["variance"][lit].sum() < 0.6 * plain.aovs["variance"][lit].sum()
    traced = path_traced(stage, device, 12, spp=512, seed=3, sun_lobe=0.85)
    largest, total = z_scores(plain, traced)
    assert largest < 5.0 and abs(total) < 4.0


def test_the_lobe_keeps_a_droplet_clouds_light_over_a_ground(blob, device, homogeneous_npy, species_phase):
    """Tabulated droplets (hero-sampled, the lobe's density weighted by the heroes' ratios) over a bright
    ground (whose bounces share nothing)."""
    species_phase("cloud")
    stage = blob(extinction_scale=0.001, ground=(-14.0, 0.6))
    add_field(stage, "cloud", homogeneous_npy, scale=0.05)
    plain = path_traced(stage, device, 10, spp=512, seed=3)
    lobed = path_traced(stage, device, 10, spp=512, seed=4, sun_lobe=0.85)
    largest, total = z_scores(plain, lobed)
    assert largest < 5.0 and abs(total) < 4.0


def test_hybrid_paths_with_the_lobe_and_the_cut_match_the_path_tracer(blob, device, homogeneous_npy,
                                                                      species_phase):
    """The hybrid's multiple-scattering paths (no sunlight at their first event, the cut media after it) with the
    lobe, plus its exact single scattering, against the path tracer with the same cut and no lobe."""
    species_phase("cloud")
    stage = blob(extinction_scale=0.001)
    add_field(stage, "cloud", homogeneous_npy, scale=0.05)
    mine = hybrid(stage, device, 10, spp=512, seed=5, sun_lobe=0.85, forward_cut=3)
    traced = path_traced(stage, device, 10, spp=512, seed=6, forward_cut=3)
    largest, total = z_scores(mine, traced)
    assert largest < 5.0 and abs(total) < 4.0
    assert mine.aovs["multiple_scatter"].sum() > 0.2 * mine.radiance.sum()


def test_the_automatic_lobe_follows_the_media(blob, homogeneous_npy, species_phase):
    scene = StageReader(blob()).scene_at(None)
    assert lobe_asymmetry(scene, None) == pytest.approx(0.85)
    assert lobe_asymmetry(scene, 0.7) == pytest.approx(0.7)
    assert lobe_asymmetry(scene, -1.0) == NO_LOBE
    assert lobe_asymmetry(scene, None, meshes=True) == NO_LOBE  # their kernels take none
    for phase, g in (("isotropic", None), ("hg", 0.3)):
        assert lobe_asymmetry(StageReader(blob(phase=phase, g=g)).scene_at(None), None) == NO_LOBE
    species_phase("cloud")
    droplets = blob(extinction_scale=0.001)
    add_field(droplets, "cloud", homogeneous_npy, scale=0.05)
    only_droplets = StageReader(droplets).scene_at(None)
    assert lobe_asymmetry(only_droplets, None) == pytest.approx(0.85)  # the blob's own HG medium is still there
