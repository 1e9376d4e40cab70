"""The Monte Carlo reference: unbiased against single scattering, a white furnace, majorant choice and seeds."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import StageSpec, add_field, image_sum_sigma, look_rotation, path_traced, render_layer, write_stage

from warpsky.techniques.path_tracer.majorants import majorant_grid
from warpsky.techniques.path_tracer.path_tracer import PathTracer
from warpsky.usd.stage import StageReader


@pytest.fixture
def box(tmp_path, homogeneous_npy):
    def make(**overrides):
        spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.05, camera_position=(3.0, 4.0, 42.0),
                         camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3))
        for key, value in overrides.items():
            setattr(spec, key, value)
        return write_stage(tmp_path / f"box{len(list(tmp_path.glob('*.usda')))}.usda", spec)

    return make


def test_single_scatter_estimator_equals_the_single_scatter_technique(box, device):
    stage = box()
    _, reference = render_layer(stage, device, 16, 16, step_length=0.05, shadow_step_length=0.05,
                                min_transmittance=0.0)
    layer = path_traced(stage, device, 16, spp=512, max_bounces=1)
    covered = np.broadcast_to((reference.transmittance < 0.95).all(axis=-1)[..., None], reference.radiance.shape)
    z = (layer.radiance - reference.radiance)[covered] / np.sqrt(layer.aovs["variance"][covered] + 1e-30)
    assert np.max(np.abs(z)) < 5.0  # ~600 values: a false alarm has probability ~3e-4
    z_mean = (layer.radiance - reference.radiance).sum() / image_sum_sigma(layer.aovs["variance"])
    assert abs(z_mean) < 4.0  # the image mean, not only each pixel, is unbiased
    np.testing.assert_allclose(layer.transmittance, reference.transmittance, atol=0.1)
    assert layer.transmittance.mean() == pytest.approx(reference.transmittance.mean(), rel=0.02)


@pytest.mark.parametrize("phase,g", [("isotropic", None), ("hg", 0.8)])
def test_white_furnace_returns_the_environment(box, device, phase, g):
    """Albedo 1 in a uniform white environment, no sun: every pixel sees exactly the environment."""
    stage = box(sun_direction=None, extinction_scale=0.2, phase=phase, g=g)
    layer = path_traced(stage, device, 8, spp=256, environment=1.0)
    seen = layer.radiance + layer.transmittance  # the layer over a background of the same radiance
    assert seen.mean() == pytest.approx(1.0, abs=0.01)
    np.testing.assert_allclose(seen, 1.0, atol=0.15)
    assert layer.stats["capped_paths"] == 0


def test_white_furnace_with_droplets_mixes_the_hero_channels(box, device, homogeneous_npy, species_phase):
    """Mie droplets (a phase table per colour channel) at optical depth 200 across the box, albedo 1, in a white
    environment: every channel sees exactly the environment. Paths sample the tables by a hero channel drawn per
    path and are weighted by the balance heuristic over the three heroes, so no channel's weight grows with the
    ~100 events of a path: red and blue are as quiet as green (sampled by green alone, red and blue had 20x green's
    pixel spread here and came out 5 % low at 64 paths per pixel)."""
    species_phase("cloud")
    stage = box(sun_direction=None, extinction_scale=0.001)
    add_field(stage, "cloud", homogeneous_npy, scale=10.0)
    layer = path_traced(stage, device, 8, spp=64, environment=1.0, max_bounces=100000)
    seen = (layer.radiance + layer.transmittance).reshape(-1, 3)
    assert layer.stats["capped_paths"] == 0 and layer.stats["scatter_events"] > 60 * layer.stats["paths"]
    np.testing.assert_allclose(seen.mean(axis=0), 1.0, atol=0.03)
    spread = seen.std(axis=0)
    assert spread.max() < 0.12 and spread.max() < 2.0 * spread.min()


def test_tight_and_loose_majorants_agree(tmp_path, device):
    """A thin cloud with a dense core: local majorants (4-voxel cells) and one global majorant per medium must
    give the same image in expectation; the local ones take fewer tracking steps."""
    rng = np.random.default_rng(3)
    density = 0.01 + 0.02 * rng.random((16, 16, 16)).astype(np.float32)
    density[6:10, 6:10, 6:10] = 1.0
    grid = tmp_path / "core.npy"
    np.save(grid, density)
    spec = StageSpec(volume_file=grid, extinction_scale=2.0, camera_position=(2.0, 3.0, 45.0),
                     camera_rotation=look_rotation((-0.04, -0.05, -1.0)), sun_direction=(0.3, 0.9, -0.2))
    stage = write_stage(tmp_path / "core.usda", spec)
    tight = path_traced(stage, device, 12, spp=256, majorant_block=4, seed=1)
    loose = path_traced(stage, device, 12, spp=256, majorant_block=1000, seed=2)
    variance = tight.aovs["variance"] + loose.aovs["variance"]
    z = (tight.radiance - loose.radiance) / np.sqrt(variance + 1e-30)
    assert np.max(np.abs(z)) < 5.0
    z_mean = (tight.radiance.sum() - loose.radiance.sum()) / image_sum_sigma(variance)
    assert abs(z_mean) < 4.0
    assert tight.stats["tracking_steps"] < 0.5 * loose.stats["tracking_steps"]


def test_majorant_grid_bounds_every_trilinear_lookup():
    rng = np.random.default_rng(0)
    density = rng.random((9, 7, 5)).astype(np.float32)
    bound = majorant_grid(density, 4)
    assert bound.shape == (3, 2, 2)
    # any point in cell c interpolates voxels c*4 - 1 .. c*4 + 4 (clamped)
    for (i, j, k), value in np.ndenumerate(bound):
        block = density[max(4 * i - 1, 0):4 * i + 5, max(4 * j - 1, 0):4 * j + 5, max(4 * k - 1, 0):4 * k + 5]
        assert value == block.max()


def test_same_seed_same_image(box, device):
    stage = box()
    first = path_traced(stage, device, 8, spp=8, seed=5)
    again = path_traced(stage, device, 8, spp=8, seed=5)
    other = path_traced(stage, device, 8, spp=8, seed=6)
    np.testing.assert_array_equal(first.radiance, again.radiance)
    assert not np.array_equal(first.radiance, other.radiance)


def test_optically_thick_albedo_one_stays_bounded_and_reports_the_cap(box, device):
    stage = box(extinction_scale=50.0)  # optical thickness 1e3 across the box
    layer = path_traced(stage, device, 8, spp=8, max_bounces=16)
    for values in (layer.radiance, layer.transmittance, layer.aovs["variance"]):
        assert np.all(np.isfinite(values)) and values.min() >= 0.0
    assert layer.stats["capped_paths"] > 0
    assert layer.transmittance.max() < 1e-6 or layer.transmittance[layer.radiance > 0].max() < 1e-6


def test_grazing_sun_over_ground_is_finite(box, device):
    stage = box(sun_direction=(1.0, 1e-4, 0.0), ground=(-12.0, 0.95))
    layer = path_traced(stage, device, 8, spp=8)
    assert np.all(np.isfinite(layer.radiance)) and layer.radiance.min() >= 0.0


def test_cli_writes_a_variance_aov(box, tmp_path):
    from warpsky.cli.main import main
    from warpsky.output.exr import read_exr

    stage = box()
    out = tmp_path / "pt.exr"
    assert main(["render", str(stage), str(out), "--technique", "path_tracer", "--spp", "4", "--seed", "3",
                 "--res", "8x8", "--device", "cpu"]) == 0
    image = read_exr(out)
    assert {"variance.R", "variance.G", "variance.B"} <= set(image.channels)


@pytest.mark.slow
@pytest.mark.parametrize("phase,g,tau", [("isotropic", None, 0.5), ("isotropic", None, 2.0), ("hg", 0.8, 4.0)])
def test_homogeneous_slab_against_adding_doubling(tmp_path, homogeneous_npy, device, phase, g, tau):
    """A 10 m slab, 20 km wide, sun at normal incidence: radiance reflected straight up and at 60 deg, and
    diffusely transmitted at 45.6 deg, against adding-doubling (tests/adding_doubling.py) within 2%."""
    from adding_doubling import slab_radiance

    from warpsky.model.scene import PhaseKind
    from warpsky.optics.phase import phase_numpy

    kind = PhaseKind.HG if phase == "hg" else PhaseKind.ISOTROPIC
    views = {"up": (0.0, 1.0), "oblique": (np.sin(np.radians(60)), 0.5), "below": (np.sin(np.arccos(0.7)), -0.7)}
    reflected, transmitted = slab_radiance(lambda c: phase_numpy(kind, g or 0.0, c), tau, 1.0, [1.0, 0.5, 0.7])
    expected = {"up": reflected[0], "oblique": reflected[1], "below": transmitted[2]}
    for name, (sideways, mu) in views.items():
        look = np.array([sideways, -mu, 0.0])  # mu > 0: camera above looking down; < 0: below looking up
        position = -look * 40.0 + np.array([0.0, 5.0, 0.0])
        spec = StageSpec(volume_file=homogeneous_npy, volume_extent=((-1e4, 0.0, -1e4), (1e4, 10.0, 1e4)),
                         extinction_scale=tau / 10.0, phase=phase, g=g, sun_direction=(0.0, 1.0, 0.0),
                         camera_position=tuple(position), camera_rotation=look_rotation(look), focal_length=2000.0)
        stage = write_stage(tmp_path / f"slab-{name}.usda", spec)
        layer = path_traced(stage, device, 8, spp=8192, seed=11)
        measured = layer.radiance[..., 1].mean()
        noise = np.sqrt(layer.aovs["variance"][..., 1].sum()) / layer.radiance[..., 1].size
        assert noise < 0.0067 * expected[name]  # a 2% error is 3 standard errors
        print(f"slab {phase} tau={tau} {name}: path tracer {measured:.5f} +- {noise:.5f}, adding-doubling "
              f"{expected[name]:.5f}")
        assert measured == pytest.approx(expected[name], rel=0.02), (name, measured, expected[name], noise)


def test_chromatic_extinction_is_unbiased_per_channel(box, device):
    """One shared path for RGB with per-channel weights: with R, G, B extinctions 0.02, 0.05, 0.12 /m and albedos
    1, 0.9, 0.7 the single-scattering estimator still equals the single-scatter technique in every channel."""
    import dataclasses

    from warpsky.techniques.single_scatter.single_scatter import SingleScatter, SingleScatterSettings

    scene = StageReader(box()).scene_at(None)
    medium = dataclasses.replace(scene.media[0], extinction_scale=np.array([0.02, 0.05, 0.12]),
                                 albedo=np.array([1.0, 0.9, 0.7]))
    scene = dataclasses.replace(scene, media=(medium,))
    reference = SingleScatter(SingleScatterSettings(step_length=0.05, shadow_step_length=0.05, min_transmittance=0.0),
                              device=device).render(scene, 12, 12)
    layer = PathTracer(PathTracer.Settings(spp=1024, max_bounces=1, seed=4), device=device).render(scene, 12, 12)
    for c in range(3):
        z = (layer.radiance[..., c].sum() - reference.radiance[..., c].sum()) / np.sqrt(
            layer.aovs["variance"][..., c].sum())
        assert abs(z) < 4.0, (c, z)
    np.testing.assert_allclose(layer.transmittance.mean(axis=(0, 1)), reference.transmittance.mean(axis=(0, 1)),
                               rtol=0.02)


def test_zero_density_gives_exactly_nothing(tmp_path, device):
    grid = tmp_path / "zero.npy"
    np.save(grid, np.zeros((5, 5, 5), dtype=np.float32))
    stage = write_stage(tmp_path / "zero.usda", StageSpec(volume_file=grid, camera_position=(0, 0, 30)))
    layer = path_traced(stage, device, 8, spp=4, environment=1.0)
    assert np.all(layer.radiance == 0.0) and np.all(layer.transmittance == 1.0)
    assert layer.stats["tracking_steps"] <= 8 * 8 * 4 * 5  # segment crossings only: no tentative collisions


def test_ground_at_sea_level_is_drawn_with_air(tmp_path, homogeneous_npy, device):
    """A ground plane at sea level (y = 0, atmosphere altitude 0) is one surface with the air's floor: camera rays
    end on the lit ground, not on the black sea. Looking straight down from 50 m through 50 m of air, each pixel is
    the Lambertian ground in the sun: albedo E T_sun / pi, T_sun the air's transmittance from the top of the
    atmosphere (Riley Eq. 12), times > 0.99 of air up to the camera; the ratio-tracked T_sun is noisy per pixel."""
    from conftest import add_atmosphere

    from warpsky.media.air.analytic import sun_transmittance

    spec = StageSpec(volume_file=homogeneous_npy, volume_translate=(500.0, 40.0, 0.0), extinction_scale=0.1,
                     camera_position=(0.0, 50.0, 0.0), camera_rotation=look_rotation((0.0, -1.0, 0.0001)),
                     sun_direction=(0.0, 1.0, 0.0), ground=(0.0, 0.5))
    stage = add_atmosphere(write_stage(tmp_path / "sea.usda", spec), scaleHeight=8000.0, altitude=0.0)
    layer = path_traced(stage, device, 8, spp=16, max_bounces=1)
    atmosphere = StageReader(stage).scene_at(None).atmosphere
    lambert = 0.5 / np.pi * sun_transmittance(atmosphere.beta_sea_level, atmosphere.gamma, 0.0, 1.0)
    np.testing.assert_allclose(layer.radiance.mean(axis=(0, 1)), lambert, rtol=0.05)
    assert layer.radiance.min() > 0.5 * lambert.min()  # every pixel sees the ground (a sea pixel would be ~0)
    assert np.all(layer.transmittance == 0.0)  # the opaque ground, not the far plane


def _slab_stage(tmp_path, homogeneous_npy, tau: float, phase: str, g, sideways: float, mu: float, name: str):
    """A 10 m slab of optical depth ``tau``, 200 km wide, under a zenith sun, seen along (sideways, -mu)."""
    look = np.array([sideways, -mu, 0.0])
    spec = StageSpec(volume_file=homogeneous_npy, volume_extent=((-1e5, 0.0, -1e5), (1e5, 10.0, 1e5)),
                     extinction_scale=tau / 10.0, phase=phase, g=g, sun_direction=(0.0, 1.0, 0.0),
                     camera_position=tuple(-look * 40.0 + np.array([0.0, 5.0, 0.0])),
                     camera_rotation=look_rotation(look), focal_length=2000.0)
    return write_stage(tmp_path / f"{name}.usda", spec)


def test_similarity_continuation_leaves_an_isotropic_medium_unchanged(tmp_path, homogeneous_npy, device):
    """High-order similarity maps an isotropic medium to itself (sigma_s (1 - 0), isotropic): reflected and
    transmitted radiance of a slab of optical depth 2 agree with the exact path tracer and with adding-doubling."""
    from adding_doubling import slab_radiance

    from warpsky.model.scene import PhaseKind
    from warpsky.optics.phase import phase_numpy

    reflected, transmitted = slab_radiance(lambda c: phase_numpy(PhaseKind.ISOTROPIC, 0.0, c), 2.0, 1.0, [1.0, 0.7])
    for (sideways, mu), expected in (((0.0, 1.0), reflected[0]), ((np.sin(np.arccos(0.7)), -0.7), transmitted[1])):
        stage = _slab_stage(tmp_path, homogeneous_npy, 2.0, "isotropic", None, sideways, mu, f"iso{mu}")
        exact = path_traced(stage, device, 8, spp=1024, seed=4)
        similar = path_traced(stage, device, 8, spp=1024, seed=5, similarity_order=1)
        values = [layer.radiance[..., 1].mean() for layer in (exact, similar)]
        noise = [np.sqrt(layer.aovs["variance"][..., 1].sum()) / 64 for layer in (exact, similar)]
        assert abs(values[0] - values[1]) < 4.0 * np.hypot(*noise), (values, noise)
        assert abs(values[1] - expected) < 0.02 * expected + 4.0 * noise[1], (values[1], expected)


def test_similarity_continuation_on_a_thick_forward_scattering_slab(tmp_path, homogeneous_npy, device):
    """Optical depth 100, HG g = 0.85, albedo 1: after 64 exact events the paths continue reduced (sigma_s (1 - g),
    isotropic). Reflected radiance straight up stays within 6% of adding-doubling (measured -3%: the order-1
    similarity with an isotropic phase is biased where the light still has angular structure; -7% to -9% after
    4 to 16 events), transmitted radiance within 6% (measured -4% and -6%), while the paths take about a third of the
    exact tracer's collisions."""
    from adding_doubling import slab_radiance

    from warpsky.model.scene import PhaseKind
    from warpsky.optics.phase import phase_numpy

    reflected, transmitted = slab_radiance(lambda c: phase_numpy(PhaseKind.HG, 0.85, c), 100.0, 1.0, [1.0, 0.7],
                                           nodes=96, doublings=30)
    for (sideways, mu), expected in (((0.0, 1.0), reflected[0]), ((np.sin(np.arccos(0.7)), -0.7), transmitted[1])):
        stage = _slab_stage(tmp_path, homogeneous_npy, 100.0, "hg", 0.85, sideways, mu, f"hg{mu}")
        layer = path_traced(stage, device, 8, spp=256, seed=6, similarity_order=64, max_bounces=100000)
        value = layer.radiance[..., 1].mean()
        noise = np.sqrt(layer.aovs["variance"][..., 1].sum()) / 64
        print(f"tau 100, mu {mu}: similarity after 64 events {value:.5f} +- {noise:.5f}, adding-doubling "
              f"{expected:.5f}, {layer.stats['tracking_steps'] / layer.stats['paths']:.0f} steps per path")
        assert abs(value - expected) < 0.06 * expected + 2.0 * noise, (value, expected, noise)


