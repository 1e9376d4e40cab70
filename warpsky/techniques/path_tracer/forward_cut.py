"""Paths that treat the media's forward diffraction peak as no scattering after their first event.

A cloud droplet's phase function puts about 43 % of its scattering within 3 deg of straight ahead (ice 61 %, rain
51 %: :func:`warpsky.optics.multiple.forward_cut`). In next-event estimation that peak is a heavy tail: the rare
event whose direction lies within a degree of the sun's gets a phase of up to 800 per steradian (10^4 times an
isotropic one's), so in an optically thick Mie cloud those events carry much of the light from a tiny share of the
paths, and a pixel's noise does not fall below its mean for thousands of paths. Light deflected by less than a few
degrees has barely moved, so after its first event a path continues through *cut* media (the delta-M idea,
Wiscombe 1977; a first-order similarity relation, Zhao et al. 2014, that keeps every angle above the cut exact):
scattering
sigma_s (1 - f), extinction sigma_t - f sigma_s, the phase with its peak flattened to its value at the cut. Its
flights, shadow rays and phase sampling there are those of ordinary media (:class:`CutMedia` holds the same
values with other coefficients, tables and majorants).

The first flight and the first event stay exact, so the camera's view of the media and everything single
scattering depends on are unchanged. What the cut media count as direct sunlight at later events (light scattered
into the peak on its way) is light of an extra order in the exact media; at the first event the exact NEE takes the
sun through the exact media, so the path adds the sun through the cut media *minus* that
(:func:`first_event_peak_light`): the sunlight that reaches the first event through peak scatterings only, which
a single-scattering march (hybrid's, exact) leaves out too. Both transmittances are ratio-tracked on one ray, so
their difference is never negative. Tabulated species are cut; analytic phases
(Henyey-Greenstein, isotropic, Rayleigh) are not, and a frame with oriented ice is not cut at all.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import warp as wp

from warpsky.light.sun import Sun
from warpsky.media.air.medium import Air, air_part, no_air
from warpsky.media.phase_mixture import mixture_functions
from warpsky.media.voxels.voxel import VoxelMedia, media_functions
from warpsky.model.scene import VoxelMedium
from warpsky.optics.kernels import scattering_angle
from warpsky.optics.multiple import forward_cut
from warpsky.optics.phase_sampling import PhaseTables
from warpsky.optics.tables import phase_table
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.majorants import Majorants
from warpsky.techniques.path_tracer.planet import air_to_sun, ground_cosine
from warpsky.techniques.path_tracer.ray_ends import UNBOUNDED
from warpsky.techniques.path_tracer.tracking import ROULETTE_TRANSMITTANCE, media_sums, next_collision, positive


@wp.struct
class CutMedia:
    """The media a path continues through after its first event (the exact ones when paths are not cut)."""

    media: VoxelMedia
    majorants: Majorants


@wp.struct
class PeakLight:
    """What :func:`first_event_peak_light` adds to a path: light, shadow-ray steps, the advanced random stream."""

    radiance: wp.vec3
    steps: int
    state: wp.uint32


@dataclasses.dataclass(frozen=True)
class CutTables:
    """Host side of a cut: the truncated tables appended after the species' own, and each species' peak share."""

    phase: np.ndarray  # (2 S, 3, M): the species' tables, then the same species cut
    fraction: np.ndarray  # (S, 3): f per species and channel


def cut_tables(species: tuple[str, ...], phase: np.ndarray, cut_deg: float) -> CutTables:
    """The species' ``phase`` tables (S, 3, M) followed by their cut versions at ``cut_deg`` degrees."""
    pairs = [forward_cut(phase[i], math.radians(cut_deg)) for i in range(len(species))]
    cut = np.stack([p for p, _ in pairs]) if pairs else np.zeros_like(phase)
    fraction = np.stack([f for _, f in pairs]) if pairs else np.zeros((0, 3))
    return CutTables(np.concatenate([phase, cut]), fraction)


def cut_medium(medium: VoxelMedium, species: tuple[str, ...], fraction: np.ndarray) -> VoxelMedium:
    """``medium`` with the coefficients of its cut (unchanged for analytic phases and oriented ice): extinction
    sigma_t (1 - f albedo), albedo albedo (1 - f) / (1 - f albedo)."""
    if medium.species is None or (medium.ice is not None and medium.ice.orientation != "random"):
        return medium
    f = fraction[species.index(medium.species)]
    albedo = np.asarray(medium.albedo, dtype=np.float64)
    kept = 1.0 - f * albedo
    return dataclasses.replace(medium, extinction_scale=np.asarray(medium.extinction_scale) * kept,
                               albedo=np.where(kept > 0.0, albedo * (1.0 - f) / np.maximum(kept, 1e-30), 0.0))


def check_cut_settings(cut_deg: float, similarity_order: int) -> None:
    """A UsageError naming both settings when the cut and high-order similarity are both set: they reduce the
    media two ways."""
    if cut_deg > 0.0 and similarity_order > 0:
        from warpsky.core.errors import UsageError

        raise UsageError("settings forward_cut and similarity_order reduce the media two ways; set one of them "
                         f"(got forward_cut={cut_deg:g}, similarity_order={similarity_order})")


