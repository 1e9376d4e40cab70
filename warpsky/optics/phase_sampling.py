"""Phase sampling on the device: the tables kernels sample from (:class:`PhaseTables`), a medium's sampling density
whatever its model, and the rotation of a direction by a sampled angle. Each analytic model's evaluation, sampling
and density sit together in :mod:`warpsky.optics.phase`, a table's in :mod:`warpsky.optics.kernels`; the mixture
of every medium at a point is :mod:`warpsky.media.phase_mixture`.
"""

from __future__ import annotations

import warp as wp

from warpsky.optics.kernels import TABLE_KIND, DevicePhaseTables, table_pdf
from warpsky.optics.oriented_phase import OrientedPhases
from warpsky.optics.oriented_sampling import OrientedTables
from warpsky.optics.phase import phase_pdf

#: Oriented ice's continuation tables are sampled by one channel, green; the other channels' ratio to it is carried
#: by the sample's weight. Random-orientation tables are sampled by a path's hero channel (:func:`channel_row`).
SAMPLED_CHANNEL = wp.constant(1)


@wp.struct
class PhaseTables:
    """Flat phase tables and their cumulative tables on one device (one-value dummies without species)."""

    values: wp.array(dtype=float)
    cdf: wp.array(dtype=float)
    oriented: OrientedPhases  # the frame's oriented-ice slices, for the sun's light (count 0: none)
    continuation: OrientedTables  # oriented ice for any incoming direction, to continue paths (count 0: none)


def phase_tables_struct(tables: DevicePhaseTables, oriented: OrientedPhases | None = None,
                        continuation: OrientedTables | None = None) -> PhaseTables:
    """Kernel view of uploaded phase tables and of oriented ice: the frame's slices for the sun's light and the
    tables that continue paths (None: no oriented media)."""
    out = PhaseTables()
    out.values = tables.values
    out.cdf = tables.cdf
    if oriented is None:
        oriented = OrientedPhases()
        oriented.count = 0
    if continuation is None:
        continuation = OrientedTables()
        continuation.count = 0
    out.oriented = oriented
    out.continuation = continuation
    return out


@wp.func
def sampled_row(kind: int) -> int:
    """Row of the cumulative tables that phase kind ``kind`` (>= TABLE_KIND) is sampled from."""
    return (kind - TABLE_KIND) * 3 + SAMPLED_CHANNEL


@wp.func
def channel_row(kind: int, channel: int) -> int:
    """Row of the cumulative tables of phase kind ``kind`` (>= TABLE_KIND) for colour channel ``channel``."""
    return (kind - TABLE_KIND) * 3 + channel


@wp.func
def medium_pdf3(cdf: wp.array(dtype=float), kind: int, g: float, theta: float) -> wp.vec3:
    """Sampling density [1/sr] at ``theta`` of one medium's phase sampling by each colour channel as the hero: a
    table's three rows, an analytic model's one density in every channel."""
    if kind >= TABLE_KIND:
        return wp.vec3(table_pdf(cdf, channel_row(kind, 0), theta), table_pdf(cdf, channel_row(kind, 1), theta),
                       table_pdf(cdf, channel_row(kind, 2), theta))
    return wp.vec3(phase_pdf(kind, g, wp.cos(theta)))


@wp.func
def medium_pdf(cdf: wp.array(dtype=float), kind: int, g: float, theta: float) -> float:
    """Sampling density [1/sr] at ``theta`` of one medium's phase sampling: its table's (sampled by the green
    row), or its analytic model's."""
    if kind >= TABLE_KIND:
        return table_pdf(cdf, sampled_row(kind), theta)
    return phase_pdf(kind, g, wp.cos(theta))


@wp.func
def rotate_about(d: wp.vec3, cos_theta: float, phi: float) -> wp.vec3:
    """The direction at angle acos(cos_theta) from unit ``d`` with azimuth ``phi``."""
    helper = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(d[0]) > 0.9:
        helper = wp.vec3(0.0, 1.0, 0.0)
    u = wp.normalize(wp.cross(helper, d))
    v = wp.cross(d, u)
    sin_theta = wp.sqrt(wp.max(1.0 - cos_theta * cos_theta, 0.0))
    return wp.normalize(d * cos_theta + (u * wp.cos(phi) + v * wp.sin(phi)) * sin_theta)
