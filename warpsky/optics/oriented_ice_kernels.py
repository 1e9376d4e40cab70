"""Geometric-optics Monte Carlo of oriented hexagonal ice prisms, tallied over the sky around the sun.

The prism, its faces and the Fresnel / total-internal-reflection rules are those of
:mod:`warpsky.optics.ice_kernels` (reused here: :func:`~warpsky.optics.ice_kernels.face_normal`,
:func:`~warpsky.optics.ice_kernels.face_offset`, :func:`~warpsky.optics.ice_kernels.fresnel_unpolarised`,
:func:`~warpsky.optics.ice_kernels.reflect`). What changes is that the crystal's orientation is no longer uniform,
so the outgoing direction is tallied in two angles instead of one.

Sun frame
    X horizontal towards the sun's azimuth, Y up, Z = X x Y. Sunlight travels along ``(-cos e, -sin e, 0)`` for
    sun elevation e. A scattered photon leaving along ``d`` is seen by an observer looking along ``look = -d``; it
    is tallied at the look direction's elevation h (from -90° to 90°) and its azimuth from the sun's azimuth,
    folded to |a| in [0°, 180°] (every orientation law here is mirror-symmetric about the sun's vertical plane).

Sky bins (:class:`SkyGrid`)
    Elevation bins are centred on -90°, -90° + step, ..., 90° (the two end bins are half bins); azimuth bins on
    0°, step, ..., 180° (end bins half bins too). A sun elevation on the step lattice therefore sits on a bin
    centre, so a perfectly aligned plate's parhelion (which keeps the sun's elevation exactly) is not split
    between two bins. Counts are whole numbers in float64, so atomics in any order give the same histogram.

Orientation laws (``kind``; flutter angles are normal deviates of standard deviation ``tilt`` [rad])
    0 random: a uniform rotation (four normal deviates, as in :mod:`~warpsky.optics.ice_kernels`).
    1 plate: c-axis vertical, uniform spin about it, then tilted by the flutter angle about a horizontal axis of
      uniform azimuth.
    2 column: c-axis horizontal with uniform azimuth, uniform spin about it, the c-axis tilted out of the
      horizontal by the flutter angle (singly oriented columns: tangent arcs).
    3 parry: as column, but the spin about the c-axis is fixed with two prism faces horizontal, up to a flutter
      roll (Parry arcs).

Each photon starts on a uniform point of a square of side 2 R (R the bounding-sphere radius) across the sunlight,
so the chance of a hit is proportional to the crystal's projected area along the sunlight in its sampled
orientation: an oriented crystal's scattering is weighted by the area it shows the sun, as it must be.
"""

from __future__ import annotations

import math

import warp as wp

from warpsky.optics.ice_kernels import face_normal, face_offset, fresnel_unpolarised, reflect

wp.set_module_options({"enable_backward": False})

KIND_RANDOM = 0
KIND_PLATE = 1
KIND_COLUMN = 2
KIND_PARRY = 3
#: Photon fates returned by :func:`trace_photon`.
FATE_MISSED = 0
FATE_LEFT = 1
FATE_TRAPPED = 2
#: Tally columns: photons that hit the crystal, missed it, and were still inside after the interaction cap.
TALLY_HITS = 0
TALLY_MISSES = 1
TALLY_TRAPPED = 2
TALLY_COUNT = 3

_FACE_COUNT = wp.constant(8)
_HALF_PI = wp.constant(0.5 * math.pi)


@wp.struct
class SkyGrid:
    """Bins of the sky around the sun (see the module docstring).

    Attributes:
        elevation_step: Spacing of the elevation bin centres [rad]; bins centred on -pi/2 + k step.
        azimuth_step: Spacing of the azimuth bin centres [rad]; bins centred on k step, k = 0..azimuth_bins - 1.
        elevation_bins: pi / elevation_step + 1.
        azimuth_bins: pi / azimuth_step + 1.
    """

    elevation_step: float
    azimuth_step: float
    elevation_bins: int
    azimuth_bins: int


