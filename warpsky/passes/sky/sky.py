"""Host side of the sky pass: Riley 2004 §4.1's air in front of and behind the media, with the sun's disk, and the
light the air scatters more than once (:mod:`warpsky.media.air.multiple_kernels`)."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu
from warpsky.core.image import ImageLayer
from warpsky.core.resources import MemoryEstimate
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.air.analytic import analytic_air
from warpsky.media.air.multiple_kernels import floor_of, multiple_struct, scene_table
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Projection, Scene
from warpsky.passes.render_pass import Pass
from warpsky.passes.sky.round_sky import launch_round_sky, round_description
from warpsky.passes.sky.sky_kernels import sky_kernel
from warpsky.surfaces.plane import ground_struct

#: Direction the sky pass gives an absent sun: below the horizon.
BELOW = (0.0, -1.0, 0.0)


#: The sky pass's outputs (front radiance, front transmittance, back radiance): kept across frames as
#: :func:`warpsky.core.device_buffers.reusable` arrays ``sky:NAME``, each downloaded once at the end of a frame.
OUTPUTS = ("front", "front_transmittance", "back")


def view_rays(scene: Scene, camera, light):
    """(atmosphere, eye altitude, floor altitude [m above sea level], the sun's air sine) for the sky pass's view
    table when every
    camera ray starts at the eye (a pinhole), else None; the floor is where :func:`~warpsky.media.air.analytic.
    air_ray` ends a downward ray: the ground plane below the eye, else sea level."""
    if camera.projection != Projection.PERSPECTIVE:
        return None
    atm = scene.atmosphere
    altitude = float(camera.position[1]) + atm.altitude
    floor = 0.0
    if scene.ground is not None and scene.ground.height < camera.position[1]:
        floor = max(float(scene.ground.height) + atm.altitude, 0.0)
    return atm, altitude, floor, float(light.air_sine) if light is not None and light.lit else 0.0


def air_summary(atm) -> str:
    """The air's constituents and the earth's shape, in one line."""
    parts = [f"Rayleigh gas betaSeaLevel {np.round(atm.beta_sea_level * 1e6, 3).tolist()} /Mm, scale height "
             f"{atm.scale_height:g} m"]
    if atm.has_aerosols:
        extinction = atm.mie_scattering + atm.mie_absorption
        albedo = atm.mie_scattering / np.maximum(extinction, 1e-30)
        parts.append(f"aerosols {np.round(extinction * 1e6, 3).tolist()} /Mm (albedo {np.round(albedo, 3).tolist()}), "
                     f"scale height {atm.mie_scale_height:g} m, g {atm.mie_g:g}")
    if atm.has_ozone:
        parts.append(f"ozone {np.round(atm.ozone_absorption * 1e6, 3).tolist()} /Mm at {atm.ozone_altitude:g} "
                     f"+- {atm.ozone_width:g} m")
    earth = f"round earth (radius {atm.planet_radius / 1e3:g} km)" if atm.round else "flat earth"
    return "; ".join(parts) + f"; {earth}, altitude {atm.altitude:g} m"


class Sky:
    """Air in front of the media (radiance + transmittance) and behind them (radiance, with the sun's disk), drawn
    from Riley's closed form (:mod:`warpsky.media.air.analytic`) with the sun above the air, plus the multiple-
    scattering table's light (:mod:`warpsky.media.air.multiple_kernels`) unless the atmosphere turns it off."""

    def __init__(self, *, device: str = "cpu"):
        self.device = device

    def render(self, scene: Scene, width: int, height: int, media_depth: np.ndarray | None = None):
        """(front ImageLayer, back ImageLayer); composite as [front, media, back]."""
        atm = scene.atmosphere
        camera = scene.camera.conformed(width, height)
        far = float(camera.far)
        depth = np.full((height, width), far, np.float32) if media_depth is None else media_depth
        with wp.ScopedDevice(self.device), device_buffers.exclusive("sky", self.device):
            shape = (height, width)
            front, front_t, back = outputs = [device_buffers.reusable(f"sky:{name}", shape, wp.vec3, self.device)
                                              for name in OUTPUTS]
            for array in outputs:
                array.zero_()
            depth_in = device_buffers.reusable("sky:media_depth", shape, float, self.device)
            depth_in.assign(np.ascontiguousarray(depth, dtype=np.float32))
            light = sunlight(scene)
            if atm.round:
                launch_round_sky(scene, camera, width, height, depth_in, outputs, self.device)
            else:
                wp.launch(sky_kernel, dim=shape, inputs=[
                    pinhole_camera(camera, width, height), analytic_air(atm, camera.position),
                    multiple_struct(scene_table(scene, light), self.device, name="sky:multiple",
                                    views=view_rays(scene, camera, light)),
                    sun_struct(light, unlit_direction=BELOW),
                    int(scene.ground is not None), ground_struct(scene.ground, camera.position),
                    depth_in, front, front_t, back,
                ])
            images = [device_buffers.download(f"sky:{name}", array) for name, array in zip(OUTPUTS, outputs,
                                                                                           strict=True)]
            front_layer = ImageLayer(images[0], images[1], np.full(shape, far, np.float32))
            back_layer = ImageLayer(images[2], np.zeros((height, width, 3), np.float32),
                                    np.full(shape, far, np.float32))
        return front_layer, back_layer


#: Host bytes per point of the shadowed air's batch (its float64 positions, visibilities, coefficients and sums):
#: the sky pass's peak rose 128 MiB over a full batch of 65,536 pixels x 8 points on the valley fog at 384x256.
SHADOWED_AIR_POINT_BYTES = 256


class SkyPass(Pass):
    """The frame's air: in front of everything the other passes drew and behind it, with the sun's disk. Runs when
    the scene has an atmosphere and the technique does not trace the air; its air lights the media, layers and
    scenery (their sun comes through it)."""

    name = "sky"
    wraps = True

    @classmethod
    def runs(cls, scene, technique) -> bool:
        return scene.atmosphere is not None and not technique.traces_air

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if scene.atmosphere is None:
            return {"sky": "off (no warpsky:atmosphere prim): black background, no sky pass"}
        atm = scene.atmosphere
        night = scene.sun is None or scene.sun.direction[1] <= 0.0
        how = (f"traced by {technique.name} as a participating medium, with the sun disk" if technique.traces_air
               else ("single scattering by quadrature along each ray" if atm.round
                     else "Riley's single-scattering sky in closed form")
               + (" plus the multiple-scattering table (every order, with the floor's bounces)"
                  if atm.multiple_scattering else " (multiple scattering off)")
               + ", aerial perspective and sun disk")
        out = {"sky": f"{atm.name}: {how}; {air_summary(atm)}"
                      + ("; sun below the horizon: night (black sky)" if night and not atm.round else "")}
        if atm.round:
            return {**out, **round_description(scene, technique, how)}
        table = None if technique.traces_air else scene_table(scene, sunlight(scene))
        if table is not None:
            floor, albedo = floor_of(scene)
            out["sky table"] = (f"multiple scattering: {len(table.values)} altitudes x RGB over {floor:g}..."
                                f"{floor + table.height:g} m, floor albedo {np.round(albedo, 3).tolist()}, built in "
                                f"{1e3 * table.seconds:.0f} ms (cached per air, floor and sun)")
        return out

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        """The air's images, and the temporaries of the shadowed air in front (:data:`SHADOWED_AIR_POINT_BYTES`
        per point of a batch) where the meshes, the fog or a deck can shade it."""
        pixels = width * height
        estimate = MemoryEstimate().add("sky", host=pixels * (20 + (0 if is_cpu(self.device) else 36)),
                                        device=pixels * 40)
        shaded = (scene.meshes or scene.fogs or scene.decks) and scene.sun is not None
        if shaded and scene.camera.projection == Projection.PERSPECTIVE:
            from warpsky.passes.sky.shadowed_air import BATCH, STEPS

            points = min(pixels, BATCH) * STEPS
            estimate.add("shadowed air", host=points * SHADOWED_AIR_POINT_BYTES)
        return estimate

    def render(self, frame) -> list[ImageLayer]:
        """[front, back]: the air in front runs to the nearest opaque surface where one is hit (the haze and fog in
        front of it are thin enough that the order of air and fog along the ray matters little), else to the
        merged layer's depth; the sun's single scattering in it that the scenery shades (the meshes, the fog, the
        deck) is taken out (:mod:`~warpsky.passes.sky.shadowed_air`)."""
        main, opaque = frame.merged, frame.limit
        far = frame.scene.camera.far
        air_depth = main.depth if opaque is None else np.where(opaque < far, opaque, main.depth)
        front, back = Sky(device=self.device).render(frame.scene, frame.width, frame.height, media_depth=air_depth)
        seen = frame.light.lit_at_media(frame.scene)
        shadows = [shadow for runner in frame.runners if runner.shades_air
                   for shadow in [runner.shadow(seen)] if shadow is not None]
        shaded = None
        if shadows or frame.occluders is not None:  # the scenery's shadows in the air in front (kernels load here)
            from warpsky.passes.sky.shadowed_air import shadowed_front

            shaded = shadowed_front(frame, air_depth, shadows)
        if shaded is not None:
            front.radiance = np.maximum(front.radiance - shaded, 0.0).astype(np.float32)
            front.stats["shadowed_air"] = float(shaded.mean())
        return [front, back]