def cuts(scene, cut_deg: float) -> bool:
    """Whether paths continue through cut media: a cut is set, a species is tabulated, and no ice is oriented (its
    phase at the first event and its continuation tables are not cut)."""
    from warpsky.optics.oriented_phase import oriented_media

    return cut_deg > 0.0 and bool(scene.species) and not oriented_media(scene.media)


def cut_feature(scene, cut_deg: float, features: dict[str, str]) -> dict[str, str]:
    """``features`` with warpsky info's ``forward cut`` line for a scene with tabulated species: the cut and each
    species' peak share f (from tables already cached; the others say so), or why paths are exact."""
    from warpsky.optics.tables import is_cached

    if not scene.species:
        return features
    if cut_deg <= 0.0:
        line = "off: paths scatter by the exact tables"
    elif not cuts(scene, cut_deg):
        line = f"off (set to {cut_deg:g} deg): the frame has oriented ice"
    else:
        shares = []
        for name in scene.species:
            if is_cached(name):
                f = forward_cut(phase_table(name), math.radians(cut_deg))[1]
                shares.append(f"{name} f {float(np.mean(f)):.2f}")
            else:
                shares.append(f"{name} (f once its table is built)")
        line = (f"{cut_deg:g} deg after each path's first event, peaks treated as unscattered (delta-M): "
                f"{', '.join(shares)}; forward_cut=0 for exact paths")
    return {**features, "forward cut": line}


@functools.cache
def peak_light_function(has_tables: bool, has_detail: bool):
    """``first_event_peak_light(media, majorants, cut, tables, air, sun, ground, throughput, direction, p,
    on_ground, state) -> PeakLight``, specialised like the path tracer's kernels."""
    sample_media = media_functions(has_detail)
    mixture_phase = mixture_functions(has_tables)[0]

    @wp.func
    def peak_transmittance(media: VoxelMedia, majorants: Majorants, cut: CutMedia, p: wp.vec3, d: wp.vec3,
                           state: wp.uint32) -> PeakLight:
        """Ratio tracking of the exact and the cut media's transmittance from ``p`` along ``d`` on one ray, with
        the exact media's majorants (which bound the cut extinction too): at every tentative collision both
        estimates take their own factor 1 - sigma_t / majorant. The cut's extinction is never above the exact
        one's, so ``radiance`` = cut - exact is never negative; Russian roulette on the cut estimate below
        ``ROULETTE_TRANSMITTANCE`` keeps both unbiased."""
        exact = wp.vec3(1.0)
        through_cut = wp.vec3(1.0)
        t = float(0.0)
        steps = int(0)
        found = int(1)
        while found != 0:
            hit = next_collision(media, majorants, no_air(), p, d, t, UNBOUNDED, steps, state, 0)
            t = hit.t
            steps = hit.steps
            state = hit.state
            found = hit.found
            if found != 0:
                point = sample_media(media, p + t * d)
                reduced = media_sums(cut.media, point, wp.vec3(0.0), wp.vec3(0.0), 0).extinction
                exact = wp.cw_mul(exact, positive(wp.vec3(1.0) - point.extinction / hit.majorant))
                through_cut = wp.cw_mul(through_cut, positive(wp.vec3(1.0) - reduced / hit.majorant))
                largest = wp.max(through_cut)
                if largest < ROULETTE_TRANSMITTANCE:
                    q = largest / ROULETTE_TRANSMITTANCE
                    if wp.randf(state) >= q:
                        through_cut = wp.vec3(0.0)
                        exact = wp.vec3(0.0)
                        break
                    through_cut = through_cut / q
                    exact = exact / q
        out = PeakLight()
        out.radiance = positive(through_cut - exact)
        out.steps = steps
        out.state = state
        return out

    @wp.func
    def first_event_peak_light(media: VoxelMedia, majorants: Majorants, cut: CutMedia, tables: PhaseTables,
                               air: Air, sun: Sun, ground: Ground, throughput: wp.vec3, direction: wp.vec3,
                               p: wp.vec3, on_ground: int, state: wp.uint32) -> PeakLight:
        """The sunlight a path's first event at ``p`` gets through peak scatterings alone: the sun through the
        cut media minus through the exact ones (:func:`peak_transmittance`, times the air's transmittance in
        closed form), times the exact phase towards ``direction`` (or the ground's Lambertian reflection)."""
        out = peak_transmittance(media, majorants, cut, p, sun.direction, state)
        gained = wp.cw_mul(wp.cw_mul(sun.irradiance, out.radiance), air_to_sun(air, sun, p))
        out.radiance = wp.vec3(0.0)
        if on_ground != 0:
            if ground.enabled != 0:
                out.radiance = wp.cw_mul(wp.cw_mul(throughput, ground.albedo), gained) * (
                    ground_cosine(air, sun, p) / wp.pi)
        else:
            point = sample_media(media, p)
            phase = mixture_phase(media, point, tables.values, air_part(air, p),
                                  scattering_angle(sun.direction, direction))
            out.radiance = wp.cw_mul(wp.cw_mul(throughput, phase), gained)
        return out

    return first_event_peak_light
