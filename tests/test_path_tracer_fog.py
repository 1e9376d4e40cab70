"""The path tracer's analytic fog (Biri et al. 2002) as a participating medium: free flights against the closed-form
transmittance, the camera ray's transmittance against the fog pass's, a fog slab over a Lambertian ground against
adding-doubling, thin fog's single scattering against the fog pass, dense and cancelling fogs, and the plan."""

from __future__ import annotations

import time

import numpy as np
import pytest
import warp as wp
from scipy.integrate import quad

from warpsky.media.air.medium import Air, air_struct
from warpsky.media.voxels.voxel import VoxelMedia, VoxelMediaBuffers
from warpsky.model.fog import AnalyticFog, BlobTerm, ConstantTerm, CosineTerm, PolynomialTerm
from warpsky.model.scene import Camera, Ground, PhaseKind, Scene, Sun
from warpsky.optics.phase import phase_numpy
from warpsky.passes.fog.fog import Fog
from warpsky.techniques.path_tracer.fog_media import density_bound, fog_tracking
from warpsky.techniques.path_tracer.majorants import Majorants, upload_majorants
from warpsky.techniques.path_tracer.path_tracer import PathTracer, PathTracerSettings
from warpsky.techniques.path_tracer.tracking import delta_track_function

#: The fog pass's quadrature at the accuracy of tests/test_analytic_fog.py (relative 1e-5).
EXACT = {"nodes": 8, "min_pieces": 16, "max_pieces": 256}

fog_flight = delta_track_function(False, True)


@wp.kernel
def _flights(media: VoxelMedia, majorants: Majorants, air: Air, origin: wp.vec3, direction: wp.vec3, t_max: float,
             out: wp.array(dtype=wp.vec3)):
    """One free flight per thread: its weight when it escapes, zero when it scatters."""
    i = wp.tid()
    flight = fog_flight(media, majorants, air, origin, direction, t_max, wp.vec3(1.0), wp.rand_init(7, i), 0)
    out[i] = wp.vec3(0.0)
    if flight.scattered == 0:
        out[i] = flight.weight


def varied_fog(scale=(1.0, 0.6, 0.3), albedo=(0.9, 0.9, 0.9), g=0.6, strength=1.0) -> AnalyticFog:
    """Every family: a constant, two cosines, a polynomial in height, a point and a line blob, in a 20 m slab."""
    s = strength
    terms = [ConstantTerm(0.05 * s), CosineTerm(0.02 * s, [0.2, 0.05, 0.1], 0.3),
             CosineTerm(-0.02 * s, [0.0, 0.3, -0.4]),
             PolynomialTerm((0.02 * s, 0.002 * s, -0.0001 * s), axis=[0.0, 1.0, 0.0], interval=(0.0, 20.0)),
             BlobTerm([10.0, 8.0, -30.0], 0.2 * s, 4.0), BlobTerm([0.0, 12.0, -20.0], 0.1 * s, 2.0, [1.0, 0.0, 0.0])]
    return AnalyticFog("varied", terms, floor=0.0, top=20.0, extinction_scale=np.array(scale),
                       albedo=np.array(albedo), g=g)


def closed_depth(fog: AnalyticFog, origin, direction, length) -> np.ndarray:
    """RGB optical depth by adaptive quadrature of the fog's own numpy density (independent of the kernels)."""
    o, w = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
    breaks = [t for t in ((fog.floor - o[1]) / w[1], (fog.top - o[1]) / w[1]) if 0.0 < t < length]
    value = quad(lambda t: float(fog.density(o + t * w)), 0.0, length, points=breaks or None, limit=400)[0]
    return value * fog.extinction_scale


@pytest.mark.parametrize("direction,length", [((0.3, -0.4, -0.866), 60.0), ((0.6, 0.05, -0.8), 300.0),
                                              ((0.0, 1.0, 0.0), 1.0e30)])
