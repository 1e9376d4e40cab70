"""Advected textures (Neyret 2003): still and uniform flows, statistics over 2,000 frames, random access in time,
divergence-free curl noise, stiff and extreme cases, and the 3D detail ``@wp.func`` inside a kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

import warpsky.media.advection.advection as advection
from warpsky.core.errors import SceneError
from warpsky.media.advection.advection import (
    AdvectedDetail,
    AdvectedTexture,
    Flow2D,
    Flow3D,
    LayerSchedule,
    autocorrelation,
    layer_schedule,
    periodic_noise,
)
from warpsky.media.advection.advection_kernels import DetailState, modulated_density

EXTENT = (1000.0, 1000.0)  # [m], a 64^2 texture: 15.6 m texels
MEAN, STD = 1.0, 0.25  # the test texture's statistics (a thickness-like map)


def texture(n: int = 64, smoothing: float = 2.0, seed: int = 1) -> np.ndarray:
    return (MEAN + STD * periodic_noise((n, n), smoothing_texels=smoothing, seed=seed)).astype(np.float32)


def curl_flow(speed: float = 5.0, wind=(3.0, 1.0), resolution=(32, 32)) -> Flow2D:
    return Flow2D.procedural(EXTENT, speed_m_s=speed, scale_m=500.0, resolution=resolution, seed=3, wind_m_s=wind)


def frames(layer: AdvectedTexture, times) -> np.ndarray:
    return np.stack([layer.at(t).numpy().copy() for t in times])


# --- still and uniform flows -------------------------------------------------------------------------------------


def test_zero_velocity_shows_the_static_texture(device):
    """Zero velocity: every layer samples its own texel, so the output is the texture bit for bit."""
    tex = texture()
    still = Flow2D.procedural(EXTENT, speed_m_s=0.0, scale_m=500.0, resolution=(32, 32))
    layer = AdvectedTexture(tex, EXTENT, still, period_s=100.0, step_s=3.0, device=device)
    for t in (0.0, 12.5, 1.0e5, -333.3, -1.0e7):
        np.testing.assert_array_equal(layer.at(t).numpy(), tex)


def test_uniform_wind_translates_the_texture(device):
    """Wind only: the output is the texture translated by wind * t. Against the exact (spectral) translation the
    error is bilinear interpolation's, bounded by (max|f_xx| + max|f_yy|) / 8 in texel units; against a float64
    bilinear resampling only float32 coordinate rounding remains (<= 1e-5)."""
    tex = texture()
    wind = np.array([7.3, -2.1])
    layer = AdvectedTexture(tex, EXTENT, Flow2D.still(EXTENT, wind_m_s=wind), period_s=60.0, device=device)
    n = tex.shape[0]
    k = 2.0 * np.pi * np.fft.fftfreq(n)
    spectrum = np.fft.fft2(tex.astype(np.float64))
    fxx = np.fft.ifft2(spectrum * -(k[None, :] ** 2)).real
    fyy = np.fft.ifft2(spectrum * -(k[:, None] ** 2)).real
    interpolation_bound = (np.abs(fxx).max() + np.abs(fyy).max()) / 8.0
    for t in (0.0, 41.0, 1234.567, -98.7, -5.0e5):
        shift = wind * t * n / EXTENT[0]  # texels
        exact = np.fft.ifft2(spectrum * np.exp(-1j * (k[None, :] * shift[0] + k[:, None] * shift[1]))).real
        got = layer.at(t).numpy()
        assert np.abs(got - exact).max() <= interpolation_bound + 1e-5
        # float64 bilinear resampling of the periodic texture at x - shift
        x = np.arange(n) - np.mod(shift[0], n)
        y = np.arange(n) - np.mod(shift[1], n)
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        tx, ty = (x - x0)[None, :], (y - y0)[:, None]
        t64 = tex.astype(np.float64)
        rows = [t64[np.mod(jj, n)] for jj in (y0, y0 + 1)]
        cols = [[r[:, np.mod(ii, n)] for ii in (x0, x0 + 1)] for r in rows]
        bilinear = ((cols[0][0] * (1 - tx) + cols[0][1] * tx) * (1 - ty)
                    + (cols[1][0] * (1 - tx) + cols[1][1] * tx) * ty)
        np.testing.assert_allclose(got, bilinear, rtol=0, atol=1e-5)


# --- statistics and popping --------------------------------------------------------------------------------------


FRAME_S = 1.0  # frame interval [s]
PERIOD_S = 100.0  # layer period: 100 frames, 20 periods in 2,000 frames


def frame_changes(layer: AdvectedTexture, frame_count: int):
    """Per frame: mean, std; per frame pair: max and rms |change|."""
    means, stds, max_change, rms_change = [], [], [], []
    previous = None
    for f in range(frame_count):
        out = layer.at(f * FRAME_S).numpy().astype(np.float64)
        means.append(out.mean())
        stds.append(out.std())
        if previous is not None:
            change = np.abs(out - previous)
            max_change.append(change.max())
            rms_change.append(math.sqrt(np.mean(change**2)))
        previous = out.copy()
    return np.array(means), np.array(stds), np.array(max_change), np.array(rms_change)


def regeneration_pairs(layer: AdvectedTexture, frame_count: int) -> np.ndarray:
    """Mask over frame pairs (f, f + 1) between which some layer is regenerated."""
    regen = np.stack([layer.schedule(f * FRAME_S).regeneration for f in range(frame_count)])
    return np.any(regen[1:] != regen[:-1], axis=1)


def smooth_change_bound(tex: np.ndarray, flow: Flow2D) -> float:
    """Upper envelope of one frame's change under smooth advection: 2 x (fastest motion per frame, wind
    included, in texels) x (largest texel-to-texel difference of the texture). The factor 2 covers the layers'
    stretching within a period and the weights' drift (at most pi/period per second)."""
    speed = np.sqrt(np.sum(flow.velocity.astype(np.float64) ** 2, axis=-1)).max() + np.linalg.norm(flow.wind_m_s)
    texels_per_frame = speed * FRAME_S * tex.shape[1] / EXTENT[0]
    steepest = max(np.abs(np.diff(tex, axis=0, append=tex[:1])).max(),
                   np.abs(np.diff(tex, axis=1, append=tex[:, :1])).max())
    return 2.0 * texels_per_frame * float(steepest)


