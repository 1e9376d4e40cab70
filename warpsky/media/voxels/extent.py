"""How far rays run through a scene's voxel media: the boxes' diagonal, a ray's chord through each box, the
longest chord along a direction and along the frame's camera rays. The techniques bound their work estimates
with these (:mod:`warpsky.core.resources`)."""

from __future__ import annotations

import numpy as np

from warpsky.model.camera import Projection


def grid_bytes(scene) -> int:
    """Bytes of every voxel field of ``scene`` as float32 (one upload of the media)."""
    return sum(int(np.prod(m.shape)) * 4 for m in scene.media)


def media_diagonal(media) -> float:
    """Diagonal of the box around ``media`` [m]: the longest path any ray takes through them."""
    if not media:
        return 0.0
    corners = np.concatenate([m.world_corners() for m in media])
    return float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))

#: Camera rays per image axis whose path through each medium's box bounds the march (the corners included).
CHORD_RAYS = 33


def box_chords(medium, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Length [m] of each ray ``origin + t d`` (t >= 0, (N, 3) unit world directions) inside ``medium``'s box."""
    index_from_world = np.linalg.inv(medium.world_from_index)
    o = (index_from_world @ np.append(origin, 1.0))[:3]
    d = directions @ index_from_world[:3, :3].T  # index units per metre along each ray
    lo, hi = -0.5, np.asarray(medium.shape, dtype=np.float64) - 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - o) / d
        tb = (hi - o) / d
    inside = (o >= lo) & (o <= hi)
    near = np.where(d == 0.0, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    far = np.where(d == 0.0, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    enter = np.maximum(near.max(axis=1), 0.0)
    leave = far.min(axis=1)
    return np.where(leave > enter, leave - enter, 0.0)


def longest_chord(medium, direction: np.ndarray) -> float:
    """Longest segment [m] along ``direction`` that fits in ``medium``'s box: min over its axes of the box's edge
    over the direction's component along that axis (in index units)."""
    d = np.linalg.inv(medium.world_from_index)[:3, :3] @ np.asarray(direction, dtype=np.float64)
    edges = np.asarray(medium.shape, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(np.abs(d) > 0.0, edges / np.abs(d), np.inf)))


def camera_chord(scene) -> float:
    """The longest path [m] a camera ray takes through the media (summed over their boxes), over a
    :data:`CHORD_RAYS` square grid of the frame's rays, corners included; the boxes' diagonal for an
    orthographic camera (its rays do not share an origin)."""
    camera = scene.camera
    if camera.projection is not Projection.PERSPECTIVE:
        return media_diagonal(scene.media)
    steps = np.linspace(0.0, 1.0, CHORD_RAYS)
    directions = np.array([camera.pixel_direction(x, y, 1, 1) for y in steps for x in steps])
    chords = sum(box_chords(m, np.asarray(camera.position, dtype=np.float64), directions) for m in scene.media)
    return float(np.max(chords))