def test_free_flights_escape_with_the_closed_form_transmittance(direction, length, device):
    """Delta tracking through the fog alone (chromatic extinction, every term family): each channel's mean escape
    weight is exp(-tau) of the fog's density integrated by quadrature, |z| < 3.5 over 400,000 flights."""
    fog = varied_fog()
    camera = np.array([2.0, 10.0, 5.0])
    direction = np.asarray(direction) / np.linalg.norm(direction)
    scene = Scene(Camera("cam", camera, np.eye(3), 18.0, 36.0, 36.0), fogs=(fog,))
    with wp.ScopedDevice(device):
        media = VoxelMediaBuffers.upload((), camera, device, ())
        majorants = upload_majorants((), None, device)[0]
        majorants.fog = fog_tracking([fog], camera, 0.0, device)
        out = wp.zeros(400000, dtype=wp.vec3)
        air = air_struct(scene, camera, device, air=False)
        wp.launch(_flights, dim=out.shape[0], inputs=[media.media, majorants, air, wp.vec3(0.0), wp.vec3(*direction),
                                                      float(length), out])
        weights = out.numpy().astype(np.float64)
    reach = min(length, (fog.top - camera[1]) / direction[1] if direction[1] > 0 else length)
    expected = np.exp(-closed_depth(fog, camera, direction, reach))
    z = (weights.mean(axis=0) - expected) / (weights.std(axis=0) / np.sqrt(len(weights)) + 1e-12)
    print(f"\nfree flights along {np.round(direction, 3).tolist()}: T {np.round(expected, 4).tolist()}, "
          f"z {np.round(z, 2).tolist()}")
    assert np.all(np.abs(z) < 3.5), (z, expected)
    assert np.all(weights >= 0.0) and np.all(np.isfinite(weights))


def fog_camera(position=(0.0, 10.0, 0.0), far=2000.0) -> Camera:
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, 0.96, 0.28], [0.0, -0.28, 0.96]])  # looking a little down
    return Camera("cam", np.array(position), rotation, 18.0, 36.0, 36.0, far=far)


def oblique_sun() -> Sun:
    d = np.array([0.3, 0.7, 0.5])
    return Sun(d / np.linalg.norm(d), np.array([1.0, 0.9, 0.8]))


def test_camera_transmittance_is_the_fog_pass_closed_form(device):
    """The transmittance the path tracer reports along camera rays (closed form, no tracking) is the fog pass's to
    1e-6 relative; neither sees noise."""
    fog = varied_fog()
    scene = Scene(fog_camera(), oblique_sun(), fogs=(fog,))
    traced = PathTracer(PathTracerSettings(spp=1), device=device).render(scene, 12, 12)
    marched = Fog(device=device, **EXACT).render(scene, 12, 12, ambient=np.zeros(3))
    assert traced.transmittance.min() < 0.5  # the fog is seen
    np.testing.assert_allclose(traced.transmittance, marched.transmittance, rtol=1e-6, atol=1e-30)


def looking_down(mu: float, position) -> Camera:
    """A camera of a tiny field of view whose ray leaves at cos(angle to the downward vertical) = ``mu``."""
    back = np.array([-np.sqrt(1.0 - mu * mu), mu, 0.0])
    right = np.array([0.0, 0.0, -1.0])
    up = np.cross(back, right)
    return Camera("cam", np.asarray(position, np.float64), np.column_stack([right, up, back]), 1000.0, 1.0, 1.0,
                  far=1.0e4)


#: The cosine to the downward vertical at which the slab's reflected radiance is compared.
SLAB_MU = 0.7


def slab_scene(g: float, **surface) -> Scene:
    """A constant fog slab of optical depth 1 (albedo 0.9, HG ``g``) from 0 to 10 m under a zenith sun, seen from
    30 m at :data:`SLAB_MU`, over the ``surface`` (``ground=`` a plane or ``meshes=``) of albedo 0.5."""
    fog = AnalyticFog("slab", [ConstantTerm(0.1)], floor=0.0, top=10.0, albedo=np.full(3, 0.9), g=g)
    return Scene(looking_down(SLAB_MU, (0.0, 30.0, 0.0)), Sun(np.array([0.0, 1.0, 0.0]), np.ones(3)), fogs=(fog,),
                 **surface)


def against_adding_doubling(layer, g: float, what: str) -> tuple[float, float, float, float]:
    """(mean, its standard error, adding-doubling's radiance, z) of the green channel of :func:`slab_scene`'s
    layer."""
    from adding_doubling import ground_reflected_radiance

    expected = ground_reflected_radiance(lambda c: phase_numpy(PhaseKind.HG, g, c), 1.0, 0.9, 0.5, SLAB_MU)
    mean = layer.radiance[..., 1].astype(np.float64).mean()
    sigma = np.sqrt(layer.aovs["variance"][..., 1].astype(np.float64).sum()) / layer.radiance[..., 1].size
    z = (mean - expected) / sigma
    print(f"\nfog slab {what}: path tracer {mean:.5f} +- {sigma:.5f}, adding-doubling {expected:.5f}, z = {z:.2f}")
    return mean, sigma, expected, z