@wp.struct
class OrientedTrace:
    """One sun elevation's Monte Carlo.

    Attributes:
        seed: Random seed; a photon's stream depends only on (seed, global photon index).
        photons_per_channel: Photons launched per channel, hits and misses together.
        half_length: Half the prism length for hexagon circumradius 1 (= length / diameter).
        refractive_index: (3, samples) real index per channel and sample wavelength; photon i uses sample i mod
            samples.
        max_interactions: Internal face hits after which a photon still inside counts as trapped.
        kind: Orientation law, ``KIND_*``.
        tilt: Flutter standard deviation [rad].
        sun_elevation: Elevation of the sun [rad], 0..pi/2.
        grid: Sky bins of the tally.
    """

    seed: int
    photons_per_channel: int
    half_length: float
    refractive_index: wp.array2d(dtype=float)
    max_interactions: int
    kind: int
    tilt: float
    sun_elevation: float
    grid: SkyGrid


@wp.func
def sample_orientation(kind: int, tilt: float, state: wp.uint32):
    """(world-from-crystal rotation drawn from orientation law ``kind`` (sun frame, Y up), advanced random state).

    Warp passes a random state to a function by value, so every function drawing numbers returns it."""
    if kind == KIND_RANDOM:
        q = wp.normalize(wp.quat(wp.randn(state), wp.randn(state), wp.randn(state), wp.randn(state)))
        return q, state
    up = wp.vec3(0.0, 1.0, 0.0)
    c_axis = wp.vec3(0.0, 0.0, 1.0)
    spin = 2.0 * wp.pi * wp.randf(state)
    azimuth = 2.0 * wp.pi * wp.randf(state)
    flutter = tilt * wp.randn(state)
    if kind == KIND_PLATE:
        base = wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), -_HALF_PI)  # c-axis to +Y
        axis = wp.vec3(wp.cos(azimuth), 0.0, wp.sin(azimuth))
        return wp.quat_from_axis_angle(axis, flutter) * base * wp.quat_from_axis_angle(c_axis, spin), state
    # columns: c-axis to +X, crystal y (the normal of prism faces 1 and 4) stays +Y
    base = wp.quat_from_axis_angle(up, _HALF_PI)
    if kind == KIND_PARRY:
        spin = tilt * wp.randn(state)
    lean = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), flutter)
    turn = wp.quat_from_axis_angle(up, azimuth)
    return turn * lean * base * wp.quat_from_axis_angle(c_axis, spin), state


@wp.func
def enter_prism(origin: wp.vec3, direction: wp.vec3, half_length: float):
    """(distance, face) where the ray ``origin + t direction`` enters the prism; face -1 when it misses."""
    t_in = float(-1.0e30)
    t_out = float(1.0e30)
    entry_face = int(-1)
    for face in range(_FACE_COUNT):
        normal = face_normal(face)
        denom = wp.dot(normal, direction)
        gap = face_offset(face, half_length) - wp.dot(normal, origin)
        if denom < 0.0:
            hit = gap / denom
            if hit > t_in:
                t_in = hit
                entry_face = face
        elif denom > 0.0:
            t_out = wp.min(t_out, gap / denom)
        elif gap < 0.0:
            t_out = float(-1.0e30)  # parallel to a face and outside it
    if t_in >= t_out:
        entry_face = -1
    return t_in, entry_face


@wp.func
def leave_prism(position: wp.vec3, direction: wp.vec3, half_length: float):
    """(distance, face) to the face a ray inside the prism reaches next."""
    t_exit = float(1.0e30)
    exit_face = int(0)
    for face in range(_FACE_COUNT):
        normal = face_normal(face)
        denom = wp.dot(normal, direction)
        if denom > 0.0:
            hit = (face_offset(face, half_length) - wp.dot(normal, position)) / denom
            if hit < t_exit:
                t_exit = hit
                exit_face = face
    return wp.max(t_exit, 0.0), exit_face


