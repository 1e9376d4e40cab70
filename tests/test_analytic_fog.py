"""Analytic fog (Biri et al. 2002): closed-form optical depths against numerical quadrature of the density, the
pass's single scattering against a nested quadrature, wind, extremes, and the USD reader."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from scipy.integrate import quad

from warpsky.core.errors import SceneError
from warpsky.media.fog import FogSet, fog_density, fog_optical_depth, fog_struct
from warpsky.model.fog import (
    AnalyticFog,
    BlobTerm,
    ConstantTerm,
    CosineTerm,
    PolynomialTerm,
    read_analytic_fog,
)
from warpsky.model.scene import Camera, Scene, Sun
from warpsky.passes.fog.fog import Fog, fog_sun_transmittance
from warpsky.passes.fog.fog_kernels import FogMarch, fog_ray

CAMERA = np.array([3.0, 10.0, -7.0])


# ------------------------------------------------------------------------------------------- device helpers
@wp.kernel
def _depth_kernel(fogs: FogSet, a: wp.array(dtype=wp.vec3d), b: wp.array(dtype=wp.vec3d),
                  depth: wp.array(dtype=wp.float64), density: wp.array(dtype=wp.float64)):
    i = wp.tid()
    depth[i] = fog_optical_depth(fogs, 0, a[i], b[i])
    density[i] = fog_density(fogs, 0, a[i])


@wp.kernel
def _ray_kernel(fogs: FogSet, march: FogMarch, o: wp.vec3d, w: wp.vec3d, t0: wp.float64, t1: wp.float64,
                out: wp.array(dtype=wp.float64)):
    ray = fog_ray(fogs, march, o, w, t0, t1)
    for c in range(3):
        out[c] = ray.radiance[c]
        out[3 + c] = ray.transmittance[c]
    out[6] = ray.distance


def device_depths(fog, a, b, device, *, time_s=0.0, camera=CAMERA):
    """(optical depth a -> b, density at a) of ``fog`` from the kernel, float64, world points."""
    fogs = fog_struct(fog, camera, time_s, device)
    a_dev = wp.array(np.asarray(a, np.float64) - camera, dtype=wp.vec3d, device=device)
    b_dev = wp.array(np.asarray(b, np.float64) - camera, dtype=wp.vec3d, device=device)
    depth = wp.zeros(len(a), dtype=wp.float64, device=device)
    density = wp.zeros(len(a), dtype=wp.float64, device=device)
    wp.launch(_depth_kernel, dim=len(a), inputs=[fogs, a_dev, b_dev, depth, density], device=device)
    return depth.numpy(), density.numpy()


#: Quadrature settings that hold 1e-5 on the rays below (the pass's defaults trade that for speed).
EXACT = {"nodes": 8, "min_pieces": 16, "max_pieces": 256}


def device_ray(fogs, scene, origin, direction, t0, t1, device, ambient=None, **pass_kwargs):
    """(radiance, transmittance, mean distance) of one eye-relative ray through ``fog_ray``, float64."""
    march = Fog(device=device, **{**EXACT, **pass_kwargs}).march(scene)
    if ambient is not None:
        march.ambient = wp.vec3d(*np.asarray(ambient, np.float64).tolist())
    fog_set = fog_struct(fogs, scene.camera.position, scene.time_s, device)
    out = wp.zeros(7, dtype=wp.float64, device=device)
    wp.launch(_ray_kernel, dim=1, device=device, inputs=[
        fog_set, march, wp.vec3d(*np.asarray(origin, np.float64).tolist()),
        wp.vec3d(*np.asarray(direction, np.float64).tolist()), wp.float64(t0), wp.float64(t1), out])
    values = out.numpy()
    return values[:3], values[3:6], values[6]


# --------------------------------------------------------------------------------- numerical references
GL_X, GL_W = (0.5 * (v + 1.0) if i == 0 else 0.5 * v for i, v in enumerate(np.polynomial.legendre.leggauss(20)))


def composite(f, breaks) -> float:
    """Gauss-Legendre (20 nodes) on each interval between consecutive ``breaks``; f takes an array of s."""
    breaks = np.asarray(breaks, dtype=np.float64)
    lo, hi = breaks[:-1], breaks[1:]
    s = lo[:, None] + (hi - lo)[:, None] * GL_X[None, :]
    return float(np.sum(f(s.reshape(-1)).reshape(s.shape) * GL_W[None, :] * (hi - lo)[:, None]))


def slab_range(fog, a, d, time_s=0.0):
    y0 = a[1] - fog.wind[1] * time_s
    if d[1] == 0.0:
        return (0.0, 1.0) if fog.floor <= y0 <= fog.top else (1.0, 0.0)
    s = sorted([(fog.floor - y0) / d[1], (fog.top - y0) / d[1]])
    return max(0.0, s[0]), min(1.0, s[1])


def term_reference(term, a, d, s0, s1) -> float:
    """Integral of one term's density over s in [s0, s1] of x = a + s d (metres of path), numerically."""
    length = float(np.linalg.norm(d))
    def f(s):
        return term.density(a + np.multiply.outer(s, d))
    if s1 <= s0 or length == 0.0:
        return 0.0
    if isinstance(term, (ConstantTerm, CosineTerm)):
        feature = 2.0 * math.pi / max(np.linalg.norm(term.wave_vector), 1e-300) if isinstance(term, CosineTerm) \
            else length
        count = int(math.ceil(length * (s1 - s0) / (0.5 * feature))) + 1
        return length * composite(f, np.linspace(s0, s1, count + 1))
    if isinstance(term, PolynomialTerm):  # exact per piece: GL 20 integrates degree <= 39
        u0, du = float((a - term.origin) @ term.axis), float(d @ term.axis)
        lo, hi = term.interval
        levels = [lo, hi]
        if term.repeat and du != 0.0:
            u_min, u_max = sorted([u0 + s0 * du, u0 + s1 * du])
            period = hi - lo
            levels = lo + period * np.arange(math.ceil((u_min - lo) / period), math.floor((u_max - lo) / period) + 1)
        cuts = [(level - u0) / du for level in levels] if du != 0.0 else []
        breaks = np.unique(np.clip(np.concatenate([[s0, s1], cuts]), s0, s1))
        return length * composite(f, breaks)
    offset, dd = a - term.centre, d
    if term.is_line:
        offset = offset - (offset @ term.direction) * term.direction
        dd = d - (d @ term.direction) * term.direction
    centre = -float(offset @ dd) / float(dd @ dd) if dd @ dd > 0.0 else s0
    width = term.radius / (length * max(float(np.linalg.norm(dd)) / length, 1e-12))
    points = sorted({float(np.clip(centre + k * width, s0, s1)) for k in (-100, -10, -1, 0, 1, 10, 100)} | {s0, s1})
    total = 0.0
    for lo, hi in zip(points[:-1], points[1:], strict=True):
        if hi > lo:
            total += quad(lambda s: float(f(np.array([s]))[0]), lo, hi, epsabs=0.0, epsrel=1e-13, limit=400)[0]
    return length * total


