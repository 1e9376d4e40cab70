"""The hybrid's error estimate counts the denoiser's bias that its two halves measure, and no noise as bias."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import StageSpec, look_rotation, write_stage

from warpsky.render.plan import make_plan
from warpsky.techniques.hybrid import estimate as estimate_module
from warpsky.techniques.hybrid import hybrid as hybrid_module
from warpsky.techniques.hybrid.denoise import Denoised
from warpsky.techniques.hybrid.estimate import with_denoiser_bias
from warpsky.usd.stage import StageReader


def box_blur(image: np.ndarray, radius: int) -> np.ndarray:
    """Mean over a (2 radius + 1)^2 box, edges clamped: a linear 'denoiser' whose bias is known exactly."""
    padded = np.pad(image, ((radius, radius), (radius, radius), (0, 0)), mode="edge")
    out = np.zeros_like(image, dtype=np.float64)
    size = 2 * radius + 1
    for dy in range(size):
        for dx in range(size):
            out += padded[dy:dy + image.shape[0], dx:dx + image.shape[1]]
    return out / size**2


def truth_image(size: int = 64) -> np.ndarray:
    """Squares of light with sharp edges (where a blur is biased) on a dimmer floor, three channels."""
    y, x = np.mgrid[0:size, 0:size]
    light = 1.0 + 2.0 * (((x // 8) + (y // 8)) % 2)
    return np.repeat(light[..., None].astype(np.float64), 3, axis=-1) * np.array([1.0, 0.9, 0.8])


def halves(light: np.ndarray, sigma: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = light + sigma * rng.standard_normal(light.shape)
    b = light + sigma * rng.standard_normal(light.shape)
    return a, b, np.full(light.shape, sigma**2)


@pytest.mark.parametrize("sigma", [0.02, 1.0])
def test_a_blurring_denoisers_error_is_measured_without_a_reference(sigma):
    """A 7 x 7 box blur of a checkerboard: the estimate (its noise plus the bias bound) is within 10 % of the
    denoised whole's actual relative RMSE against the truth, with raw halves nearly noise-free (sigma 0.02) or about
    half as noisy per pixel as the light is bright (1.0)."""
    light = truth_image()
    a, b, variance = halves(light, sigma, seed=1)
    covered = np.ones(light.shape[:2], bool)
    level = float(light.mean())
    got = with_denoiser_bias((a, b), (variance, variance), (box_blur(a, 3), box_blur(b, 3)), covered, level)
    actual = math.sqrt(np.mean((box_blur(0.5 * (a + b), 3) - light) ** 2)) / level
    assert got == pytest.approx(actual, rel=0.1)


def test_an_unbiased_denoiser_counts_no_bias():
    """The identity as 'denoiser', noise only: the estimate is the raw whole's noise, sigma / sqrt(2), within the
    sampling error of the halves' difference; nothing is counted as bias."""
    light = truth_image()
    sigma = 0.3
    counted = []
    for seed in range(20):
        a, b, variance = halves(light, sigma, seed)
        got = with_denoiser_bias((a, b), (variance, variance), (a, b), np.ones(light.shape[:2], bool), 1.0)
        half_noise = float(np.mean((a - b) ** 2)) / 2.0
        counted.append(got**2 - half_noise / 2.0)
        assert got == pytest.approx(sigma / math.sqrt(2.0), rel=0.03)
    assert sum(value > 1e-12 for value in counted) <= 2  # a 2-standard-error bound: about 1 in 44 counts noise


def test_nothing_covered_or_no_light_is_zero():
    light = truth_image(8)
    a, b, variance = halves(light, 0.1, seed=3)
    assert with_denoiser_bias((a, b), (variance, variance), (a, b), np.zeros((8, 8), bool), 1.0) == 0.0
    assert with_denoiser_bias((a, b), (variance, variance), (a, b), np.ones((8, 8), bool), 0.0) == 0.0


def blurring_denoiser(image, coverage, *, radius, quality="high", device="cpu"):
    return Denoised(box_blur(np.asarray(image, np.float64), 2).astype(np.float32), 0.0, 0)


def box_scene(tmp_path, volume_file):
    """A lit homogeneous box seen from above at an angle."""
    spec = StageSpec(volume_file=volume_file, extinction_scale=0.3, camera_position=(3.0, 4.0, 42.0),
                     camera_rotation=look_rotation((-0.05, -0.06, -1.0)), sun_direction=(0.4, 0.8, 0.3))
    return StageReader(write_stage(tmp_path / "box.usda", spec)).scene_at(None)


def test_the_frames_estimate_sees_the_denoisers_blur(tmp_path, homogeneous_npy, monkeypatch):
    """A frame denoised by a 5 x 5 box blur at 2,048 paths per pixel: its estimate is within 30 % of its error
    against 16,384 undenoised paths; without the bias bound the halves alone put it below half of that."""
    scene = box_scene(tmp_path, homogeneous_npy)

    def render(**settings):
        plan = make_plan(scene, technique="hybrid", settings={k: str(v) for k, v in settings.items()},
                         resolution=(16, 16), device="cpu")
        return plan.renderer.render(scene, 16, 16)

    truth = render(spp=16384, target_error=0, denoise=0, seed=2, samples_per_pass=1024)
    covered = truth.transmittance.mean(axis=-1) < 0.99
    monkeypatch.setattr(hybrid_module, "denoise", blurring_denoiser)

    def frame_and_error():
        layer = render(spp=2048, target_error=1e-4, seed=1, samples_per_pass=256)
        error = np.sqrt(np.mean((layer.radiance - truth.radiance)[covered] ** 2)) / truth.radiance[covered].mean()
        return layer.stats["error_estimate"], float(error)

    estimate, error = frame_and_error()
    assert estimate == pytest.approx(error, rel=0.3)
    monkeypatch.setattr(estimate_module, "with_denoiser_bias", lambda *args: 0.0)
    halves_only, same_error = frame_and_error()
    assert same_error == pytest.approx(error, rel=1e-6)
    assert halves_only < 0.5 * error


def test_one_path_per_half_counts_no_bias(tmp_path, homogeneous_npy, monkeypatch):
    """With one path per pixel in each half a half's variance is unknown (zero from one sample), which would count
    all of its noise as bias: the bound is not taken then."""
    scene = box_scene(tmp_path, homogeneous_npy)
    monkeypatch.setattr(hybrid_module, "denoise", blurring_denoiser)
    called = []
    monkeypatch.setattr(estimate_module, "with_denoiser_bias", lambda *args: called.append(1) or 0.0)
    plan = make_plan(scene, technique="hybrid", settings={"spp": "2", "samples_per_pass": "1",
                                                          "target_error": "1e-4"}, resolution=(16, 16), device="cpu")
    layer = plan.renderer.render(scene, 16, 16)
    assert layer.stats["passes"] == 2 and math.isfinite(layer.stats["error_estimate"])
    assert called == []
    plan = make_plan(scene, technique="hybrid", settings={"spp": "4", "samples_per_pass": "2",
                                                          "target_error": "1e-4"}, resolution=(16, 16), device="cpu")
    plan.renderer.render(scene, 16, 16)
    assert called  # two paths per half: taken
