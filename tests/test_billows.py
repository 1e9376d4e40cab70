"""The demo cumulus's procedural field: cellular noise against brute force, and the field's range and base."""

from __future__ import annotations

import numpy as np
import warp as wp

from evaluation.billows import LATTICE, BillowParams, billow_grid_numpy, cellular_f1


@wp.kernel
def _f1_at(points: wp.array(dtype=wp.vec3), features: wp.array3d(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = cellular_f1(points[i], features)


def test_cellular_f1_is_the_nearest_feature_point_of_the_periodic_lattice():
    rng = np.random.default_rng(3)
    features = rng.random((LATTICE, LATTICE, LATTICE, 3)).astype(np.float32)
    points = rng.uniform(-40.0, 40.0, (200, 3)).astype(np.float32)
    out = wp.zeros(len(points), dtype=float, device="cpu")
    wp.launch(_f1_at, dim=len(points), inputs=[wp.array(points, dtype=wp.vec3, device="cpu"),
                                              wp.array(features, dtype=wp.vec3, device="cpu"), out], device="cpu")
    # Brute force: every lattice cell within two cells of the point, with the lattice repeated periodically.
    expected = []
    for p in points.astype(np.float64):
        base = np.floor(p).astype(int)
        offsets = np.stack(np.meshgrid(*[np.arange(-2, 3)] * 3, indexing="ij"), -1).reshape(-1, 3)
        cells = base + offsets
        wrapped = np.mod(cells, LATTICE)
        centres = cells + features[wrapped[:, 0], wrapped[:, 1], wrapped[:, 2]]
        expected.append(np.linalg.norm(centres - p, axis=1).min())
    np.testing.assert_allclose(out.numpy(), expected, rtol=0, atol=2e-5)


def test_billow_field_is_bounded_with_a_flat_base_and_empty_outside_the_spheres():
    shape, voxel = (48, 32, 48), 50.0
    size = np.array(shape, float) * voxel
    spheres = np.array([[1200.0, 500.0, 1200.0, 600.0]], np.float32)
    params = BillowParams()
    density = billow_grid_numpy(shape, size, spheres, seed=5, params=params)
    assert np.isfinite(density).all() and density.min() >= 0.0 and density.max() <= 1.0
    assert density.max() == 1.0
    # Nothing beyond the largest outward push of the billows (bump / 2 past the sphere's surface).
    centres = (np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1) + 0.5) * voxel
    distance = np.linalg.norm(centres - spheres[0, :3], axis=-1)
    assert density[distance > spheres[0, 3] + 0.5 * params.bump].max() == 0.0
    # Flat base: the first cell row (25 m up) is at most its share of the base ramp.
    assert density[:, 0, :].max() <= 0.5 * voxel / params.base_ramp
    # Seeded: the same seed gives the same field, another seed another one.
    np.testing.assert_array_equal(density, billow_grid_numpy(shape, size, spheres, seed=5, params=params))
    assert np.abs(density - billow_grid_numpy(shape, size, spheres, seed=6, params=params)).max() > 0.1