def reference_depth(fog, a, b, time_s=0.0) -> float:
    """Numerical integral of D along the world segment a -> b at time ``time_s``, term by term, in the slab."""
    shift = fog.wind * time_s
    a0, d = np.asarray(a, np.float64) - shift, np.asarray(b, np.float64) - np.asarray(a, np.float64)
    s0, s1 = slab_range(fog, np.asarray(a, np.float64), d, time_s)
    return sum(term_reference(t, a0, d, s0, s1) for t in fog.terms)


# ------------------------------------------------------------------------------------------------ fogs
def family(name: str) -> AnalyticFog:
    terms = {
        "constant": [ConstantTerm(0.03)],
        "cosine": [ConstantTerm(0.05), CosineTerm(0.02, [0.3, 0.1, -0.2], 0.4), CosineTerm(-0.015, [0, 0.5, 0.05])],
        "polynomial": [PolynomialTerm((0.006, -0.004, 0.001), [1.0, 0.5, 0.2], [2.0, 0.0, -1.0], (-40.0, 60.0))],
        "repeated": [PolynomialTerm((0.004, 0.001, -0.0001), [0.3, 1.0, 0.0], [0.0, 1.0, 0.0], (0.0, 8.0), True)],
        "point_blob": [BlobTerm([5.0, 30.0, -10.0], 0.2, 6.0), BlobTerm([-20.0, 10.0, 25.0], 0.05, 15.0)],
        "line_blob": [BlobTerm([0.0, 20.0, 0.0], 0.1, 3.0, [1.0, 0.2, 0.5])],
    }
    if name == "combination":
        return AnalyticFog("combination", [t for ts in terms.values() for t in ts], floor=0.0, top=60.0)
    return AnalyticFog(name, terms[name], floor=0.0, top=60.0)


FAMILIES = ("constant", "cosine", "polynomial", "repeated", "point_blob", "line_blob", "combination")


def sample_rays(fog, rng):
    """~50 random rays through and around the slab, and the stiff ones."""
    a = rng.uniform([-80, -20, -80], [80, 80, 80], (44, 3))
    b = rng.uniform([-80, -20, -80], [80, 80, 80], (44, 3))
    special = [([1.0, 20.0, 2.0], [1.0, 20.0, 2.0])]  # zero length (index 44)
    for term in fog.of_type(CosineTerm)[:1]:  # along the level sets of the first cosine: k . d = 0
        d = np.cross(term.wave_vector, [0.3, 0.7, -0.2])
        special.append(([-5.0, 25.0, 4.0], np.array([-5.0, 25.0, 4.0]) + 90.0 * d / np.linalg.norm(d)))
    special += [
        ([0.0, 30.0, 0.0], [1e6 * 0.6, 30.0, 1e6 * 0.8]),  # 1e6 m inside the slab
        ([0.0, 59.0, 0.0], [6e5, 61.0, -8e5]),  # 1e6 m, grazing out through the top
        ([-50.0, 60.0, 3.0], [70.0, 60.0, -9.0]),  # along the top face
        ([-50.0, 70.0, 3.0], [40.0, -10.0, 9.0]),  # through the whole slab
    ]
    special_a, special_b = (np.array([np.asarray(p, np.float64) for p in ends]) for ends in zip(*special, strict=True))
    return np.vstack([a, special_a]), np.vstack([b, special_b])


