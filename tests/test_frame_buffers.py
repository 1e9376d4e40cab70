"""Frames of a batch reuse their device buffers: the second frame of the same stage allocates nothing through
:mod:`warpsky.core.device_buffers` and gives the same pixels as a fresh render; the radiosity reads few values back."""

from __future__ import annotations

import dataclasses
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, write_stage

from warpsky.core import device_buffers
from warpsky.render.plan import make_plan
from warpsky.techniques.path_tracer.path_tracer import (
    PathTracerSettings,
    PathTracing,
    per_sample_launches,
    pixel_sums,
    sums_layer,
)
from warpsky.usd.stage import StageReader

SIZE = 12


@pytest.fixture
def stage(tmp_path, homogeneous_npy):
    spec = StageSpec(volume_file=homogeneous_npy, extinction_scale=0.15, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3),
                     ground=(-12.0, 0.3))
    return write_stage(tmp_path / "box.usda", spec)


def render_frame(stage, device, technique, **settings):
    """One frame as a batch renders it: a new technique instance per frame."""
    scene = StageReader(stage).scene_at(None)
    plan = make_plan(scene, technique=technique, settings={k: str(v) for k, v in settings.items()},
                     resolution=(SIZE, SIZE), device=device)
    return plan.renderer.render(scene, SIZE, SIZE)


def assert_layers_equal(a, b):
    np.testing.assert_array_equal(a.radiance, b.radiance)
    np.testing.assert_array_equal(a.transmittance, b.transmittance)
    np.testing.assert_array_equal(a.depth, b.depth)
    for name in a.aovs:
        np.testing.assert_array_equal(a.aovs[name], b.aovs[name])


@pytest.mark.parametrize("technique,settings", [
    ("path_tracer", {"spp": 6, "samples_per_pass": 4, "max_bounces": 8}),
    ("hybrid", {"spp": 4, "target_error": 0, "denoise": 0, "max_bounces": 8}),
    ("single_scatter", {}),
])


def test_second_frame_allocates_nothing_and_matches_a_fresh_render(stage, device, technique, settings):
    device_buffers.clear()
    fresh = render_frame(stage, device, technique, **settings)
    allocated = device_buffers.allocation_count()
    second = render_frame(stage, device, technique, **settings)
    assert device_buffers.allocation_count() == allocated
    assert_layers_equal(second, fresh)


@pytest.mark.parametrize("technique,settings", [
    ("path_tracer", {"spp": 16, "samples_per_pass": 1, "max_bounces": 8}),
    ("hybrid", {"spp": 8, "samples_per_pass": 1, "target_error": 0, "denoise": 0, "max_bounces": 8}),
])


def test_frames_rendered_at_once_by_threads_do_not_share_kept_buffers(stage, technique, settings):
    """Two threads of one process rendering frames at once (a multi-threaded Dask worker) take turns on the kept
    arrays: each frame equals the one rendered alone (without the lock, one frame's passes zero or add into the
    other's sums)."""
    alone = render_frame(stage, "cpu", technique, **settings)
    start = threading.Barrier(3)

    def frames():
        start.wait()
        return [render_frame(stage, "cpu", technique, **settings) for _ in range(3)]

    with ThreadPoolExecutor(3) as pool:
        results = [layer for future in [pool.submit(frames) for _ in range(3)] for layer in future.result()]
    for layer in results:
        assert_layers_equal(layer, alone)


def test_path_tracer_pixels_do_not_depend_on_the_pass_split(stage):
    one = render_frame(stage, "cpu", "path_tracer", spp=6, samples_per_pass=6, max_bounces=8)
    split = render_frame(stage, "cpu", "path_tracer", spp=6, samples_per_pass=1, max_bounces=8)
    assert_layers_equal(one, split)