@wp.func
def trace_photon(
    incident: wp.vec3, across_u: wp.vec3, across_v: wp.vec3, half_length: float, eta: float, cap: int,
    state: wp.uint32,
):
    """(fate, outgoing direction) of one photon sent along ``incident`` (crystal frame) at the prism.

    ``across_u``, ``across_v`` span the plane across the beam; the start point is uniform on the square of side
    2 R around the crystal, R = sqrt(1 + half_length^2). Fates: ``FATE_MISSED``, ``FATE_LEFT``, ``FATE_TRAPPED``.
    """
    bound = wp.sqrt(1.0 + half_length * half_length)
    s = (2.0 * wp.randf(state) - 1.0) * bound
    t = (2.0 * wp.randf(state) - 1.0) * bound
    origin = s * across_u + t * across_v - 2.0 * bound * incident
    t_in, entry_face = enter_prism(origin, incident, half_length)
    if entry_face < 0:
        return FATE_MISSED, incident

    # external interface: reflect away or refract in
    normal = face_normal(entry_face)
    cos_i = -wp.dot(incident, normal)
    inv_eta = 1.0 / eta
    cos_t = wp.sqrt(wp.max(1.0 - inv_eta * inv_eta * (1.0 - cos_i * cos_i), 0.0))
    if wp.randf(state) < fresnel_unpolarised(1.0, eta, cos_i, cos_t):
        return FATE_LEFT, reflect(incident, normal)
    direction = wp.normalize(inv_eta * incident + (inv_eta * cos_i - cos_t) * normal)
    position = origin + t_in * incident

    # internal interactions until the photon refracts out or meets the cap
    for _interaction in range(cap):
        t_exit, exit_face = leave_prism(position, direction, half_length)
        position = position + t_exit * direction
        normal = face_normal(exit_face)
        cos_i = wp.dot(direction, normal)
        sin_t2 = eta * eta * (1.0 - cos_i * cos_i)
        if sin_t2 >= 1.0:
            direction = reflect(direction, normal)  # total internal reflection
        else:
            cos_t = wp.sqrt(1.0 - sin_t2)
            if wp.randf(state) < fresnel_unpolarised(eta, 1.0, cos_i, cos_t):
                direction = reflect(direction, normal)
            else:
                return FATE_LEFT, wp.normalize(eta * direction + (cos_t - eta * cos_i) * normal)
    return FATE_TRAPPED, direction


@wp.func
def sky_bin(look: wp.vec3, grid: SkyGrid):
    """(elevation bin, azimuth bin) of a unit look direction given in the sun frame."""
    horizontal = wp.sqrt(look[0] * look[0] + look[2] * look[2])
    elevation = wp.atan2(look[1], horizontal)
    azimuth = wp.atan2(wp.abs(look[2]), look[0])
    row = int(wp.floor((elevation + _HALF_PI) / grid.elevation_step + 0.5))
    column = int(wp.floor(azimuth / grid.azimuth_step + 0.5))
    return wp.clamp(row, 0, grid.elevation_bins - 1), wp.clamp(column, 0, grid.azimuth_bins - 1)


@wp.kernel
def trace_oriented_kernel(
    trace: OrientedTrace,
    band: int,
    photon_offset: int,
    histogram: wp.array4d(dtype=wp.float64),
    tallies: wp.array3d(dtype=wp.int32),
):
    """Trace one photon; global index = photon_offset + tid, channel = index // photons_per_channel.

    Args:
        trace: The sun elevation, orientation law, crystal and grid.
        band: Histogram/tally row this launch writes (one per concurrent CPU launch).
        photon_offset: Global index of this launch's first photon.
        histogram: (bands, 3, elevation_bins, azimuth_bins) photons leaving per sky bin.
        tallies: (bands, 3, TALLY_COUNT) hit / miss / trapped counts.
    """
    gid = photon_offset + wp.tid()
    channel = gid // trace.photons_per_channel
    photon = gid - channel * trace.photons_per_channel
    state = wp.rand_init(trace.seed, gid)
    eta = trace.refractive_index[channel, photon % trace.refractive_index.shape[1]]

    rotation, state = sample_orientation(trace.kind, trace.tilt, state)
    sunlight = wp.vec3(-wp.cos(trace.sun_elevation), -wp.sin(trace.sun_elevation), 0.0)
    across = wp.vec3(0.0, 0.0, 1.0)
    incident = wp.quat_rotate_inv(rotation, sunlight)
    across_u = wp.quat_rotate_inv(rotation, across)
    across_v = wp.quat_rotate_inv(rotation, wp.cross(sunlight, across))

    fate, outgoing = trace_photon(incident, across_u, across_v, trace.half_length, eta, trace.max_interactions,
                                  state)
    if fate == FATE_MISSED:
        wp.atomic_add(tallies, band, channel, TALLY_MISSES, 1)
        return
    wp.atomic_add(tallies, band, channel, TALLY_HITS, 1)
    if fate == FATE_TRAPPED:
        wp.atomic_add(tallies, band, channel, TALLY_TRAPPED, 1)
        return
    row, column = sky_bin(-wp.quat_rotate(rotation, outgoing), trace.grid)
    wp.atomic_add(histogram, band, channel, row, column, wp.float64(1.0))