@pytest.mark.parametrize("name", FAMILIES)
def test_optical_depth_matches_quadrature(name, device):
    """Closed-form integrals of each family equal term-by-term quadrature of the density to relative 1e-5."""
    fog = family(name)
    a, b = sample_rays(fog, np.random.default_rng(7))
    depth, density = device_depths(fog, a, b, device)
    reference = np.array([reference_depth(fog, a[i], b[i]) for i in range(len(a))])
    assert depth[44] == 0.0 and reference[44] == 0.0  # zero length
    np.testing.assert_allclose(depth, reference, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(density, fog.density(a), rtol=1e-12, atol=1e-15)
    assert np.all(depth >= 0.0) and np.count_nonzero(depth) > 25


# ----------------------------------------------------------------------------- single scattering of a ray
def hg(cos_theta, g):
    return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def nested_reference(fog, origin, w, t0, t1, sun_dir, irradiance, ambient, levels):
    """Radiance, transmittance and mean distance of the world ray origin + t w by nested quadrature: outer
    Gauss-Legendre on <= 1 m pieces split at the density's discontinuities (``levels``: heights where it jumps),
    the view transmittance by quadrature from the piece start, the sun's by quadrature along y up to the top."""
    ext, sca = fog.extinction_scale, fog.extinction_scale * fog.albedo
    cuts = [(y - origin[1]) / w[1] for y in [fog.floor, fog.top, *levels]] if w[1] != 0.0 else []
    breaks = np.unique(np.clip([t0, t1, *cuts], t0, t1))
    breaks = np.unique(np.concatenate([np.linspace(lo, hi, int(math.ceil(hi - lo)) + 1)
                                       for lo, hi in zip(breaks[:-1], breaks[1:], strict=True)]))
    def density(t):
        return fog.density(origin + np.multiply.outer(t, w))
    radiance, sky_weight, distance, opacity, tau = np.zeros(3), 0.0, 0.0, 0.0, 0.0
    for lo, hi in zip(breaks[:-1], breaks[1:], strict=True):
        nodes, weights = lo + (hi - lo) * GL_X, (hi - lo) * GL_W
        partial = np.array([composite(density, [lo, s]) for s in nodes])
        view = np.exp(-np.multiply.outer(tau + partial, ext))
        d = density(nodes)
        for j, s in enumerate(nodes):
            x = origin + s * w
            y_breaks = np.unique(np.concatenate([[x[1], fog.top], [v for v in levels if x[1] < v < fog.top]]))
            pieces = np.unique(np.concatenate([np.linspace(a, b, int(math.ceil(b - a)) + 1)
                                               for a, b in zip(y_breaks[:-1], y_breaks[1:], strict=True)]))
            column = composite(lambda y, x=x: fog.density(x + np.multiply.outer((y - x[1]) / sun_dir[1], sun_dir)),
                               pieces) / sun_dir[1]
            lit = np.exp(-column * ext)
            radiance += weights[j] * d[j] * hg(w @ sun_dir, fog.g) * sca * view[j] * lit * irradiance
        seen = weights[:, None] * d[:, None] * ext * view
        lum = seen @ np.array([0.2126, 0.7152, 0.0722])
        opacity += lum.sum()
        distance += (lum * nodes).sum()
        sky_weight += weights @ d
        tau += composite(density, [lo, hi])
    transmittance = np.exp(-tau * ext)
    radiance = radiance + fog.albedo * ambient * (1.0 - transmittance)
    return radiance, transmittance, distance / opacity


def pixel_fog() -> AnalyticFog:
    return AnalyticFog("pixel", [
        ConstantTerm(0.01), CosineTerm(0.008, [0.2, 0.15, -0.25], 0.7),
        PolynomialTerm((0.002, 0.0004, -0.8e-5), [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], (5.0, 45.0)),
        BlobTerm([20.0, 12.0, -60.0], 0.08, 6.0), BlobTerm([0.0, 8.0, -40.0], 0.05, 4.0, [1.0, 0.1, 0.3])],
        floor=0.0, top=60.0, extinction_scale=[1.0, 1.3, 1.7], albedo=[0.95, 0.9, 0.8], g=0.6)


def test_single_scatter_matches_nested_quadrature(device):
    """One ray's sunlight, skylight, transmittance and depth from the kernel's float64 ``fog_ray`` against a
    nested numerical quadrature, camera inside the fog: radiance to relative 1e-5, transmittance to 1e-10."""
    fog = pixel_fog()
    sun_dir = np.array([0.4, 0.6, -0.5]) / np.linalg.norm([0.4, 0.6, -0.5])
    irradiance, ambient = np.array([1.0, 0.9, 0.8]), np.array([0.2, 0.3, 0.5])
    camera = Camera("cam", CAMERA, np.eye(3), 35.0, 36.0, 36.0)
    scene = Scene(camera, Sun(sun_dir, irradiance), fogs=(fog,))
    w = np.array([0.15, -0.03, -1.0]) / np.linalg.norm([0.15, -0.03, -1.0])
    t0, t1 = 0.1, 80.0
    radiance, transmittance, distance = device_ray(fog, scene, np.zeros(3), w, t0, t1, device, ambient=ambient)
    ref_radiance, ref_transmittance, ref_distance = nested_reference(fog, CAMERA, w, t0, t1, sun_dir, irradiance,
                                                                     ambient, levels=(5.0, 45.0))
    assert 0.02 < ref_transmittance[0] < 0.5  # the test sees a substantial, not saturated, fog
    np.testing.assert_allclose(transmittance, ref_transmittance, rtol=1e-10)
    np.testing.assert_allclose(radiance, ref_radiance, rtol=1e-5)
    np.testing.assert_allclose(distance, ref_distance, rtol=1e-5)
    sunlit, _, _ = device_ray(fog, scene, np.zeros(3), w, t0, t1, device, ambient=np.zeros(3))  # the sun alone
    ref_sunlit = nested_reference(fog, CAMERA, w, t0, t1, sun_dir, irradiance, np.zeros(3), levels=(5.0, 45.0))[0]
    assert ref_sunlit.min() > 0.005
    np.testing.assert_allclose(sunlit, ref_sunlit, rtol=1e-5)


def test_fogs_add(device):
    """Two fogs: their optical depths add (T = T1 T2), and two halves of one fog render as that fog."""
    whole = pixel_fog()
    half_a = AnalyticFog("a", whole.terms[:2], floor=0.0, top=60.0, extinction_scale=whole.extinction_scale,
                         albedo=whole.albedo, g=whole.g)
    half_b = AnalyticFog("b", whole.terms[2:], floor=0.0, top=60.0, extinction_scale=whole.extinction_scale,
                         albedo=whole.albedo, g=whole.g)
    sun_dir = np.array([-0.3, 0.5, 0.2]) / np.linalg.norm([-0.3, 0.5, 0.2])
    scene = Scene(Camera("cam", CAMERA, np.eye(3), 35.0, 36.0, 36.0), Sun(sun_dir, np.ones(3)))
    w = np.array([0.1, 0.05, -1.0]) / np.linalg.norm([0.1, 0.05, -1.0])
    ambient = np.array([0.1, 0.2, 0.3])
    both = device_ray([half_a, half_b], scene, np.zeros(3), w, 0.1, 90.0, device, ambient=ambient)
    one = device_ray([whole], scene, np.zeros(3), w, 0.1, 90.0, device, ambient=ambient)
    t_a = device_ray([half_a], scene, np.zeros(3), w, 0.1, 90.0, device)[1]
    t_b = device_ray([half_b], scene, np.zeros(3), w, 0.1, 90.0, device)[1]
    np.testing.assert_allclose(both[1], t_a * t_b, rtol=1e-12)
    np.testing.assert_allclose(both[0], one[0], rtol=1e-6)
    np.testing.assert_allclose(both[1], one[1], rtol=1e-12)


# ---------------------------------------------------------------------------------------------------- wind
def test_wind_translates_the_fog(device):
    """The fog at time t is the fog at 0 moved by wind t: densities and integrals, and the rendered image equals
    the one at time 0 seen from a camera moved by -wind t."""
    base = family("combination")
    wind = np.array([3.0, 0.5, -2.0])
    fog = AnalyticFog("windy", base.terms, floor=base.floor, top=base.top, wind=wind)
    t = 37.5
    a, b = sample_rays(fog, np.random.default_rng(3))
    a, b = a[:40], b[:40]
    depth_t, density_t = device_depths(fog, a, b, device, time_s=t)
    depth_0, density_0 = device_depths(fog, a - wind * t, b - wind * t, device, time_s=0.0)
    np.testing.assert_allclose(depth_t, depth_0, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(density_t, density_0, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(density_t, fog.density(a, t), rtol=1e-12, atol=1e-15)
    reference = [reference_depth(fog, a[i], b[i], t) for i in range(0, 40, 4)]
    np.testing.assert_allclose(depth_t[::4], reference, rtol=1e-5, atol=1e-12)
    assert not np.allclose(depth_t, device_depths(fog, a, b, device)[0])  # the wind did move it
    sun = Sun(np.array([0.3, 0.8, 0.1]) / np.linalg.norm([0.3, 0.8, 0.1]), np.ones(3))
    camera = Camera("cam", np.array([0.0, 30.0, 80.0]), np.eye(3), 20.0, 36.0, 36.0)
    moved = Camera("cam", camera.position - wind * t, np.eye(3), 20.0, 36.0, 36.0)
    later = Fog(device=device, **EXACT).render(Scene(camera, sun, fogs=(fog,), time_code=t * 24.0), 12, 12)
    still = Fog(device=device, **EXACT).render(Scene(moved, sun, fogs=(fog,)), 12, 12)
    np.testing.assert_allclose(later.radiance, still.radiance, rtol=1e-5)
    np.testing.assert_allclose(later.transmittance, still.transmittance, rtol=1e-5)


# -------------------------------------------------------------------------------------------- the pass
def homogeneous_radiance(sigma, fog, sun, ambient, origin, directions, t0, t1):
    """Closed form for a constant fog (extinction sigma x scale) seen from inside its slab: per ray, with
    T_view = exp(-s (t - t0)) and T_sun = exp(-s (top - y(t)) / mu) the sunlight integral is an exponential
    in t; the sky adds a L (1 - T)."""
    s = sigma * fog.extinction_scale  # (3,)
    w = directions.reshape(-1, 3)
    t1 = np.broadcast_to(np.asarray(t1, np.float64), w.shape[:1]).copy()
    t0 = np.broadcast_to(np.asarray(t0, np.float64), w.shape[:1])
    with np.errstate(divide="ignore"):
        exit_t = np.where(w[:, 1] > 0, (fog.top - origin[1]) / w[:, 1],
                          np.where(w[:, 1] < 0, (fog.floor - origin[1]) / w[:, 1], np.inf))
    t1 = np.minimum(t1, exit_t)
    span = np.maximum(t1 - t0, 0.0)[:, None]
    transmittance = np.exp(-s * span)
    radiance = fog.albedo * ambient * -np.expm1(-s * span)
    mu = sun.direction[1]
    if sun is not None and mu > 0:
        y0 = origin[1] + t0[:, None] * w[:, 1:2]
        kappa = s * (1.0 - w[:, 1:2] / mu)
        with np.errstate(divide="ignore", invalid="ignore"):
            integral = np.where(np.abs(kappa * span) > 1e-12, -np.expm1(-kappa * span) / kappa, span)
        phase = hg(w @ sun.direction, fog.g)[:, None]
        radiance = radiance + s * fog.albedo * sun.irradiance * phase * np.exp(-s * (fog.top - y0) / mu) * integral
    return radiance.reshape(directions.shape), transmittance.reshape(directions.shape)


def fog_camera(position=(0.0, 20.0, 0.0), far=1.0e6):
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, 0.96, 0.28], [0.0, -0.28, 0.96]])  # looking a little down
    return Camera("cam", np.array(position), rotation, 18.0, 36.0, 36.0, far=far)