@pytest.mark.parametrize("g,order", [(0.5, 0), (0.0, 1)])
def test_fog_slab_over_ground_against_adding_doubling(g, order, device):
    """A constant fog slab of optical depth 1 (albedo 0.9, HG g) on a Lambertian ground (albedo 0.5) under a zenith
    sun, no air: the radiance leaving it at mu = 0.7 (every order of scattering and ground bounce) agrees with
    adding-doubling, |z| < 3. With g = 0 high-order similarity from the first event changes nothing (the reduced
    fog is the fog): the same agreement through the reduced flights, events and shadow rays."""
    scene = slab_scene(g, ground=Ground(0.0, np.full(3, 0.5)))
    settings = PathTracerSettings(spp=4096, seed=3, similarity_order=order)
    layer = PathTracer(settings, device=device).render(scene, 4, 4)
    mean, sigma, expected, z = against_adding_doubling(layer, g, f"over ground, g = {g}, similarity order {order}")
    assert abs(z) < 3.0
    assert np.allclose(layer.radiance[..., 0], layer.radiance[..., 1]) and sigma < 0.005 * expected


def test_fog_slab_over_a_terrain_mesh_against_adding_doubling(device):
    """The same fog slab (g = 0.5) over a flat Lambertian mesh instead of the ground plane: the meshes and the fog
    meet in one walk (the mesh bounce's sunlight through the fog's closed-form transmittance), |z| < 3 against
    adding-doubling."""
    from warpsky.model.terrain import TerrainMesh

    half = 500.0  # wide enough for every path in the slab; its rays leave 2e-5 x (1 m + 707 m) = 1.4 cm off it
    floor = TerrainMesh("floor", np.array([[-half, 0.0, -half], [half, 0.0, -half], [half, 0.0, half],
                                           [-half, 0.0, half]]), np.array([[0, 2, 1], [0, 3, 2]]), (0.5, 0.5, 0.5))
    layer = PathTracer(PathTracerSettings(spp=4096, seed=5), device=device).render(slab_scene(0.5, meshes=(floor,)),
                                                                                   4, 4)
    _, sigma, expected, z = against_adding_doubling(layer, 0.5, "over a mesh")
    assert abs(z) < 3.0 and sigma < 0.005 * expected


def test_fogs_and_a_voxel_slab_mix_against_adding_doubling(tmp_path, homogeneous_npy, device):
    """Two fogs and a voxel slab filling the same 10 m under a zenith sun (tau 0.3 + 0.2 + 0.5, albedos 0.9, 0.6 and
    1, HG g 0.7, -0.2 and 0.5), seen from above at mu = 0.7: the scattering events pick each part by its share, so
    the reflected radiance is adding-doubling's for the mixture's albedo and phase, |z| < 3."""
    import dataclasses

    from adding_doubling import slab_radiance
    from conftest import StageSpec, look_rotation, write_stage

    from warpsky.usd.stage import StageReader

    mu = 0.7
    look = np.array([np.sqrt(1.0 - mu * mu), -mu, 0.0])
    spec = StageSpec(volume_file=homogeneous_npy, volume_extent=((-1e5, 0.0, -1e5), (1e5, 10.0, 1e5)),
                     extinction_scale=0.05, phase="hg", g=0.5, sun_direction=(0.0, 1.0, 0.0),
                     camera_position=tuple(-look * 40.0 + np.array([0.0, 5.0, 0.0])),
                     camera_rotation=look_rotation(look), focal_length=2000.0)
    scene = StageReader(write_stage(tmp_path / "mixed.usda", spec)).scene_at(None)
    fogs = (AnalyticFog("a", [ConstantTerm(0.03)], floor=0.0, top=10.0, albedo=np.full(3, 0.9), g=0.7),
            AnalyticFog("b", [ConstantTerm(0.02)], floor=0.0, top=10.0, albedo=np.full(3, 0.6), g=-0.2))
    scene = dataclasses.replace(scene, fogs=fogs)
    layer = PathTracer(PathTracerSettings(spp=4096, seed=5), device=device).render(scene, 4, 4)
    parts = [(0.3 * 0.9, 0.7), (0.2 * 0.6, -0.2), (0.5 * 1.0, 0.5)]  # (scattering optical depth, g)
    scattering = sum(s for s, _ in parts)

    def phase(c):
        return sum(s * phase_numpy(PhaseKind.HG, g, c) for s, g in parts) / scattering

    expected = slab_radiance(phase, 1.0, scattering, [mu])[0][0]
    mean = layer.radiance[..., 1].astype(np.float64).mean()
    sigma = np.sqrt(layer.aovs["variance"][..., 1].astype(np.float64).sum()) / layer.radiance[..., 1].size
    z = (mean - expected) / sigma
    print(f"\nfogs and voxels: path tracer {mean:.5f} +- {sigma:.5f}, adding-doubling {expected:.5f}, z = {z:.2f}")
    assert abs(z) < 3.0 and sigma < 0.01 * expected


