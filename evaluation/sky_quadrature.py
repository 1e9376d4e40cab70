"""Brute-force reference of the analytic sky: Riley Eq. 8 (with Eqs. 10-12) integrated by trapezoids in float64,
and a seeded table of view/sun/altitude cases including the degenerate angles. Used by the sky's tests and
``evaluation/benchmarks/bench_sky.py``; no render uses it."""

from __future__ import annotations

import numpy as np

from warpsky.media.air import analytic as sky

BETA = np.array(sky.RILEY_BETA_SEA_LEVEL)
GAMMA = 1.0 / sky.RILEY_SCALE_HEIGHT


def quadrature(h0: float, view_y: float, sun_y: float, distance: float) -> np.ndarray:
    """∫_0^K β(h) exp(-∫_0^t β) T_sun(h) dt by trapezoids on a graded grid, optical depth integrated numerically."""
    if sun_y <= 0.0:
        return np.zeros(3)
    k = distance
    if not np.isfinite(k):
        if view_y > 0.0:
            k = 60.0 / (GAMMA * view_y)  # 60 scale heights up: the rest weighs e^-60
        elif view_y == 0.0:
            k = 60.0 / (BETA.min() * np.exp(-GAMMA * h0))  # optical depth 60 along a level ray
        else:
            k = 60.0 / (GAMMA * -view_y)
    t = np.concatenate([[0.0], np.geomspace(1e-3, k, 200_000)])
    h = h0 + view_y * t
    beta = BETA[:, None] * np.exp(-GAMMA * h)[None, :]
    depth = np.concatenate([np.zeros((3, 1)), np.cumsum(0.5 * (beta[:, 1:] + beta[:, :-1]) * np.diff(t), axis=1)],
                           axis=1)
    sun = np.exp(-BETA[:, None] * np.exp(-GAMMA * h)[None, :] / (GAMMA * sun_y))
    f = beta * np.exp(-depth) * sun
    return np.sum(0.5 * (f[:, 1:] + f[:, :-1]) * np.diff(t), axis=1)


DEGENERATE = [0.0, 1e-7, -1e-7, 1.0, -1.0]


def cases(count: int, seed: int = 0):
    """``count`` (altitude [m], view y, sun y, distance [m]) cases: every degenerate combination, then random ones."""
    rng = np.random.default_rng(seed)
    out = []
    for h0 in (0.0, 10.0, 12_000.0, 100_000.0):
        for view_y in DEGENERATE + list(rng.uniform(-1, 1, 4)):
            for sun_y in [0.0, 1e-7, 0.02, 0.5, 1.0] + [view_y if view_y > 0 else 0.3]:
                for distance in (np.inf, 3_000.0):
                    out.append((h0, view_y, sun_y, distance))
    for _ in range(count - len(out)):
        out.append((rng.choice([0.0, 10.0, 12_000.0, 100_000.0]) * rng.random(), rng.uniform(-1, 1),
                    rng.uniform(-0.1, 1.0), rng.choice([np.inf, rng.uniform(10.0, 200_000.0)])))
    return out