@pytest.mark.parametrize("sigma,albedo", [(0.01, 0.9), (0.05, 1.0), (1.0, 1.0)])
def test_homogeneous_fog_matches_closed_form(sigma, albedo, device):
    """A constant fog around the camera (1 /m: T ~ 0, albedo exactly 1): the image equals the closed form, and
    stays finite, non-negative and below the single-scattering bound a (E p + L_ambient)."""
    from warpsky.light.background import pixel_directions
    from warpsky.model.lights import Dome

    fog = AnalyticFog("c", [ConstantTerm(sigma)], floor=-200.0, top=100.0, extinction_scale=[0.8, 1.0, 1.3],
                      albedo=[albedo, albedo * 0.9, albedo * 0.8], g=0.7)
    sun = Sun(np.array([0.2, 0.7, -0.6]) / np.linalg.norm([0.2, 0.7, -0.6]), np.array([1.0, 0.95, 0.9]))
    ambient = np.array([0.1, 0.15, 0.3])
    camera = fog_camera()
    scene = Scene(camera, sun, fogs=(fog,), dome=Dome(ambient))
    layer = Fog(device=device, **EXACT).render(scene, 16, 16)
    w = pixel_directions(camera, 16, 16)
    cos_axis = w @ camera.forward
    radiance, transmittance = homogeneous_radiance(sigma, fog, sun, ambient, camera.position, w,
                                                   (camera.near / cos_axis).reshape(-1), 1e6 / cos_axis.reshape(-1))
    assert np.all(np.isfinite(layer.radiance)) and np.all(layer.radiance >= 0.0)
    # optical depths: the float32 ray direction (1e-7) moves a depth of 50 by 5e-6, so T by that relatively
    shown = transmittance > 1e-36
    np.testing.assert_allclose(-np.log(layer.transmittance[shown]), -np.log(transmittance[shown]), rtol=1e-6)
    np.testing.assert_allclose(layer.radiance, radiance, rtol=2e-5)
    bound = fog.albedo * (sun.irradiance * hg(1.0, fog.g) + ambient)
    assert np.all(layer.radiance <= bound)
    if sigma == 1.0:
        assert layer.transmittance.max() < 1e-30


