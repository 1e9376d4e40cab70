"""Buffers kept across frames: the same array for the same request, uploads skipped for the same bytes, downloads
that copy."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core import device_buffers as buffers


def test_reusable_arrays_and_content_keyed_uploads(device):
    buffers.clear()
    start = buffers.allocation_count()
    a = buffers.reusable("test:a", (4, 3), float, device)
    assert buffers.reusable("test:a", (4, 3), float, device) is a
    assert buffers.reusable("test:b", (4, 3), float, device) is not a  # names never share
    b = buffers.reusable("test:a", (5, 3), float, device)  # a new shape replaces the kept array
    assert b.shape == (5, 3) and buffers.allocation_count() == start + 3
    grid = np.arange(24, dtype=np.float32)
    up = buffers.upload("test:grid", grid, float, device)
    assert buffers.upload("test:grid", grid.copy(), float, device) is up  # same bytes: no upload
    changed = grid.copy()
    changed[7] += 1.0
    again = buffers.upload("test:grid", changed, float, device)
    assert again is not up and np.array_equal(again.numpy(), changed)
    host = buffers.download("test:grid", again)
    host[0] = -1.0  # the caller owns its copy
    assert again.numpy()[0] == 0.0 and np.array_equal(buffers.download("test:grid", again)[1:], changed[1:])
    wp.synchronize()
