"""Geometric-optics Monte Carlo of hexagonal ice prisms: one thread per photon, CPU and CUDA alike.

The crystal sits in its own frame: c-axis along z, circumradius of the hexagon 1 (so the diameter across corners is
2), half length ``half_length`` (= length / diameter for that unit). Its 8 faces are planes ``dot(normal, x) =
offset``: 6 prism sides with outward normals at azimuths 30° + k 60° and offset cos 30° (the apothem), and the two
basal faces ``z = ±half_length``. Geometric optics is scale-free, so only the aspect ratio matters here.

Each photon:

1. draws a uniform random rotation (a unit quaternion of four normal deviates) that carries the incident direction
   +z and two axes perpendicular to it into the crystal frame, or uses the fixed rotation given;
2. starts on a uniform random point of a square of side 2 R (R the radius of the crystal's bounding sphere)
   perpendicular to the incident direction, so that it hits the crystal with probability proportional to the
   crystal's projected area; misses are tallied, never re-drawn, so nothing is biased;
3. at every interface takes Fresnel's reflectance for unpolarised light, R = (r_s^2 + r_p^2) / 2, and reflects with
   probability R, else refracts (weight stays 1); total internal reflection when sin(theta_t) >= 1;
4. leaves after at most ``max_interactions`` internal face hits; a photon still inside then is tallied as trapped
   (its energy is left out of the phase function; ``ice_optics`` reports the fraction).

Ice absorbs nothing that matters at visible wavelengths (imaginary index ~1e-9, absorption length of metres), so
no absorption is modelled. The deflection angle theta between incident and outgoing direction, taken as
atan2(|a x b|, a . b), is deposited on a uniform histogram of ``BIN_DEG`` nodes with linear (tent) weights, so that
histogram / (photons x node solid angle) is a piecewise linear density with exactly the photons' integral. The
weights are multiples of 2^-16, so the float64 sums are exact and a seed gives the same histogram on every device.

Histogram rows are (band, channel, node): concurrent CPU launches each own a band, and the host sums bands.
"""

from __future__ import annotations

import math

import warp as wp

wp.set_module_options({"enable_backward": False})

#: Spacing [deg] of the histogram's nodes (0, 0.1, ..., 180 deg); each node is also a node of the shared grid.
BIN_DEG = 0.1
#: Number of histogram nodes.
NODE_COUNT = int(round(180.0 / BIN_DEG)) + 1
#: Tally columns: photons that hit the crystal, missed it, and were still inside after the interaction cap.
TALLY_HITS = 0
TALLY_MISSES = 1
TALLY_TRAPPED = 2
TALLY_COUNT = 3

_NODE_COUNT = wp.constant(NODE_COUNT)
_NODES_PER_RAD = wp.constant(180.0 / (math.pi * BIN_DEG))
_APOTHEM = wp.constant(math.cos(math.pi / 6.0))
_FACE_COUNT = wp.constant(8)


@wp.func
def face_normal(face: int) -> wp.vec3:
    """Outward unit normal of face 0-5 (prism sides) or 6, 7 (basal faces +z, -z)."""
    if face == 6:
        return wp.vec3(0.0, 0.0, 1.0)
    if face == 7:
        return wp.vec3(0.0, 0.0, -1.0)
    azimuth = (float(face) + 0.5) * (wp.pi / 3.0)
    return wp.vec3(wp.cos(azimuth), wp.sin(azimuth), 0.0)


@wp.func
def face_offset(face: int, half_length: float) -> float:
    """Distance of the face's plane from the crystal centre (circumradius 1)."""
    if face >= 6:
        return half_length
    return _APOTHEM


@wp.func
def fresnel_unpolarised(n1: float, n2: float, cos_i: float, cos_t: float) -> float:
    """Reflectance (r_s^2 + r_p^2) / 2 of light from index n1 into n2 with the given angle cosines."""
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return 0.5 * (rs * rs + rp * rp)


