"""The slicing sweep across frames: kept buffers, uploads only when the grids change, the captured-graph path and
its fallback. On the CPU the graph path runs through the test hook ``sweep.CAPTURE_ON_CPU`` (Warp replays CPU
graphs itself); on CUDA it is the production path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import warp as wp
from conftest import StageSpec, look_rotation, write_stage
from test_slicing import smooth_blob

from warpsky.core import device_buffers
from warpsky.render.plan import make_plan
from warpsky.techniques.slicing import sweep
from warpsky.techniques.slicing.slicing import Slicing
from warpsky.usd.stage import StageReader

SIZE = 16
SETTINGS = {"slice_count": "8", "light_resolution": "16"}


@pytest.fixture
def puff_scene(tmp_path):
    """A soft puff lit from the side above a ground, as a Scene (each frame renders it with a new technique, as a
    batch does)."""
    spec = StageSpec(volume_file=smooth_blob(tmp_path / "blob.npy", 8), extinction_scale=0.3,
                     camera_position=(3.0, 4.0, 42.0), camera_rotation=look_rotation((-0.05, -0.06, -1.0)),
                     sun_direction=(0.4, 0.8, 0.3), phase="hg", g=0.8, ground=(-12.0, 0.3))
    return StageReader(write_stage(tmp_path / "puff.usda", spec)).scene_at(None)


def frame(scene, device):
    """One frame with a new technique instance; returns the layer."""
    plan = make_plan(scene, technique="slicing", settings=SETTINGS, resolution=(SIZE, SIZE), device=device)
    return Slicing(plan.settings, device=device).render(scene, SIZE, SIZE)


def other_sun(scene):
    direction = np.array([0.3, 0.5, -0.8]) / np.linalg.norm([0.3, 0.5, -0.8])
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, direction=direction))


@pytest.fixture
def graphs(monkeypatch, device):
    """Graph path on (also on the CPU), no graph kept, no warning printed yet; yields a function giving the plain
    path's layer of a scene."""
    monkeypatch.setattr(sweep, "CAPTURE_ON_CPU", True)
    monkeypatch.setattr(sweep, "_WARNED", [False])
    sweep.forget_graphs()

    def plain(scene):
        with monkeypatch.context() as m:
            m.setattr(sweep, "USE_GRAPHS", False)
            layer = frame(scene, device)
        assert layer.stats["sweep"] == "plain"
        return layer

    yield plain
    sweep.forget_graphs()


def scribble(device) -> None:
    """Overwrite the kept sweep buffers, so that a frame shows only what its own launches (or replay) computed."""
    for name, shape in (("radiance", SIZE), ("transmittance", SIZE), ("depth_sum", SIZE), ("spans", SIZE),
                        ("light_i", 16), ("light_n", 16)):
        dtype = wp.vec2 if name in ("depth_sum", "spans") else wp.vec3
        array = device_buffers.reusable(f"slicing:{name}", (shape, shape), dtype, device)
        array.fill_(dtype(*([-7.0] * dtype._length_)))


def same_pixels(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in ((a.radiance, b.radiance), (a.transmittance, b.transmittance),
                                                  (a.depth, b.depth)))


def test_graph_is_captured_once_replayed_and_recaptured_when_the_sun_moves(puff_scene, device, graphs):
    reference, moved_reference = graphs(puff_scene), graphs(other_sun(puff_scene))
    scribble(device)
    first = frame(puff_scene, device)
    scribble(device)
    second = frame(puff_scene, device)
    assert (first.stats["sweep"], second.stats["sweep"]) == ("captured", "replayed")
    assert same_pixels(first, reference) and same_pixels(second, reference)
    scribble(device)
    moved = frame(other_sun(puff_scene), device)  # the sun is baked into the graph by value: capture again
    assert moved.stats["sweep"] == "captured" and same_pixels(moved, moved_reference)
    assert not same_pixels(moved, reference)