def test_statistics_over_2000_frames_and_no_popping(device):
    """Curl noise (5 m/s rms) plus wind: over 2,000 frames the per-frame mean and std stay within 5 % of the
    source's, no pixel changes by more than the smooth-advection envelope between frames, and frames across a
    regeneration change no more than the others (rms change within 1.25 x the median frame's)."""
    tex = texture()
    flow = curl_flow()
    layer = AdvectedTexture(tex, EXTENT, flow, period_s=PERIOD_S, step_s=1.0, device=device)
    means, stds, max_change, rms_change = frame_changes(layer, 2000)
    source_mean, source_std = float(tex.astype(np.float64).mean()), float(tex.astype(np.float64).std())
    bound = smooth_change_bound(tex, flow)
    regen = regeneration_pairs(layer, 2000)
    print(f"\nmean/source-1 in [{means.min() / source_mean - 1:+.4f}, {means.max() / source_mean - 1:+.4f}], "
          f"std/source-1 in [{stds.min() / source_std - 1:+.4f}, {stds.max() / source_std - 1:+.4f}]; "
          f"max change {max_change.max() / source_std:.3f} std (bound {bound / source_std:.3f}); "
          f"rms change: median {np.median(rms_change) / source_std:.3f}, "
          f"across regenerations max {rms_change[regen].max() / source_std:.3f} std ({regen.sum()} pairs)")
    np.testing.assert_allclose(means, source_mean, rtol=0.05)
    np.testing.assert_allclose(stds, source_std, rtol=0.05)
    assert max_change.max() <= bound
    assert rms_change[regen].max() <= 1.25 * np.median(rms_change)


def test_popping_would_be_caught(monkeypatch):
    """The no-popping criterion detects a pop: with weights that do not fade a layer out before its reset, the rms
    change across regenerations exceeds 1.25 x the median frame's."""
    original = advection.layer_schedule

    def constant_weights(*args):
        s = original(*args)
        return LayerSchedule(s.regeneration, s.age_s, s.full_steps, s.partial_s, np.ones_like(s.weights))

    monkeypatch.setattr(advection, "layer_schedule", constant_weights)
    layer = AdvectedTexture(texture(), EXTENT, curl_flow(), period_s=PERIOD_S, step_s=1.0)
    _, _, _, rms_change = frame_changes(layer, 300)
    regen = regeneration_pairs(layer, 300)
    assert rms_change[regen].min() > 1.25 * np.median(rms_change)


# --- random access in time ---------------------------------------------------------------------------------------


