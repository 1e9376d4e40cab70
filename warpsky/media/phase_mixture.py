"""The phase of the media mixed at a point, on the device (Riley 2004, Eq. 6): the scattering-weighted phase sum of
every medium, the mixture's phase and its two-stage sampling, and what oriented ice changes in them.

A scattering point holds several media (and the air), each with its own phase function. The path tracer samples
the mixture in two stages: it picks one component with probability proportional to its mean scattering
coefficient, then samples that component's phase (Henyey–Greenstein by exact inversion, tables by their inverse
CDF, isotropic and Rayleigh uniformly: :mod:`warpsky.optics.phase`, :mod:`warpsky.optics.kernels`). The sample's
weight is the mixture's phase (the scattering-weighted phase of all components, per channel) over the mixture's
pdf (the weighted sum of every component's sampling density), so the estimate is unbiased whatever the component
picked.

Tabulated phases differ per colour channel (a droplet's diffraction peak and rainbow move with wavelength). A
path samples them by one *hero* channel drawn at its start, and is weighted by the balance heuristic over the
three channels as heroes (spectral MIS, Wilkie et al. 2014, "Hero wavelength spectral sampling"): every channel's
throughput is divided by the mean over heroes of the whole path's direction densities, kept as their ratios to
the largest (``PhaseSample.ratio``). Sampling by one fixed channel instead weights the others by the product of
their phase ratios over every event, which in a cloud of optical depth 100 (hundreds of events) has a heavy tail:
coloured fireflies; with the heroes mixed the phase's part of a path's weight stays below 3.
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.core.numerics import mean3
from warpsky.media.air.medium import AirPart, part_pdf, part_phase, part_sample_cos, part_total
from warpsky.media.voxels.voxel import MediaPoint, VoxelMedia
from warpsky.optics.kernels import TABLE_KIND, medium_phase, sample_table, scattering_angle
from warpsky.optics.oriented_phase import OrientedPhases, oriented_value
from warpsky.optics.oriented_sampling import directional_sample, directional_value
from warpsky.optics.phase import (
    phase_eval,
    phase_pdf,
    phase_sample_cos,
)
from warpsky.optics.phase_sampling import (
    SAMPLED_CHANNEL,
    PhaseTables,
    channel_row,
    medium_pdf3,
    rotate_about,
)


@wp.func
def per_unit_scattering(point: MediaPoint, air_s: AirPart, value: wp.vec3) -> wp.vec3:
    """``value`` [1/(m sr)] divided by the scattering coefficient at ``point``, the media's plus the air's
    ``air_s``, per channel (0 where nothing scatters): a sum over components in Riley Eq. 6 made a phase [1/sr]."""
    total = part_total(air_s) + point.scattering
    out = wp.vec3(0.0)
    for c in range(3):
        if total[c] > 0.0:
            out[c] = value[c] / total[c]
    return out


@wp.func
def oriented_slice(point: MediaPoint, phases: OrientedPhases, m: int) -> int:
    """The frame's oriented slice of medium ``m`` where it is present at ``point``; -1 where it is absent or its
    crystals are randomly oriented."""
    if point.density[m] > 0.0:
        return phases.slice_of[m]
    return -1


def oriented_correction_function(sample_phase):
    """``(oriented_correction, oriented_mixture_correction)``.

    ``oriented_correction(media, point, tables, phases, look, theta) -> vec3``: what the oriented media at
    ``point`` add to the scattering-weighted phase sum sum_m sigma_s,m P_m(theta) [1/(m sr)] of the techniques,
    sum over oriented media of sigma_s,m (P_slice(look) - P_m(theta)); zero when no medium is oriented.
    ``sample_phase(tables, kind, g, theta)`` is the phase the caller's sum used for a medium."""
    @wp.func
    def oriented_correction(media: VoxelMedia, point: MediaPoint, tables: wp.array(dtype=float),
                            phases: OrientedPhases, look: wp.vec3, theta: float) -> wp.vec3:
        out = wp.vec3(0.0)
        if phases.count == 0:
            return out
        for m in range(media.count):
            index = oriented_slice(point, phases, m)
            if index >= 0:
                value = point.density[m]
                grid = media.grids[m]
                difference = oriented_value(phases, index, look) - sample_phase(tables, grid.phase_kind,
                                                                                grid.phase_g, theta)
                out += wp.cw_mul(grid.scattering * value, difference)
        return out

    @wp.func
    def oriented_mixture_correction(media: VoxelMedia, point: MediaPoint, tables: wp.array(dtype=float),
                                    phases: OrientedPhases, air_s: AirPart, look: wp.vec3,
                                    theta: float) -> wp.vec3:
        """The same for a mixture phase (Riley Eq. 6, normalised by the summed scattering, the air's ``air_s``
        included): the correction divided by that sum [1/sr]."""
        if phases.count == 0:
            return wp.vec3(0.0)
        return per_unit_scattering(point, air_s, oriented_correction(media, point, tables, phases, look, theta))

    return oriented_correction, oriented_mixture_correction