@pytest.mark.parametrize("multiple_only", [False, True])
def test_one_thread_per_path_adds_the_same_sums_as_one_thread_per_pixel(stage, multiple_only):
    """The launch a small frame gets on a GPU, run on the CPU: the same pixels, bit for bit, for any split."""
    scene = StageReader(stage).scene_at(None)
    settings = PathTracerSettings(spp=5, samples_per_pass=2, max_bounces=8, pixel_jitter=multiple_only)
    layers = []
    for per_sample, name in [(False, "test:pixel"), (True, "test:sample")]:
        tracing = PathTracing(scene, SIZE, SIZE - 2, settings, "cpu", per_sample=per_sample,
                              multiple_only=multiple_only, buffer_name=name)
        assert bool(tracing.samples_per_launch) == per_sample
        sums = pixel_sums((SIZE - 2, SIZE), "cpu", name=name)
        for first, count in [(0, 2), (2, 1), (3, 2)]:
            tracing.launch(sums, first, count)
        layers.append(sums_layer([sums], 5, 1.0e5, name=name))
    assert layers[0].radiance.any()
    assert_layers_equal(layers[1], layers[0])
    assert layers[1].stats == layers[0].stats


def test_small_gpu_frames_run_one_thread_per_path():
    assert per_sample_launches("cpu", 128 * 128, 64) == 0
    assert per_sample_launches("cuda:0", 128 * 128, 64) == 64  # 2^20 threads per launch, not 2^14
    assert per_sample_launches("cuda:0", 512 * 512, 64) == 0  # the frame fills the GPU alone
    assert per_sample_launches("cuda:0", 256 * 256, 64) == 32  # at most 2^21 threads per launch
    assert per_sample_launches("cuda:0", 16 * 16, 4) == 4


def test_sky_pass_second_frame_allocates_nothing(device):
    from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun
    from warpsky.passes.sky.sky import Sky

    cam = Camera("c", np.array([0.0, 2.0, 0.0]), look_rotation((0.0, 0.3, -1.0)), 20.0, 36.0, 24.0, far=1e5)
    scene = Scene(cam, Sun((0.3, 0.8, 0.2), (1.0, 1.0, 1.0)), ground=Ground(0.0), atmosphere=Atmosphere())
    device_buffers.clear()
    first = Sky(device=device).render(scene, SIZE, SIZE)
    allocated = device_buffers.allocation_count()
    depth = np.full((SIZE, SIZE), 500.0, np.float32)
    Sky(device=device).render(scene, SIZE, SIZE, media_depth=depth)
    second = Sky(device=device).render(dataclasses.replace(scene), SIZE, SIZE)
    assert device_buffers.allocation_count() == allocated
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.radiance, b.radiance)
        np.testing.assert_array_equal(a.transmittance, b.transmittance)


def stratiform_frame(device, radiosity=True):
    from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun
    from warpsky.model.stratiform import StratiformLayer
    from warpsky.passes.stratiform.stratiform import Stratiform, StratiformSettings

    cam = Camera("c", np.array([0.0, 2.0, 0.0]), look_rotation((0.0, 1.0, -0.2)), 20.0, 36.0, 24.0, far=1e5)
    scene = Scene(cam, Sun((0.3, 0.8, 0.2), (1.0, 1.0, 1.0)), ground=Ground(0.0, albedo=(0.6, 0.6, 0.6)),
                  atmosphere=Atmosphere())
    layer = StratiformLayer(np.full((16, 16), 300.0, np.float32), 1500.0, (-10000.0, -10000.0), (20000.0, 20000.0))
    return Stratiform(StratiformSettings(radiosity=radiosity), device=device).render(scene, SIZE, SIZE, layer=layer)


@pytest.mark.parametrize("radiosity", [True, False])
def test_stratiform_second_frame_allocates_nothing(device, radiosity):
    device_buffers.clear()
    fresh = stratiform_frame(device, radiosity)
    allocated = device_buffers.allocation_count()
    second = stratiform_frame(device, radiosity)
    assert device_buffers.allocation_count() == allocated
    assert_layers_equal(second, fresh)


def test_stratiform_frames_rendered_at_once_by_threads_match_one_alone():
    """The stratiform pass and its radiosity hold their kept arrays (R_G and R_C included) until the shading kernel
    has read them: threads rendering at once get the frame rendered alone."""
    alone = stratiform_frame("cpu")
    start = threading.Barrier(3)

    def frames():
        start.wait()
        return [stratiform_frame("cpu") for _ in range(3)]

    with ThreadPoolExecutor(3) as pool:
        results = [layer for future in [pool.submit(frames) for _ in range(3)] for layer in future.result()]
    for layer in results:
        assert_layers_equal(layer, alone)