@wp.func
def reflect(d: wp.vec3, normal: wp.vec3) -> wp.vec3:
    return wp.normalize(d - 2.0 * wp.dot(d, normal) * normal)


@wp.func
def deflection_angle(a: wp.vec3, b: wp.vec3) -> float:
    """Angle [rad] between unit vectors a and b, accurate near 0 and pi."""
    return wp.atan2(wp.length(wp.cross(a, b)), wp.dot(a, b))


@wp.func
def deposit(histogram: wp.array3d(dtype=wp.float64), band: int, channel: int, theta: float):
    """Add one photon at deflection theta [rad] to the two nearest nodes with linear weights."""
    u = wp.clamp(theta * _NODES_PER_RAD, 0.0, float(_NODE_COUNT - 1))
    node = wp.min(int(u), _NODE_COUNT - 2)
    # weights on a 2^-16 lattice: float64 sums of them are exact, so atomics in any order give the same histogram
    frac = wp.float64(int((u - float(node)) * 65536.0)) / wp.float64(65536.0)
    wp.atomic_add(histogram, band, channel, node, wp.float64(1.0) - frac)
    wp.atomic_add(histogram, band, channel, node + 1, frac)


#: What became of a photon (:func:`trace_photon`).
FATE_MISSED = 0
FATE_LEFT = 1
FATE_TRAPPED = 2


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


@wp.kernel
def trace_prisms_kernel(
    seed: int,
    photons_per_channel: int,
    half_length: float,
    refractive_index: wp.array2d(dtype=float),
    max_interactions: int,
    random_orientation: int,
    fixed_rotation: wp.quat,
    band: int,
    histogram: wp.array3d(dtype=wp.float64),
    tallies: wp.array3d(dtype=wp.int32),
    photon_offset: int,
):
    """Trace one photon; global photon index = photon_offset + tid, channel = index // photons_per_channel.

    Args:
        seed: Random seed; a photon's random stream depends only on (seed, global photon index).
        photons_per_channel: Photons launched per channel, hits and misses together.
        half_length: Half the prism length for circumradius 1 (= length / diameter).
        refractive_index: (3, samples) real refractive index per channel and sample wavelength; photon i of a
            channel uses sample i mod samples (stratified).
        max_interactions: Internal face hits after which a photon still inside counts as trapped.
        random_orientation: 1 for a uniform random rotation per photon, 0 for ``fixed_rotation``.
        fixed_rotation: Crystal-from-world rotation used when ``random_orientation`` is 0.
        band: Histogram/tally row this launch writes (one per concurrent CPU launch).
        histogram: (bands, 3, NODE_COUNT) tent-weighted photon counts per deflection node.
        tallies: (bands, 3, TALLY_COUNT) hit / miss / trapped counts.
        photon_offset: Global index of this launch's first photon.
    """
    gid = photon_offset + wp.tid()
    channel = gid // photons_per_channel
    photon = gid - channel * photons_per_channel
    state = wp.rand_init(seed, gid)
    eta = refractive_index[channel, photon % refractive_index.shape[1]]

    rotation = fixed_rotation
    if random_orientation != 0:
        rotation = wp.normalize(wp.quat(wp.randn(state), wp.randn(state), wp.randn(state), wp.randn(state)))
    incident = wp.quat_rotate(rotation, wp.vec3(0.0, 0.0, 1.0))
    across_u = wp.quat_rotate(rotation, wp.vec3(1.0, 0.0, 0.0))
    across_v = wp.quat_rotate(rotation, wp.vec3(0.0, 1.0, 0.0))
    fate, outgoing = trace_photon(incident, across_u, across_v, half_length, eta, max_interactions, state)
    if fate == FATE_MISSED:
        wp.atomic_add(tallies, band, channel, TALLY_MISSES, 1)
        return
    wp.atomic_add(tallies, band, channel, TALLY_HITS, 1)
    if fate == FATE_LEFT:
        deposit(histogram, band, channel, deflection_angle(incident, outgoing))
    else:
        wp.atomic_add(tallies, band, channel, TALLY_TRAPPED, 1)
