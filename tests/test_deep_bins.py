"""Several deep samples per volume: each volume layer becomes volume samples along depth whose alphas follow its
extinction (closed forms of a homogeneous box, a density ramp and a fog slab), and which still flatten to the frame."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import look_rotation

from warpsky.core.image import ImageLayer
from warpsky.light.background import pixel_directions
from warpsky.model.scene import Atmosphere, Camera, Ground, Scene, Sun, VoxelMedium
from warpsky.output.deep import deep_from_layers, flatten, visibility_in_front
from warpsky.output.deep_bins import DepthProfile
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.render.plan import make_plan

SIZE = 24
FAR = 1.0e4
EYE = np.array([0.0, 0.0, 60.0])
SUN = Sun(np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2]), np.ones(3))
BOX = (np.array([-10.0, -10.0, -10.0]), np.array([10.0, 10.0, 10.0]))  # [m]
FAST = {"single_scatter": {"step_length": "0.5"}, "slicing": {"slice_count": "32"},
        "hybrid": {"spp": "2", "target_error": "0", "seed": "1", "step_length": "0.5"},
        "path_tracer": {"spp": "2", "seed": "1"}}


def camera(position=EYE, forward=(0.0, 0.0, -1.0)) -> Camera:
    return Camera("cam", np.asarray(position, np.float64), look_rotation(forward), 30.0, 36.0, 36.0, near=0.5,
                  far=FAR)


def box_medium(values: np.ndarray, sigma: float) -> VoxelMedium:
    """The 20 m box ``BOX`` holding ``values`` along z (index 0 at the back, z = -10 m): 4 x 4 voxels across."""
    count = len(values)
    world_from_index = np.diag([5.0, 5.0, 20.0 / count, 1.0])
    world_from_index[:3, 3] = [-7.5, -7.5, -10.0 + 10.0 / count]
    density = np.broadcast_to(np.asarray(values, np.float32), (4, 4, count)).copy()
    return VoxelMedium("box", density, world_from_index, np.full(3, sigma), np.ones(3))


def box_rays(cam: Camera):
    """Per pixel: unit direction, cosine to the view axis, distances [m] where the ray enters and leaves ``BOX``,
    and whether it meets it."""
    d = pixel_directions(cam, SIZE, SIZE)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (BOX[0] - cam.position) / d, (BOX[1] - cam.position) / d
    enter, leave = np.minimum(a, b).max(axis=-1), np.maximum(a, b).min(axis=-1)
    return d, d @ cam.forward, enter, leave, leave > enter


def frame(scene: Scene, technique: str = "single_scatter", deep_samples: int = 8, settings=None):
    plan = make_plan(scene, technique=technique, settings=settings or FAST[technique], resolution=(SIZE, SIZE),
                     device="cpu")
    return render_layers(plan, scene, deep_samples=deep_samples)


def pixel_samples(deep):
    """Each pixel's (Z, ZBack) arrays."""
    start = np.cumsum(deep.counts.reshape(-1)) - deep.counts.reshape(-1)
    return [(deep.channels["Z"][s:s + n], deep.channels["ZBack"][s:s + n])
            for s, n in zip(start, deep.counts.reshape(-1), strict=True)]


def largest_visibility_error(deep, cam, closed_form, depths) -> float:
    """The largest |deep visibility - closed form| over ``depths`` [m] and the pixels whose ray meets the box;
    ``closed_form(t, enter, leave, direction)`` gives the closed-form transmittance at distance t [m]."""
    d, cos, enter, leave, hit = box_rays(cam)
    worst = 0.0
    for depth in depths:
        exact = closed_form(np.clip(depth / cos, enter, leave), enter, leave, d)
        worst = max(worst, float(np.abs(visibility_in_front(deep, depth) - exact)[hit].max()))
    return worst


@pytest.mark.parametrize("deep_samples", [1, 8, 16])
def test_visibility_inside_a_homogeneous_box_follows_the_closed_form(deep_samples):
    """A box of uniform extinction 0.05 /m seen end on: what the deep image lets through in front of any depth d
    (the samples behind the camera's side of d, the cut sample split exponentially) is exp(-sigma (t - t_enter)),
    t = d / cos, within 1e-5 at any bin count (the bins are exact for uniform extinction), 1 in front of the box
    and the box's transmittance behind it."""
    sigma = 0.05
    cam = camera()
    main, layers = frame(Scene(camera=cam, sun=SUN, media=(box_medium(np.ones(4), sigma),)), deep_samples=deep_samples)
    deep = deep_from_layers(layers, FAR)
    error = largest_visibility_error(deep, cam, lambda t, enter, leave, d: np.exp(-sigma * (t - enter)),
                                     np.linspace(40.0, 80.0, 81))
    assert error < 1e-5, error