def radiosity_problem():
    rng = np.random.default_rng(1)
    shape = (32, 32)
    return dict(ground_albedo=np.full(shape, 0.8), cloud_reflectance=rng.uniform(0.3, 0.9, shape),
                ground_direct=rng.uniform(0.0, 1.0, (*shape, 3)), cloud_source=rng.uniform(0.0, 0.3, (*shape, 3)))


def count_downloads(monkeypatch) -> list[str]:
    names: list[str] = []
    download = device_buffers.download

    def counted(name, array):
        names.append(name)
        return download(name, array)

    monkeypatch.setattr(device_buffers, "download", counted)
    return names


@pytest.mark.parametrize("check_every", [3, 8])
def test_radiosity_reads_back_every_few_iterations_and_converges_alike(device, monkeypatch, check_every):
    from warpsky.passes.stratiform.radiosity import Radiosity

    tolerance = 1e-5
    every = Radiosity(tolerance=tolerance, device=device, check_every=1).solve(**radiosity_problem())
    names = count_downloads(monkeypatch)
    batched = Radiosity(tolerance=tolerance, device=device, check_every=check_every).solve(**radiosity_problem())
    assert batched.converged and every.converged
    assert every.iterations <= batched.iterations < every.iterations + check_every
    assert batched.history[:every.iterations] == pytest.approx(every.history, rel=1e-6)
    # the iterations past convergence add less than the tolerance of what the ground received
    np.testing.assert_allclose(batched.ground_received, every.ground_received,
                               rtol=check_every * tolerance, atol=1e-7)
    np.testing.assert_allclose(batched.cloud_received, every.cloud_received, rtol=check_every * tolerance, atol=1e-7)
    # R_G after the first gather, the exchanged energies every check_every iterations, R_G and R_C at the end
    assert len(names) == 1 + -(-batched.iterations // check_every) + 2


def test_radiosity_default_on_the_cpu_reads_every_iteration():
    from warpsky.passes.stratiform.radiosity import Radiosity

    assert Radiosity(device="cpu").check_every == 1
    assert Radiosity(device="cuda:0").check_every == 8


def test_stratiform_frame_downloads_each_output_once(device, monkeypatch):
    stratiform_frame(device)  # compiled and warm
    names = count_downloads(monkeypatch)
    layer = stratiform_frame(device)
    iterations = layer.stats["radiosity_iterations"]
    outputs = [n for n in names if n.startswith("stratiform:")]
    assert sorted(outputs) == ["stratiform:depth", "stratiform:radiance", "stratiform:transmittance"]
    checks = -(-iterations // (1 if device == "cpu" else 8))
    assert len(names) == 3 + 1 + 1 + checks + 2  # outputs, S_G^d, R_G, exchanged energies, R_G and R_C


def test_refill_reuses_one_array_and_copies_only_changed_bytes(device):
    import warp as wp

    device_buffers.clear()
    allocated = device_buffers.allocation_count()
    first = device_buffers.refill("test:map", np.ones((3, 4, 3), np.float32), wp.vec3, device)
    first.zero_()  # a marker: a refill with the same bytes copies nothing, so it stays
    same = device_buffers.refill("test:map", np.ones((3, 4, 3), np.float32), wp.vec3, device)
    assert same is first and not same.numpy().any()
    changed = device_buffers.refill("test:map", np.full((3, 4, 3), 2.0, np.float32), wp.vec3, device)
    assert changed is first and device_buffers.allocation_count() == allocated + 1
    np.testing.assert_array_equal(changed.numpy(), 2.0)
    scalar = device_buffers.refill("test:heights", np.arange(6.0).reshape(2, 3), float, device)
    assert scalar.shape == (2, 3) and scalar.dtype == wp.float32
    np.testing.assert_array_equal(scalar.numpy(), np.arange(6.0).reshape(2, 3))