def _cloud_slab(tmp_path, homogeneous_npy, tau: float, sideways: float, mu: float, name: str):
    """:func:`_slab_stage` filled with Mie droplets (``field:cloud``) of optical depth ``tau``."""
    stage = _slab_stage(tmp_path, homogeneous_npy, 1e-5, "isotropic", None, sideways, mu, name)
    add_field(stage, "cloud", homogeneous_npy, scale=tau / 10.0)
    return stage


@pytest.mark.slow
def test_forward_cut_agrees_with_exact_paths_and_removes_the_peak_noise(tmp_path, homogeneous_npy, device,
                                                                        species_phase):
    """A slab of Mie droplets of optical depth 1 under a zenith sun, seen from above and below: cutting the
    diffraction peak (3 deg) after the first event changes the radiance by less than 4 % (plus noise) and cuts the
    noise of the mean by more than 4x (measured +4 % / -2 % within the exact tracer's noise, and 14x)."""
    species_phase("cloud")
    for name, (sideways, mu) in {"up": (0.0, 1.0), "below": (np.sin(np.arccos(0.7)), -0.7)}.items():
        stage = _cloud_slab(tmp_path, homogeneous_npy, 1.0, sideways, mu, name)
        exact = path_traced(stage, device, 8, spp=8192, seed=3)
        cut = path_traced(stage, device, 8, spp=2048, seed=4, forward_cut=3.0)
        values = [layer.radiance[..., 1].mean() for layer in (exact, cut)]
        noise = [np.sqrt(layer.aovs["variance"][..., 1].sum()) / 64 for layer in (exact, cut)]
        assert abs(values[1] - values[0]) < 0.04 * values[0] + 4.0 * np.hypot(*noise), (name, values, noise)
        assert noise[1] < noise[0] / 4.0, (name, noise)


def test_forward_cut_leaves_analytic_phases_alone_and_refuses_similarity(box, device):
    """Henyey-Greenstein media have no table to cut: the image is the exact one bit for bit. Cutting and
    high-order similarity together are refused by name."""
    from warpsky.core.errors import UsageError

    stage = box(phase="hg", g=0.85, extinction_scale=0.5)
    exact = path_traced(stage, device, 8, spp=16, seed=2)
    cut = path_traced(stage, device, 8, spp=16, seed=2, forward_cut=3.0)
    np.testing.assert_array_equal(exact.radiance, cut.radiance)
    with pytest.raises(UsageError, match="forward_cut.*similarity_order"):
        path_traced(stage, device, 8, spp=4, forward_cut=3.0, similarity_order=4)