def ramp_closed_form(values: np.ndarray, sigma: float):
    """Transmittance from the entry of ``box_medium(values)`` to distance t along each ray: the field is
    trilinear in z between voxel centres (clamped within half a voxel of the faces), so its integral over z is
    piecewise quadratic, exact here."""
    count = len(values)
    z = np.concatenate([[-10.0], -10.0 + (np.arange(count) + 0.5) * 20.0 / count, [10.0]])
    f = np.concatenate([[values[0]], values, [values[-1]]])
    column = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(z))])  # int_{-10}^{z_i} f dz

    def integral(at):  # int_{-10}^{at} f dz
        i = np.clip(np.searchsorted(z, at) - 1, 0, len(z) - 2)
        h, width = at - z[i], z[i + 1] - z[i]
        return column[i] + f[i] * h + (f[i + 1] - f[i]) * h**2 / (2.0 * width)

    def transmittance(t, enter, leave, d):
        z_enter, z_at = EYE[2] + enter * d[..., 2], EYE[2] + t * d[..., 2]
        return np.exp(-sigma * np.abs(integral(z_at) - integral(z_enter)) / np.abs(d[..., 2]))

    return transmittance


@pytest.mark.parametrize("sigma,rising,bounds", [(0.05, True, (5e-3, 1.5e-3)), (0.05, False, (6e-3, 2e-3)),
                                                 (1.0, True, (2e-3, 1e-3)), (1.0, False, (1.2e-2, 6e-3))])
def test_visibility_inside_a_density_ramp_converges_to_the_closed_form(sigma, rising, bounds):
    """A density rising 20-fold along the ray (0.1 to 2 in 20 voxels), its dense side behind or in front, of optical
    depth about 1 and 21 (the thick one hides all behind its first metres): the deep visibility of a point anywhere
    in it against the closed form, at K = 8 and 16 samples. Measured: 3.7e-3, 4.7e-3, 1.2e-3, 9.4e-3 at K = 8;
    9.5e-4, 1.2e-3, 6.9e-4, 4.2e-3 at K = 16 (second order in 1/K until the profile's march, half a voxel per step,
    sets the floor of the thick one, 7e-4)."""
    values = np.arange(1, 21, dtype=np.float64) / 10.0
    values = values if rising else values[::-1]
    cam = camera()
    scene = Scene(camera=cam, sun=SUN, media=(box_medium(values, sigma),))
    exact = ramp_closed_form(values, sigma)
    depths = np.linspace(45.0, 75.0, 241)
    errors = [largest_visibility_error(deep_from_layers(frame(scene, deep_samples=k)[1], FAR), cam, exact, depths)
              for k in (8, 16)]
    assert errors[0] < bounds[0] and errors[1] < bounds[1], errors


@pytest.mark.parametrize("technique", ["single_scatter", "slicing", "hybrid", "path_tracer"])
def test_volume_samples_flatten_to_the_frame_with_ground_and_air(technique):
    """Every technique, a box over a ground plane under Rayleigh air: with 6 samples per volume the deep image
    flattens to the composited frame within 1e-3 (float32 samples); depths never decrease and samples never
    overlap along a pixel; a pixel whose ray misses the box has exactly the samples it had without volume samples
    (the air in front, its ground or sky), one that meets it at most 6 volume samples more."""
    cam = camera(position=(0.0, 8.0, 60.0), forward=(0.0, -0.25, -1.0))
    scene = Scene(camera=cam, sun=SUN, media=(box_medium(np.linspace(0.5, 1.5, 4), 0.08),),
                  ground=Ground(-12.0), atmosphere=Atmosphere())
    _, layers = frame(scene, technique, deep_samples=6)
    deep = deep_from_layers(layers, FAR)
    rgba = composite(layers, FAR).rgba
    np.testing.assert_allclose(flatten(deep), rgba, rtol=1e-3, atol=1e-3 * rgba[..., :3].max())
    for z, back in pixel_samples(deep):
        assert np.all(z <= back) and np.all(z[1:] >= back[:-1])
    bare = deep_from_layers(_without_profiles(layers), FAR)
    meets = box_rays(cam)[-1]
    np.testing.assert_array_equal(deep.counts[~meets], bare.counts[~meets])
    extra = deep.counts - bare.counts
    assert extra.max() <= 6 and extra[meets].max() >= 5


def _without_profiles(layers):
    """``layers`` with every depth profile dropped: the deep image of one sample per layer."""
    from dataclasses import replace

    return [replace(layer, profile=None, parts=[replace(p, profile=None) for p in layer.parts]) for layer in layers]