def test_random_access_equals_sequential_playback(device):
    """Frame 997 computed cold equals frame 997 reached by stepping through frames 0..996 (bit-identical)."""
    tex = texture()
    flow = curl_flow()
    frame_s = 0.5
    sequential = AdvectedTexture(tex, EXTENT, flow, period_s=PERIOD_S, step_s=0.75, device=device)
    for f in range(997):
        sequential.at(f * frame_s)
    played = sequential.at(997 * frame_s).numpy().copy()
    cold = AdvectedTexture(tex, EXTENT, flow, period_s=PERIOD_S, step_s=0.75, device=device)
    np.testing.assert_array_equal(cold.at(997 * frame_s).numpy(), played)
    # going backwards recomputes from the regenerations and still agrees with a cold start
    back = sequential.at(900 * frame_s).numpy().copy()
    cold.reset()
    np.testing.assert_array_equal(cold.at(900 * frame_s).numpy(), back)


def test_schedule_bounds_work_and_fades_layers_out():
    """Ages lie in [0, period); at most period/step full steps; weights vanish at regeneration."""
    for t in np.linspace(-1000.0, 1000.0, 777):
        s = layer_schedule(float(t), 3, 64.0, 0.7)
        assert np.all(s.age_s >= 0.0) and np.all(s.age_s < 64.0)
        assert np.all(s.full_steps <= math.floor(64.0 / 0.7))
        np.testing.assert_allclose(s.weights.sum(), 1.5, atol=1e-12)  # sum of sin^2 over 3 staggered layers
        np.testing.assert_allclose(s.partial_s + s.full_steps * 0.7, s.age_s, atol=1e-9)
    s = layer_schedule(64.0 / 3.0, 3, 64.0, 0.7)  # layer 1 is regenerated now
    assert s.age_s[1] == pytest.approx(0.0, abs=1e-12) and s.weights[1] == pytest.approx(0.0, abs=1e-20)


# --- flows -------------------------------------------------------------------------------------------------------


def divergence_ratio_2d(flow: Flow2D) -> float:
    """rms(central-difference divergence) / rms(|grad u|) on the flow's grid."""
    u = flow.velocity.astype(np.float64)
    hx = flow.extent_m[0] / u.shape[1]
    hy = flow.extent_m[1] / u.shape[0]

    def dx(f):
        return (np.roll(f, -1, axis=1) - np.roll(f, 1, axis=1)) / (2 * hx)

    def dy(f):
        return (np.roll(f, -1, axis=0) - np.roll(f, 1, axis=0)) / (2 * hy)

    div = dx(u[..., 0]) + dy(u[..., 1])
    grad = dx(u[..., 0]) ** 2 + dy(u[..., 0]) ** 2 + dx(u[..., 1]) ** 2 + dy(u[..., 1]) ** 2
    return math.sqrt(np.mean(div**2) / np.mean(grad))


def divergence_ratio_3d(flow: Flow3D) -> float:
    u = flow.velocity.astype(np.float64)
    h = [flow.extent_m[c] / u.shape[2 - c] for c in range(3)]

    def d(f, c):  # derivative along x (c=0, array axis 2), y (axis 1), z (axis 0)
        return (np.roll(f, -1, axis=2 - c) - np.roll(f, 1, axis=2 - c)) / (2 * h[c])

    div = sum(d(u[..., c], c) for c in range(3))
    grad = sum(d(u[..., a], c) ** 2 for a in range(3) for c in range(3))
    return math.sqrt(np.mean(div**2) / np.mean(grad))


def test_curl_noise_is_divergence_free_to_discretisation_error():
    """The analytic curl has zero divergence; central differences on the grid leave an O(h^2) truncation error:
    under 5 % of the velocity gradient at the default-like resolution, and ~4x smaller at twice the resolution."""
    coarse2 = divergence_ratio_2d(Flow2D.procedural(EXTENT, scale_m=500.0, resolution=(32, 32), seed=4))
    fine2 = divergence_ratio_2d(Flow2D.procedural(EXTENT, scale_m=500.0, resolution=(64, 64), seed=4))
    box = (1000.0, 500.0, 1000.0)
    coarse3 = divergence_ratio_3d(Flow3D.procedural(box, scale_m=500.0, resolution=(32, 16, 32), seed=4))
    fine3 = divergence_ratio_3d(Flow3D.procedural(box, scale_m=500.0, resolution=(64, 32, 64), seed=4))
    print(f"\nrms(div)/rms(|grad u|): 2D {coarse2:.4f} (32^2) -> {fine2:.4f} (64^2); "
          f"3D {coarse3:.4f} (32x16x32) -> {fine3:.4f} (64x32x64)")
    assert coarse2 < 0.05 and coarse3 < 0.05
    assert fine2 < coarse2 / 3.0 and fine3 < coarse3 / 3.0