def test_limit_cuts_the_fog_at_the_surface_depth(device):
    """With ``limit`` depths d the fog is integrated to d (ray distance d / cos): the closed form to that point."""
    from warpsky.light.background import pixel_directions

    fog = AnalyticFog("c", [ConstantTerm(0.03)], floor=-200.0, top=100.0, extinction_scale=[0.8, 1.0, 1.3], g=0.5)
    sun = Sun(np.array([0.2, 0.7, -0.6]) / np.linalg.norm([0.2, 0.7, -0.6]), np.ones(3))
    camera = fog_camera()
    limit = np.random.default_rng(5).uniform(5.0, 80.0, (12, 12)).astype(np.float32)
    layer = Fog(device=device, **EXACT).render(Scene(camera, sun, fogs=(fog,)), 12, 12, limit=limit)
    w = pixel_directions(camera, 12, 12)
    cos_axis = (w @ camera.forward).reshape(-1)
    radiance, transmittance = homogeneous_radiance(0.03, fog, sun, np.zeros(3), camera.position, w,
                                                   camera.near / cos_axis, limit.reshape(-1) / cos_axis)
    np.testing.assert_allclose(layer.transmittance, transmittance, rtol=1e-5)
    np.testing.assert_allclose(layer.radiance, radiance, rtol=2e-5)
    # depth: the mean of t weighted by the luminance of sigma T, int_0^D u s e^{-s u} du = (1 - e)/s - D e
    sigma = 0.03 * fog.extinction_scale
    t0, span = camera.near / cos_axis, ((limit.reshape(-1) - camera.near) / cos_axis)[:, None]
    e = np.exp(-sigma * span)
    lum = np.array([0.2126, 0.7152, 0.0722])
    mean = t0 + (((1.0 - e) / sigma - span * e) @ lum) / ((1.0 - e) @ lum)
    np.testing.assert_allclose(layer.depth.reshape(-1), mean * cos_axis, rtol=1e-5)


