"""The sun lobe: a second way to reach the next scattering event, for the sunlight it sends back.

Where a path scatters in a forward-scattering medium, the sunlight its *next* event sends back along the path is
large only where the path's new direction points nearly at the sun: the phase there peaks 82 times over its mean
for Henyey-Greenstein g = 0.85 (and far more for a droplet's table). A direction drawn from the phase at this event
rarely falls in that lobe when the sun is to the side of or behind the path, so a side- or back-lit cloud's light
arrives in rare bright paths: a heavy tail, fireflies that a denoiser keeps or smears.

So at each of its scattering events a path also draws one direction from a Henyey-Greenstein lobe around the sun
(``PathState.lobe_g``), flies it to its next event by delta tracking, exactly as the path's own flight, and takes
the sunlight there. The two directions share that sunlight by the balance heuristic (Veach and Guibas 1995, "Optimally
combining sampling techniques for Monte Carlo rendering"): the path's own next event keeps
``pdf_phase / (pdf_phase + pdf_lobe)`` of its sunlight (:func:`~warpsky.techniques.path_tracer.events.
direction_share`), the lobe's flight brings ``phase / (pdf_phase + pdf_lobe)`` times its sunlight. Each part is
then bounded by the smaller of the two lobes, and their sum is unbiased for any lobe. The lobe's flight ends at its
event; it changes nothing the path does afterwards. Light from the ground, meshes and the analytic fogs, and events
after high-order similarity, take no lobe (their paths keep all of their sunlight).
"""

from __future__ import annotations

import functools

import warp as wp

from warpsky.light.sun import Sun
from warpsky.media.air.medium import Air, air_part, scaled_part
from warpsky.media.phase_mixture import mixture_functions
from warpsky.media.voxels.voxel import VoxelMedia, media_functions
from warpsky.model.scene import PhaseKind, Scene
from warpsky.optics.phase import hg_sample_cos, phase_hg
from warpsky.optics.phase_sampling import PhaseTables, rotate_about
from warpsky.surfaces.plane import Ground
from warpsky.techniques.path_tracer.events import NO_LOBE, PathState, sunlight_function
from warpsky.techniques.path_tracer.majorants import Majorants
from warpsky.techniques.path_tracer.ray_ends import RayEnd, flight_end
from warpsky.techniques.path_tracer.tracking import tracking_functions


@wp.struct
class LobeLight:
    """What the sun lobe's flight from one event brought: its light, its tracking steps, the advanced state."""

    radiance: wp.vec3
    steps: int
    shadow_steps: int
    state: wp.uint32


@functools.cache
def sun_lobe_function(has_tables: bool, has_detail: bool):
    """``sun_lobe_light(here, media, majorants, tables, air, sun, ground, path, p, air_weight, bounce, first,
    state) -> LobeLight``, specialised on tabulated species and animated detail."""
    delta_track = tracking_functions(has_detail)[1]
    sample_media = media_functions(has_detail)
    mixture_density = mixture_functions(has_tables)[2]
    event_sunlight = sunlight_function(has_tables, has_detail)

    @wp.func
    def sun_lobe_light(here: VoxelMedia, media: VoxelMedia, majorants: Majorants, tables: PhaseTables, air: Air,
                       sun: Sun, ground: Ground, path: PathState, p: wp.vec3, air_weight: float, bounce: int,
                       first: RayEnd, state: wp.uint32) -> LobeLight:
        """The lobe's share of the sunlight at the event after the scattering at ``p`` in the media ``here``
        (``path`` as it arrived there, its air weighing ``air_weight``): a direction drawn around the sun, its
        flight (number ``bounce``) and the event at its end in ``media`` and ``majorants``, as the path's own
        would be. Two random draws for the direction, then the flight's and the shadow ray's."""
        out = LobeLight()
        out.radiance = wp.vec3(0.0)
        out.steps = 0
        out.shadow_steps = 0
        cos_theta = hg_sample_cos(path.lobe_g, wp.randf(state))
        direction = rotate_about(sun.direction, cos_theta, 2.0 * wp.pi * wp.randf(state))
        lobe = phase_hg(cos_theta, path.lobe_g)
        found = mixture_density(here, sample_media(here, p), tables, scaled_part(air_part(air, p), air_weight),
                                path.direction, direction, path.ratio)
        weight = wp.cw_mul(path.throughput, wp.max(found.phase, wp.vec3(0.0))) / (found.density + lobe)
        end = flight_end(air, ground, p, direction, bounce, first)
        flight = delta_track(media, majorants, air, p, direction, end.t, weight, state, 0)
        out.steps = flight.steps
        state = flight.state
        if flight.scattered != 0:
            q = p + flight.t * direction
            light = event_sunlight(media, majorants, tables, air, sun, sample_media(media, q), air_part(air, q), q,
                                   direction, state)
            state = light.state
            out.steps = out.steps + light.steps
            out.shadow_steps = light.steps
            out.radiance = wp.cw_mul(wp.cw_mul(weight, flight.weight), light.value)
        out.state = state
        return out

    return sun_lobe_light


#: The automatic sun lobe's rule, as the settings print it.
AUTO_LOBE = ("the largest g of the scene's Henyey-Greenstein media where it is at least 0.5, else none (isotropic "
             "media gain nothing from it, and on a storm of tabulated droplets it cut the variance by 1.4x for 1.6x "
             "the time)")
#: Henyey-Greenstein media take the automatic lobe from this g on.
AUTO_LOBE_MIN_G = 0.5


def lobe_asymmetry(scene: Scene, asked: float | None, *, meshes: bool = False, fog: bool = False) -> float:
    """The sun lobe's g for the paths of ``scene``: ``asked`` (negative: none, :data:`NO_LOBE`), or with None the
    automatic rule (:data:`AUTO_LOBE`); none where the paths trace meshes or analytic fogs (their kernels take no
    lobe) or the scene has no sun."""
    if meshes or fog or scene.sun is None:
        return float(NO_LOBE)
    if asked is not None:
        return float(NO_LOBE) if asked < 0.0 else float(asked)
    g = max((float(m.phase.g) for m in scene.media if m.species is None and m.phase.kind == PhaseKind.HG),
            default=-1.0)
    return g if g >= AUTO_LOBE_MIN_G else float(NO_LOBE)