def test_flow_from_npy_matches_the_procedural_field(tmp_path, device):
    flow = curl_flow()
    path = tmp_path / "velocity.npy"
    np.save(path, flow.velocity)
    loaded = Flow2D.from_npy(path, EXTENT, wind_m_s=flow.wind_m_s)
    tex = texture()
    a = AdvectedTexture(tex, EXTENT, flow, period_s=PERIOD_S, device=device).at(37.0).numpy().copy()
    b = AdvectedTexture(tex, EXTENT, loaded, period_s=PERIOD_S, device=device).at(37.0).numpy()
    np.testing.assert_array_equal(a, b)
    np.save(path, np.zeros((8, 8, 3), np.float32))
    with pytest.raises(SceneError, match=r"\(ny, nx, 2\)"):
        Flow2D.from_npy(path, EXTENT)


def test_invalid_parameters_are_named():
    tex = texture()
    with pytest.raises(ValueError, match="layers"):
        AdvectedTexture(tex, EXTENT, curl_flow(), layers=2, period_s=10.0)
    with pytest.raises(ValueError, match="differs from the flow"):
        AdvectedTexture(tex, (500.0, 1000.0), curl_flow(), period_s=10.0)
    with pytest.raises(ValueError, match="smallest eddy"):
        Flow2D.procedural(EXTENT, scale_m=100.0, octaves=3, resolution=(32, 32))
    with pytest.raises(ValueError, match="step_s"):
        AdvectedTexture(tex, EXTENT, curl_flow(), period_s=10.0, step_s=0.0)


# --- stiff and extreme cases -------------------------------------------------------------------------------------


def test_cfl_50_per_step_stays_stable(device):
    """A flow moving 50 coordinate cells per internal step: finite, bounded, mean and std within 10 %."""
    base = curl_flow(speed=1.0, wind=(0.0, 0.0))
    cell = EXTENT[0] / base.velocity.shape[1]
    step = 10.0
    vmax = np.sqrt(np.sum(base.velocity.astype(np.float64) ** 2, axis=-1)).max()
    flow = Flow2D(EXTENT, (base.velocity * (50.0 * cell / step / vmax)).astype(np.float32))
    tex = texture()
    layer = AdvectedTexture(tex, EXTENT, flow, period_s=PERIOD_S, step_s=step, device=device)
    out = frames(layer, np.arange(120) * 1.7)
    assert np.all(np.isfinite(out))
    assert np.abs(out - MEAN).max() < 6.0 * STD
    np.testing.assert_allclose(out.mean(axis=(1, 2)), tex.mean(), rtol=0.1)
    np.testing.assert_allclose(out.std(axis=(1, 2)), tex.std(), rtol=0.1)


def test_one_frame_per_hour_and_negative_time_codes(device):
    """Frames an hour apart (period 2 min): sequential playback equals cold frames, from negative times on, and
    the statistics hold. Negative times use floor: a time and the same time plus whole periods agree exactly when
    the wind is zero."""
    tex = texture()
    flow = curl_flow()
    sequential = AdvectedTexture(tex, EXTENT, flow, period_s=120.0, step_s=4.0, device=device)
    cold = AdvectedTexture(tex, EXTENT, flow, period_s=120.0, step_s=4.0, device=device)
    for f in range(-6, 18):
        got = sequential.at(f * 3600.0).numpy().copy()
        cold.reset()
        np.testing.assert_array_equal(cold.at(f * 3600.0).numpy(), got)
        assert abs(got.mean() / tex.mean() - 1.0) < 0.05 and abs(got.std() / tex.std() - 1.0) < 0.05
    calm = AdvectedTexture(tex, EXTENT, curl_flow(wind=(0.0, 0.0)), period_s=64.0, step_s=1.0, device=device)
    before = calm.at(-37.25).numpy().copy()
    np.testing.assert_array_equal(calm.at(-37.25 + 3 * 64.0).numpy(), before)
    assert not np.array_equal(calm.at(-37.25 + 32.0).numpy(), before)