@wp.struct
class PhaseSample:
    direction: wp.vec3
    weight: wp.vec3  # combined phase / sampling pdf, per channel (divided by the heroes' mean path density)
    ratio: wp.vec3  # the path's direction densities with each channel as hero, over their largest
    density: float  # the density [1/sr] the direction was drawn with (over the heroes, weighted by ``ratio``)
    state: wp.uint32


@wp.struct
class MixtureDensity:
    """The mixture's phase toward a direction and the density the path's sampling draws it with."""

    phase: wp.vec3  # Riley Eq. 6 [1/sr], oriented ice's terms included
    density: float  # [1/sr]: with tables, the heroes' densities weighted by the path's ratios, over their mean
    inverse: float  # with tables, 1 / density as the sample's weight takes it: the ratios' mean over their mixture
    ratio: wp.vec3  # the path's ratios after this direction (with tables; unchanged without)


@wp.struct
class ContinuationTerms:
    phase: wp.vec3  # sum of scattering_m (T_m(-d, -s) - P_m(theta)) per channel [1/(m sr)]
    pdf: wp.vec3  # sum of mean scattering_m (T_m green - the table's density with each channel as hero)


@wp.func
def continuation_terms(media: VoxelMedia, point: MediaPoint, tables: PhaseTables, d: wp.vec3, s: wp.vec3,
                       theta: float) -> ContinuationTerms:
    """What oriented ice changes in a continued path's mixture, for light from ``s`` scattered along ``d``, over
    the oriented media m at ``point``: their random table replaced by the oriented one in the phase and in the
    sampling density (oriented tables are sampled by green whichever the hero)."""
    out = ContinuationTerms()
    out.phase = wp.vec3(0.0)
    out.pdf = wp.vec3(0.0)
    for m in range(media.count):
        value = point.density[m]
        index = tables.continuation.table_of[m]
        if value > 0.0 and index >= 0:
            grid = media.grids[m]
            oriented = directional_value(tables.continuation, index, -d, -s)
            out.phase += wp.cw_mul(grid.scattering * value, oriented - medium_phase(tables.values, grid.phase_kind,
                                                                                   grid.phase_g, theta))
            random = medium_pdf3(tables.cdf, grid.phase_kind, grid.phase_g, theta)
            out.pdf += (wp.vec3(oriented[SAMPLED_CHANNEL]) - random) * (mean3(grid.scattering) * value)
    return out