def test_empty_and_zero_fog(device):
    """Density 0: transmittance exactly 1, radiance exactly 0, depth at the far plane; no fog at all likewise."""
    from warpsky.model.lights import Dome

    sun = Sun(np.array([0.0, 1.0, 0.0]), np.ones(3))
    camera = fog_camera(far=5000.0)
    for fogs in [(AnalyticFog("zero", [ConstantTerm(0.0)], floor=-100.0, top=100.0),), ()]:
        layer = Fog(device=device, **EXACT).render(Scene(camera, sun, fogs=fogs, dome=Dome(np.ones(3))), 8, 8)
        assert np.all(layer.transmittance == 1.0) and np.all(layer.radiance == 0.0)
        assert np.all(layer.depth == np.float32(5000.0))


@pytest.mark.parametrize("elevation", [0.0, -0.2])
def test_sun_at_or_below_horizon_gives_sky_light_only(elevation, device):
    """A sun on or under the horizon adds nothing: the radiance is the sky's a L (1 - T) alone."""
    from warpsky.model.lights import Dome

    fog = AnalyticFog("c", [ConstantTerm(0.02), CosineTerm(0.01, [0.0, 0.3, 0.1])], floor=-50.0, top=60.0,
                      albedo=[0.9, 0.8, 0.7])
    direction = np.array([math.cos(elevation), math.sin(elevation), 0.0])
    ambient = np.array([0.3, 0.2, 0.1])
    layer = Fog(device=device, **EXACT).render(Scene(fog_camera(), Sun(direction, np.ones(3)), fogs=(fog,),
                                                dome=Dome(ambient)), 8, 8)
    expected = fog.albedo * ambient * (1.0 - layer.transmittance.astype(np.float64))
    np.testing.assert_allclose(layer.radiance, expected, rtol=1e-5, atol=1e-9)
    assert layer.radiance.max() > 0.01


def translated(fog: AnalyticFog, offset) -> AnalyticFog:
    """``fog`` moved by ``offset`` [m]: D'(x) = D(x - offset)."""
    offset = np.asarray(offset, np.float64)
    terms = []
    for t in fog.terms:
        if isinstance(t, CosineTerm):
            terms.append(CosineTerm(t.amplitude, t.wave_vector, t.phase - float(t.wave_vector @ offset)))
        elif isinstance(t, PolynomialTerm):
            terms.append(PolynomialTerm(t.coefficients, t.axis, t.origin + offset, t.interval, t.repeat))
        elif isinstance(t, BlobTerm):
            terms.append(BlobTerm(t.centre + offset, t.strength, t.radius, t.direction))
        else:
            terms.append(t)
    return AnalyticFog(fog.name, terms, floor=fog.floor + offset[1], top=fog.top + offset[1],
                       extinction_scale=fog.extinction_scale, albedo=fog.albedo, g=fog.g)