@pytest.mark.slow
def test_texture_4096(device):
    """A 4096^2 texture (64 km layer, 15.6 m texels) in one call: finite, mean and std within 5 %."""
    n = 4096
    extent = (64000.0, 64000.0)
    tex = (MEAN + STD * periodic_noise((n, n), smoothing_texels=2.0, seed=2)).astype(np.float32)
    flow = Flow2D.procedural(extent, speed_m_s=5.0, scale_m=16000.0, resolution=(64, 64), seed=3, wind_m_s=(8, 2))
    out = AdvectedTexture(tex, extent, flow, period_s=1000.0, step_s=25.0, device=device).at(777.0).numpy()
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out.mean(), tex.mean(), rtol=0.05)
    np.testing.assert_allclose(out.std(), tex.std(), rtol=0.05)


def test_autocorrelation_of_a_constant_texture_is_one():
    np.testing.assert_array_equal(autocorrelation(np.full((8, 8), 3.0)), np.ones((8, 8), np.float32))


# --- 3D detail inside a kernel -----------------------------------------------------------------------------------


@wp.kernel
def modulate_kernel(state: DetailState, coarse: wp.array3d(dtype=float), start: wp.vec3, spacing: wp.vec3,
                    amplitude: float, out: wp.array3d(dtype=float)):
    """A density sampler's view: coarse density at each node, modulated by the advected detail there."""
    l, j, i = wp.tid()
    p = start + wp.cw_mul(wp.vec3(float(i), float(j), float(l)), spacing)
    out[l, j, i] = modulated_density(state, coarse[l, j, i], p, amplitude)


BOX = (1000.0, 500.0, 1000.0)  # [m]
BOX_MIN = np.array([-500.0, 1500.0, -800.0])  # [m]


def detail(device, *, speed=4.0, wind=(5.0, 0.0, 2.0)) -> AdvectedDetail:
    tex = (MEAN + STD * periodic_noise((16, 32, 32), smoothing_texels=2.0, seed=5)).astype(np.float32)
    flow = Flow3D.procedural(BOX, speed_m_s=speed, scale_m=500.0, resolution=(16, 8, 16), seed=6, wind_m_s=wind)
    return AdvectedDetail(tex, BOX_MIN, flow, period_s=80.0, step_s=2.0, device=device)


def test_detail_modulates_a_coarse_density_inside_a_kernel(device):
    """``modulated_density`` in a user kernel: amplitude 0 returns the coarse density; amplitude 0.3 scales it by
    1 + 0.3 z with z of zero mean and unit std; the detail keeps its statistics over time; a far-away frame origin
    (100 km) gives the same values to float32 precision; a still flow shows the texture."""
    field = detail(device)
    shape = (16, 32, 32)  # the texture's own nodes
    spacing = np.asarray(BOX) / np.array(shape[::-1])
    coarse_np = np.random.default_rng(0).uniform(0.5, 2.0, shape).astype(np.float32)
    coarse = wp.array(coarse_np, dtype=float, device=device)
    out = wp.zeros(shape, dtype=float, device=device)
    state = field.state(30.0)

    def run(state, start, amplitude):
        wp.launch(modulate_kernel, dim=shape, inputs=[state, coarse, wp.vec3(*start), wp.vec3(*spacing.tolist()),
                                                      amplitude, out], device=device)
        return out.numpy().copy()

    np.testing.assert_array_equal(run(state, BOX_MIN.tolist(), 0.0), coarse_np)
    modulated = run(state, BOX_MIN.tolist(), 0.3)
    z = (modulated / coarse_np - 1.0) / 0.3
    assert abs(z.mean()) < 0.1 and abs(z.std() - 1.0) < 0.05
    far = np.array([1.0e5, 0.0, -1.0e5])
    shifted = run(field.state(30.0, frame_origin_m=far), (BOX_MIN - far).tolist(), 0.3)
    np.testing.assert_allclose(shifted, modulated, atol=1e-4 * np.abs(modulated).max())
    for t in (-50.0, 0.0, 45.0, 200.0):
        values = field.sample_grid(t, shape).numpy()
        assert abs(values.mean() / MEAN - 1.0) < 0.05 and abs(values.std() / STD - 1.0) < 0.05
    still = detail(device, speed=0.0, wind=(0.0, 0.0, 0.0))
    tex = still.texture_shape
    np.testing.assert_allclose(still.sample_grid(-17.0, tex).numpy(), still._texture.numpy(), rtol=0, atol=1e-5)


def test_detail_random_access(device):
    """3D: frame 97 cold equals frame 97 after sequential steps (bit-identical)."""
    sequential = detail(device)
    for f in range(97):
        sequential.state(f * 0.8)
    played = sequential.sample_grid(97 * 0.8, (16, 32, 32)).numpy().copy()
    np.testing.assert_array_equal(detail(device).sample_grid(97 * 0.8, (16, 32, 32)).numpy(), played)