def test_thin_fog_single_scattering_matches_the_fog_pass(device):
    """A thin varied fog (optical depth at most 0.15 along the rays) around the camera, no ground or air, paths cut
    after one scattering: the image is the fog pass's single scattering (ambient 0), |z| < 3 over the frame (a
    pixel's handful of scattering events per path count is too few for a per-pixel z)."""
    fog = varied_fog(strength=0.01)
    scene = Scene(fog_camera(far=300.0), oblique_sun(), fogs=(fog,))
    layer = PathTracer(PathTracerSettings(spp=1024, max_bounces=1), device=device).render(scene, 8, 8)
    marched = Fog(device=device, **EXACT).render(scene, 8, 8, ambient=np.zeros(3))
    traced, expected = layer.radiance.astype(np.float64), marched.radiance.astype(np.float64)
    variance = layer.aovs["variance"].astype(np.float64)
    total_z = (traced.sum(axis=(0, 1)) - expected.sum(axis=(0, 1))) / np.sqrt(variance.sum(axis=(0, 1)))
    print(f"\nthin fog: mean {traced.mean():.5g} vs {expected.mean():.5g}, frame z {np.round(total_z, 2).tolist()}, "
          f"largest optical depth {-np.log(marched.transmittance.min()):.3f}")
    assert np.all(np.abs(total_z) < 3.0)
    assert -np.log(marched.transmittance.min()) < 0.2


@pytest.mark.parametrize("kind", ["dense", "cancelling"])
def test_dense_and_cancelling_fogs_stay_finite_and_bounded(kind, device):
    """A fog of 1 /m around the camera (optical depth 20 across the slab) and one whose terms cancel near the
    camera (2 - 2 cos(0.01 x): density ~1e-4 x^2 under a majorant of 4 /m) render finite, non-negative pixels with
    a bounded number of tracking steps per path, in bounded time."""
    if kind == "dense":
        fog = AnalyticFog("dense", [ConstantTerm(1.0)], floor=0.0, top=20.0, albedo=np.array([0.9, 0.95, 1.0]), g=0.8)
    else:
        fog = AnalyticFog("cancelling", [ConstantTerm(2.0), CosineTerm(-2.0, [0.01, 0.0, 0.0])], floor=0.0,
                          top=20.0, albedo=np.full(3, 0.9), g=0.3)
        assert density_bound(fog) == 4.0
    scene = Scene(fog_camera(), oblique_sun(), fogs=(fog,), ground=Ground(0.0, np.full(3, 0.3)))
    started = time.perf_counter()
    layer = PathTracer(PathTracerSettings(spp=8, max_bounces=256), device=device).render(scene, 8, 8)
    seconds = time.perf_counter() - started
    stats = layer.stats
    print(f"\n{kind}: {seconds:.2f} s, {stats['tracking_steps'] / stats['paths']:.1f} tracking steps per path, "
          f"mean radiance {layer.radiance.mean():.4g}, capped {stats['capped_paths']}")
    assert np.all(np.isfinite(layer.radiance)) and np.all(layer.radiance >= 0.0)
    assert np.all(np.isfinite(layer.transmittance)) and np.all(layer.transmittance >= 0.0)
    assert stats["tracking_steps"] < 2000 * stats["paths"]
    assert seconds < 120.0
    if kind == "dense":
        assert layer.transmittance.max() < 1e-6 and layer.radiance.mean() > 0.0


def test_plan_traces_fog_with_the_path_tracer_and_keeps_the_fog_pass_for_the_others():
    """With the path tracer the fog needs no fog pass (nor the surfaces pass for the ground); with the hybrid the
    fog pass draws it as before."""
    from warpsky.render.plan import make_plan

    scene = Scene(fog_camera(), oblique_sun(), fogs=(varied_fog(),), ground=Ground(0.0))
    traced = make_plan(scene, technique="path_tracer", resolution=(8, 8))
    assert "fog" not in traced.passes and "surfaces" not in traced.passes and "media" in traced.passes
    assert "traced by path_tracer" in traced.features["fog"]
    marched = make_plan(scene, technique="hybrid", resolution=(8, 8))
    assert "fog" in marched.passes and "surfaces" in marched.passes