def test_far_from_the_origin_renders_the_same(device):
    """The scene moved 100 km away (camera and fog) gives the same image to float32 precision."""
    base = pixel_fog()
    fog = AnalyticFog("far", [*base.terms, *family("repeated").terms], floor=base.floor, top=base.top,
                      extinction_scale=base.extinction_scale, albedo=base.albedo, g=base.g)
    sun = Sun(np.array([0.3, 0.8, 0.1]) / np.linalg.norm([0.3, 0.8, 0.1]), np.ones(3))
    camera = fog_camera((0.0, 30.0, 90.0))
    offset = np.array([1.0e5, 250.0, -1.0e5])
    far_camera = Camera("cam", camera.position + offset, camera.rotation, 18.0, 36.0, 36.0)
    near = Fog(device=device, **EXACT).render(Scene(camera, sun, fogs=(fog,)), 12, 12)
    away = Fog(device=device, **EXACT).render(Scene(far_camera, sun, fogs=(translated(fog, offset),)), 12, 12)
    np.testing.assert_allclose(away.transmittance, near.transmittance, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(away.radiance, near.radiance, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(away.depth, near.depth, rtol=1e-5)
    assert near.transmittance.min() < 0.2 < 0.4 < near.transmittance.max() and near.radiance.min() > 1e-3


def test_sun_transmittance_is_the_closed_form(device):
    """``fog_sun_transmittance``: exp(-c (top - y) / mu) for a constant fog, 1 above the slab."""
    fog = AnalyticFog("c", [ConstantTerm(0.02)], floor=0.0, top=50.0, extinction_scale=[1.0, 2.0, 3.0])
    direction = np.array([0.6, 0.8, 0.0])
    scene = Scene(fog_camera(), Sun(direction, np.ones(3)), fogs=(fog,))
    points = np.array([[0.0, 0.0, 0.0], [1e5, 10.0, -3e4], [5.0, 50.0, 5.0], [0.0, 70.0, 0.0], [0.0, -30.0, 0.0]])
    out = fog_sun_transmittance(scene, points, device)
    column = np.clip(50.0 - np.clip(points[:, 1], 0.0, None), 0.0, None) / 0.8
    np.testing.assert_allclose(out, np.exp(-0.02 * np.outer(column, [1.0, 2.0, 3.0])), rtol=1e-12)


# ------------------------------------------------------------------------------------------------------ USD
def write_fog_stage(path, *, up="Y", mpu=1.0, translate=(100.0, 5.0, -30.0), overrides=None):
    """A stage with one analytic fog prim /World/Fog (an Xform) carrying every attribute; ``overrides`` replaces
    or adds attributes by name ({name: (type name, value)})."""
    from pxr import Gf, Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    xform = UsdGeom.Xform.Define(stage, "/World/Fog")
    xform.AddTranslateOp().Set(Gf.Vec3d(*translate))
    prim = xform.GetPrim()
    prim.CreateAttribute("warpsky:kind", Sdf.ValueTypeNames.Token, custom=True, variability=Sdf.VariabilityUniform) \
        .Set("analyticFog")
    attributes = {
        "constant": ("Float", 0.04),
        "cosine:amplitudes": ("FloatArray", [0.01, -0.02]),
        "cosine:waveVectors": ("Float3Array", [Gf.Vec3f(0.1, 0.0, 0.2), Gf.Vec3f(0.0, 0.3, 0.05)]),
        "cosine:phases": ("FloatArray", [0.5, 1.5]),
        "polynomial:coefficients": ("FloatArray", [0.01, 0.002, 0.0001]),
        "polynomial:axis": ("Float3", Gf.Vec3f(1.0, 0.0, 1.0)),
        "polynomial:interval": ("Float2", Gf.Vec2f(-20.0, 30.0)),
        "polynomial:repeat": ("Bool", True),
        "blob:centers": ("Point3fArray", [Gf.Vec3f(1.0, 2.0, 3.0), Gf.Vec3f(-4.0, 5.0, 6.0)]),
        "blob:strengths": ("FloatArray", [0.2, 0.1]),
        "blob:radii": ("FloatArray", [5.0, 2.0]),
        "blob:directions": ("Float3Array", [Gf.Vec3f(0.0, 0.0, 0.0), Gf.Vec3f(1.0, 0.0, 0.0)]),
        "floor": ("Float", -10.0),
        "top": ("Float", 40.0),
        "extinctionScale": ("Color3f", Gf.Vec3f(1.0, 1.5, 2.0)),
        "albedo": ("Color3f", Gf.Vec3f(0.9, 0.8, 0.7)),
        "g": ("Float", 0.6),
        "wind": ("Vector3f", Gf.Vec3f(2.0, 0.0, -1.0)),
    }
    attributes.update(overrides or {})
    for name, (kind, value) in attributes.items():
        prim.CreateAttribute(f"warpsky:fog:{name}", getattr(Sdf.ValueTypeNames, kind), custom=True).Set(value)
    stage.GetRootLayer().Save()
    return path


def local_fog() -> AnalyticFog:
    """The fog of :func:`write_fog_stage` in its own frame (stage units = metres, no transform)."""
    return AnalyticFog("local", [
        ConstantTerm(0.04), CosineTerm(0.01, [0.1, 0.0, 0.2], 0.5), CosineTerm(-0.02, [0.0, 0.3, 0.05], 1.5),
        PolynomialTerm((0.01, 0.002, 0.0001), [1.0, 0.0, 1.0], [0, 0, 0], (-20.0, 30.0), True),
        BlobTerm([1.0, 2.0, 3.0], 0.2, 5.0), BlobTerm([-4.0, 5.0, 6.0], 0.1, 2.0, [1.0, 0.0, 0.0])],
        floor=-10.0, top=40.0, extinction_scale=[1.0, 1.5, 2.0], albedo=[0.9, 0.8, 0.7], g=0.6, wind=[2, 0, -1])


def read_fog(path):
    from warpsky.usd.stage import StageReader

    reader = StageReader(path)
    return read_analytic_fog(reader, reader.stage.GetPrimAtPath("/World/Fog"), None, 0.0)


@pytest.mark.parametrize("up,mpu", [("Y", 1.0), ("Z", 0.01)])
def test_usd_round_trip(tmp_path, up, mpu):
    """Every attribute read back: the fog from the stage equals the local fog moved by the prim's transform
    (densities at random points), in a Y-up metre stage and a Z-up centimetre one."""
    translate = np.array([100.0, 5.0, -30.0])
    fog = read_fog(write_fog_stage(tmp_path / "fog.usda", up=up, mpu=mpu, translate=translate))
    local = local_fog()
    to_world = np.eye(3) if up == "Y" else np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    origin = mpu * to_world @ translate
    up_local = np.array([0.0, 1.0, 0.0]) if up == "Y" else np.array([0.0, 0.0, 1.0])
    points_local = np.random.default_rng(2).uniform(-60.0, 60.0, (200, 3))
    points_local = points_local - np.outer(points_local @ up_local, up_local) + np.outer(
        np.random.default_rng(3).uniform(-9.0, 39.0, 200), up_local)  # inside the slab along the local up axis
    points_world = (mpu * points_local) @ to_world.T + origin
    terms_local = AnalyticFog("t", local.terms, floor=-1e9, top=1e9)
    expected = terms_local.density(points_local if up == "Y" else points_local)
    np.testing.assert_allclose(fog.density(points_world), expected, rtol=1e-6)
    assert fog.floor == pytest.approx(origin[1] - 10.0 * mpu) and fog.top == pytest.approx(origin[1] + 40.0 * mpu)
    np.testing.assert_allclose(fog.extinction_scale, [1.0, 1.5, 2.0])
    np.testing.assert_allclose(fog.albedo, [0.9, 0.8, 0.7], rtol=1e-6)
    assert fog.g == pytest.approx(0.6)
    np.testing.assert_allclose(fog.wind, to_world @ [2.0, 0.0, -1.0])
    assert fog.name == "/World/Fog"


@pytest.mark.parametrize("overrides,attribute", [
    ({"cosine:phases": ("FloatArray", [0.5, 1.5, 2.5])}, "warpsky:fog:cosine:phases"),
    ({"blob:radii": ("FloatArray", [5.0])}, "warpsky:fog:blob:radii"),
    ({"constant": ("Float", 0.02)}, "warpsky:fog:cosine:amplitudes"),
    ({"polynomial:coefficients": ("FloatArray", [0.01, 0.0, -0.001])}, "warpsky:fog:polynomial:coefficients"),
    ({"blob:strengths": ("FloatArray", [0.2, -0.1])}, "warpsky:fog:blob:strengths"),
    ({"top": ("Float", -20.0)}, "warpsky:fog:top"),
    ({"albedo": ("Color3f", (1.2, 0.5, 0.5))}, "warpsky:fog:albedo"),
    ({"colour": ("Float", 1.0)}, "warpsky:fog:colour"),
])


def test_usd_bad_attributes_name_prim_and_attribute(tmp_path, overrides, attribute):
    """Mismatched array lengths, a fog that can go negative and out-of-range values raise a SceneError naming
    the prim and the attribute."""
    path = write_fog_stage(tmp_path / "bad.usda", overrides=overrides)
    with pytest.raises(SceneError) as error:
        read_fog(path)
    assert "/World/Fog" in str(error.value) and attribute in str(error.value)