@functools.cache
def phase_sum_function(has_tables: bool):
    """``scattered_phase(media, point, tables, start, theta) -> vec3``: ``start`` plus the sum over the media at
    ``point`` of scattering_i P_i(theta) [1/(m sr)], in medium order (Riley Eq. 6 before dividing by the summed
    scattering); ``tables`` are the flat phase tables, ``theta`` the scattering angle [rad]. Specialised on whether
    any medium uses a phase table (without, ``tables`` is never read). It reads no grid: the densities come from
    ``point``."""

    @wp.func
    def scattered_phase(media: VoxelMedia, point: MediaPoint, tables: wp.array(dtype=float), start: wp.vec3,
                        theta: float) -> wp.vec3:
        out = start
        for m in range(media.count):
            value = point.density[m]
            if value > 0.0:
                grid = media.grids[m]
                phase = wp.vec3(0.0)
                if wp.static(has_tables):
                    phase = medium_phase(tables, grid.phase_kind, grid.phase_g, theta)
                else:
                    phase = wp.vec3(phase_eval(grid.phase_kind, grid.phase_g, wp.cos(theta)))
                out += wp.cw_mul(grid.scattering * value, phase)
        return out

    return scattered_phase


@functools.cache
def mixture_phase_function(has_tables: bool):
    """``mixture_phase(media, point, tables, air_s, theta) -> vec3`` (see :func:`mixture_functions`)."""

    scattered_phase = phase_sum_function(has_tables)

    @wp.func
    def mixture_phase(media: VoxelMedia, point: MediaPoint, tables: wp.array(dtype=float), air_s: AirPart,
                      theta: float) -> wp.vec3:
        """Riley Eq. 6: the scattering-weighted phase [1/sr] at scattering angle ``theta`` of the air's
        constituents (scattering ``air_s``) and every medium at ``point``, summed in that order."""
        num = scattered_phase(media, point, tables, part_phase(air_s, wp.cos(theta)), theta)
        den = part_total(air_s)
        for m in range(media.count):
            value = point.density[m]
            if value > 0.0:
                den += media.grids[m].scattering * value
        out = wp.vec3(0.0)
        for c in range(3):
            if den[c] > 0.0:
                out[c] = num[c] / den[c]
        return out

    return mixture_phase


@wp.func
def chosen_medium(media: VoxelMedia, point: MediaPoint, air_weight: float, target: float) -> int:
    """The medium picked by ``target`` in [0, total) of the mean scattering [1/m] at ``point`` laid out air first
    (``air_weight``), then the media in order (clamped to the media; the caller checks the air)."""
    chosen = int(0)
    running = air_weight
    for m in range(media.count):
        running += mean3(media.grids[m].scattering) * point.density[m]
        if running < target:
            chosen = m + 1
    return wp.clamp(chosen, 0, wp.max(media.count - 1, 0))


@functools.cache
def mixture_density_function(has_tables: bool):
    """``mixture_density(media, point, tables, air_s, d, direction, ratio) -> MixtureDensity`` (see
    :func:`mixture_functions`)."""

    mixture_phase = mixture_phase_function(has_tables)

    @wp.func
    def mixture_density(media: VoxelMedia, point: MediaPoint, tables: PhaseTables, air_s: AirPart, d: wp.vec3,
                        direction: wp.vec3, ratio: wp.vec3) -> MixtureDensity:
        """The mixture's phase from ``d`` into ``direction`` and the density with which :func:`sample_mixture` draws
        it: the components' densities weighted by their mean scattering (with tables, each channel's as hero
        weighted by the path's ``ratio`` and divided by their mean, the balance heuristic's combined density), so
        ``phase / density`` is the sample's weight."""
        theta = scattering_angle(d, direction)
        out = MixtureDensity()
        out.ratio = ratio
        out.density = 0.0
        out.inverse = 0.0
        total = mean3(part_total(air_s))
        for m in range(media.count):
            total += mean3(media.grids[m].scattering) * point.density[m]
        if wp.static(has_tables):
            pdf3 = wp.vec3(part_pdf(air_s, wp.cos(theta)))
            for m in range(media.count):
                grid = media.grids[m]
                w = mean3(grid.scattering) * point.density[m]
                if w > 0.0:
                    pdf3 += medium_pdf3(tables.cdf, grid.phase_kind, grid.phase_g, theta) * w
            out.phase = mixture_phase(media, point, tables.values, air_s, theta)
            if tables.continuation.count > 0:
                terms = continuation_terms(media, point, tables, d, direction, theta)
                pdf3 += terms.pdf
                out.phase += per_unit_scattering(point, air_s, terms.phase)
            path_pdf = wp.cw_mul(ratio, wp.max(pdf3, wp.vec3(0.0)) / wp.max(total, 1.0e-30))
            mixed = mean3(path_pdf)
            if mixed > 0.0:
                out.density = mixed / mean3(ratio)
                out.inverse = mean3(ratio) / mixed
                out.ratio = path_pdf / wp.max(wp.max(path_pdf[0], path_pdf[1]), path_pdf[2])
        else:
            pdf = part_pdf(air_s, wp.cos(theta))
            for m in range(media.count):
                grid = media.grids[m]
                w = mean3(grid.scattering) * point.density[m]
                if w > 0.0:
                    pdf += w * phase_pdf(grid.phase_kind, grid.phase_g, wp.cos(theta))
            out.density = pdf / wp.max(total, 1.0e-30)
            out.phase = mixture_phase(media, point, tables.values, air_s, theta)
        return out

    return mixture_density