@pytest.mark.parametrize("where", ["begin", "inside"])
def test_failed_capture_falls_back_to_plain_launches_with_one_warning(puff_scene, device, graphs, monkeypatch,
                                                                      capsys, where):
    reference = graphs(puff_scene)
    if where == "begin":
        def refuse(*args, **kwargs):
            raise RuntimeError("capture refused")

        monkeypatch.setattr(wp, "ScopedCapture", refuse)
    else:  # a launch fails while the capture is open: the capture must still be ended
        issue = sweep.SliceSweep.issue

        def failing(self, *, capturing):
            if capturing:
                raise RuntimeError("launch refused during capture")
            issue(self, capturing=capturing)

        monkeypatch.setattr(sweep.SliceSweep, "issue", failing)
    layers = [frame(puff_scene, device), frame(puff_scene, device)]
    warnings = [line for layer in layers for line in layer.warnings]
    assert len(warnings) == 1 and layers[0].warnings, warnings
    assert "slicing" in warnings[0]
    assert [layer.stats["sweep"] for layer in layers] == ["plain", "plain"]
    assert all(same_pixels(layer, reference) for layer in layers)


def test_buffers_kept_and_grids_uploaded_only_when_they_change(puff_scene, device):
    frame(puff_scene, device)  # the first frame allocates what it needs
    before = device_buffers.allocation_count()
    values = device_buffers.upload("slicing:values", puff_scene.media[0].density.reshape(-1).astype(np.float32),
                                   float, device)
    frame(puff_scene, device)
    assert device_buffers.allocation_count() == before  # same stage: no buffer, table or grid allocated again
    medium = puff_scene.media[0]
    changed = dataclasses.replace(puff_scene, media=(dataclasses.replace(medium, density=medium.density * 0.5),))
    layer = frame(changed, device)
    # the new values, their cells' maxima and their column sums, nothing else
    assert device_buffers.allocation_count() == before + 3
    again = device_buffers.upload("slicing:values", changed.media[0].density.reshape(-1).astype(np.float32), float,
                                  device)
    assert again is not values and np.array_equal(again.numpy(), changed.media[0].density.reshape(-1))
    assert np.all(np.isfinite(layer.radiance)) and np.any(np.all(layer.transmittance == 0.0, axis=-1))  # ground


def test_the_captured_sweep_allocates_reads_back_and_synchronises_nothing(puff_scene, device, graphs, monkeypatch):
    """CUDA's capture rules, checked on every device: inside the capture no array is created, copied to the host or
    waited for (any of these would fail or bake a stale host pointer into a CUDA graph)."""
    issue = sweep.SliceSweep.issue

    def guarded(self, *, capturing):
        if not capturing:
            return issue(self, capturing=capturing)

        def refuse(*args, **kwargs):
            raise AssertionError("not allowed inside a graph capture")

        with monkeypatch.context() as m:
            for owner, name in ((wp.array, "__init__"), (wp.array, "numpy"), (wp, "synchronize"),
                                (wp, "synchronize_device"), (wp, "synchronize_stream"), (wp, "copy")):
                m.setattr(owner, name, refuse)
            issue(self, capturing=capturing)

    monkeypatch.setattr(sweep.SliceSweep, "issue", guarded)
    layer = frame(puff_scene, device)
    assert layer.stats["sweep"] == "captured" and same_pixels(layer, graphs(puff_scene))


def test_chunks_of_planes_give_the_pixels_of_one_plane_at_a_time(puff_scene, device, monkeypatch):
    """The sweep in chunks (the light carried through several planes, then the eye through them) computes per texel
    and per pixel what alternating one light step and one eye step per plane does: a chunk of one plane is that
    alternation, and every chunking gives its pixels bit for bit."""
    per_plane = 2 * 12 * 16 * 16
    layers = {}
    for planes_per_chunk in (1, 3, 8):
        monkeypatch.setattr(sweep, "STACK_BYTES", {"cpu": per_plane * planes_per_chunk,
                                                   "cuda": per_plane * planes_per_chunk})
        layers[planes_per_chunk] = frame(puff_scene, device)
    assert float(layers[1].radiance.max()) > 0.0
    assert same_pixels(layers[1], layers[3]) and same_pixels(layers[1], layers[8])


def test_chunk_sizes_fit_the_budget_and_even_out():
    per_plane = 2 * 12 * 256 * 256
    most = sweep.STACK_BYTES["cpu"] // per_plane
    assert sweep.chunk_planes(most, 256, "cpu") == most
    assert sweep.chunk_planes(most + 1, 256, "cpu") == -(-(most + 1) // 2)  # two even chunks, not most + 1
    assert sweep.chunk_planes(161, 256, "cpu") * per_plane <= sweep.STACK_BYTES["cpu"]
    assert sweep.chunk_planes(1, 4096, "cpu") == 1  # one plane per chunk however large the buffer
    assert sweep.chunk_planes(161, 256, "cuda:0") == 161  # a GPU sweeps the storm's 161 planes in one chunk