def test_a_pixel_without_media_gets_no_volume_samples_and_bins_are_bounded_by_the_setting():
    """Single box, no air: where the ray misses the box there is no sample; where it meets it, exactly K volume
    samples (Z < ZBack) spanning the box's entry to exit along the view axis, for K = 1, 3, 12."""
    cam = camera()
    d, cos, enter, leave, hit = box_rays(cam)
    for k in (1, 3, 12):
        main, layers = frame(Scene(camera=cam, sun=SUN, media=(box_medium(np.ones(4), 0.05),)), deep_samples=k)
        deep = deep_from_layers(layers, FAR)
        assert np.all(deep.counts[~hit] == 0) and np.all(deep.counts[hit] == k)
        for (z, back), e, l, c in zip(pixel_samples(deep), (enter * cos).reshape(-1), (leave * cos).reshape(-1),
                                      hit.reshape(-1), strict=True):
            if c:
                assert np.all(z < back)
                np.testing.assert_allclose([z[0], back[-1]], [e, l], rtol=1e-5)


def test_fog_slab_samples_follow_its_closed_form():
    """A constant analytic fog slab (Biri 2002), y from 0 to 20 m, seen from 50 m above looking down: its deep
    samples' visibility at any depth is exp(-c sigma (t - t_enter)) within 1e-6, flattening gives the frame."""
    from warpsky.model.fog import AnalyticFog, ConstantTerm

    c = 0.04
    cam = camera(position=(0.0, 50.0, 0.0), forward=(0.0, -1.0, 0.0))
    fog = AnalyticFog("slab", (ConstantTerm(c),), floor=0.0, top=20.0, extinction_scale=np.ones(3))
    _, layers = frame(Scene(camera=cam, sun=SUN, fogs=(fog,)), deep_samples=8)
    deep = deep_from_layers(layers, FAR)
    np.testing.assert_allclose(flatten(deep), composite(layers, FAR).rgba, atol=1e-6)
    cos = pixel_directions(cam, SIZE, SIZE) @ cam.forward
    for depth in np.linspace(20.0, 60.0, 41):  # the view axis is vertical: depth is the height below the eye
        np.testing.assert_allclose(visibility_in_front(deep, depth),
                                   np.exp(-c * np.clip(depth - 30.0, 0.0, 20.0) / cos), atol=1e-6)
    assert np.all(deep.counts == 8)


def test_split_of_a_layer_is_exact_with_coloured_opaque_and_clamped_profiles():
    """A hand-made profile against layers it does not match: transmittance greater than the profile's (a march cut
    off early), smaller (a ground the ray ends on: a point behind the bins), opaque, a channel the layer does not
    dim, strongly coloured: flattening equals the composite to float32 precision and every alpha lies in [0, 1]."""
    rng = np.random.default_rng(7)
    shape, k = (4, 5), 4
    tau = np.cumsum(rng.uniform(0.0, 0.6, shape + (k + 1, 3)), axis=-2)
    tau[..., 0, :] = 0.0
    tau[0, 0] = 0.0  # no media in this pixel
    edges = np.cumsum(rng.uniform(0.5, 3.0, shape + (k + 1,)), axis=-1) + 10.0
    end = np.where(rng.uniform(size=shape) < 0.5, edges[..., -1] + 5.0, 0.0)
    through = np.exp(-tau[..., -1, :] * rng.uniform(0.3, 1.7, shape + (1,)))
    through[1, :] = 0.0
    through[2, 0] = [1.0, 0.5, 0.2]
    volume = ImageLayer(rng.uniform(0.0, 2.0, shape + (3,)).astype(np.float32), through.astype(np.float32),
                        np.full(shape, 20.0, np.float32), profile=DepthProfile(edges.astype(np.float32),
                                                                           tau.astype(np.float32), end))
    sky = ImageLayer(np.full(shape + (3,), 0.3, np.float32), np.ones(shape + (3,), np.float32), np.full(shape, FAR))
    deep = deep_from_layers([volume, sky], FAR)
    np.testing.assert_allclose(flatten(deep), composite([volume, sky], FAR).rgba, rtol=1e-5, atol=1e-6)
    assert np.all((deep.channels["A"] >= 0.0) & (deep.channels["A"] <= 1.0))
    assert deep.counts[0, 0] == 2  # the layer as one point, and the sky


def test_deep_samples_outside_their_range_are_refused(tmp_path, homogeneous_npy, capsys):
    from conftest import StageSpec, write_stage
    from conftest import run_cli as run

    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy, camera_position=(0, 0, 40)))
    code, _, err = run(["render", stage, tmp_path / "f.exr", "--deep", "--deep-samples", "0"], capsys)
    assert code == 2 and "--deep-samples must be a whole number of samples per volume in 1..64, got 0" in err