@functools.cache
def mixture_functions(has_tables: bool):
    """``(mixture_phase, sample_mixture, mixture_density)`` over the media at a point plus the air's components
    (zero scattering for none), specialised on whether any medium uses a phase table."""

    mixture_phase = mixture_phase_function(has_tables)
    mixture_density = mixture_density_function(has_tables)

    @wp.func
    def sample_mixture(media: VoxelMedia, point: MediaPoint, tables: PhaseTables, air_s: AirPart, d: wp.vec3,
                       hero: int, ratio: wp.vec3, state: wp.uint32) -> PhaseSample:
        """New direction after scattering at ``point`` from direction ``d``: pick one of the air's constituents or a
        medium by mean scattering, sample its phase (Rayleigh: uniformly; aerosols: Henyey-Greenstein; a table by
        the path's ``hero`` channel), weight by the mixture's phase over the mixture's pdf (with tables: over the
        path's density ratios ``ratio`` mixed over the heroes, see the module docstring). Three random draws: the
        component, cos θ, the azimuth."""
        air_w = mean3(part_total(air_s))
        total = air_w
        for m in range(media.count):
            total += mean3(media.grids[m].scattering) * point.density[m]
        target = wp.randf(state) * total
        use_air = target < air_w or media.count == 0
        chosen = chosen_medium(media, point, air_w, target)
        u = wp.randf(state)
        cos_theta = part_sample_cos(air_s, target, u)
        oriented = int(-1)
        if not use_air:
            grid = media.grids[chosen]
            if grid.phase_kind >= TABLE_KIND:
                if wp.static(has_tables):
                    cos_theta = wp.cos(sample_table(tables.cdf, channel_row(grid.phase_kind, hero), u)[0])
                    if tables.continuation.count > 0:
                        oriented = tables.continuation.table_of[chosen]
            else:
                cos_theta = phase_sample_cos(grid.phase_kind, grid.phase_g, u)
        out = PhaseSample()
        out.direction = rotate_about(d, cos_theta, 2.0 * wp.pi * wp.randf(state))
        out.ratio = ratio
        if wp.static(has_tables):
            if oriented >= 0:  # oriented ice: its table for light arriving along d (six more draws)
                source, state = directional_sample(tables.continuation, oriented, d, state)
                out.direction = source
        out.state = state
        found = mixture_density(media, point, tables, air_s, d, out.direction, ratio)
        out.ratio = found.ratio
        out.density = found.density
        out.weight = wp.vec3(0.0)
        if found.density > 0.0:
            if wp.static(has_tables):
                out.weight = wp.max(found.phase, wp.vec3(0.0)) * found.inverse
            else:
                out.weight = wp.max(found.phase, wp.vec3(0.0)) / found.density
        return out

    return mixture_phase, sample_mixture, mixture_density
