"""Host side of the sky pass and the sunlight the atmosphere leaves for the media (Riley 2004 §4.1, §4.2.4)."""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

from warpsky import device_buffers
from warpsky.camera_rays import pinhole_camera
from warpsky.layer import Layer
from warpsky.light.sun import light_elevation_sine, sun_struct, sunlight
from warpsky.media.air_analytic import analytic_air, sun_transmittance
from warpsky.passes.sky.kernels import sky_kernel
from warpsky.scene.model import Scene
from warpsky.surfaces.plane import ground_struct

#: Direction the sky pass gives an absent sun: below the horizon.
BELOW = (0.0, -1.0, 0.0)


def media_altitude(scene: Scene) -> float:
    """Altitude above sea level [m] at which the media (else the ground, else the camera) receive sunlight."""
    atmosphere = scene.atmosphere
    if scene.media:
        centres = []
        for medium in scene.media:
            n = np.asarray(medium.shape, dtype=np.float64)
            centre = np.asarray(medium.world_from_index, dtype=np.float64) @ np.append(0.5 * (n - 1.0), 1.0)
            centres.append(centre[1])
        y = float(np.mean(centres))
    elif scene.ground is not None:
        y = scene.ground.height
    else:
        y = float(scene.camera.position[1])
    return y + atmosphere.altitude


def attenuated_sun(scene: Scene) -> Scene:
    """``scene`` with its sun's irradiance reduced by the air above the media (Eq. 12); night leaves it unlit.

    One transmittance per scene, taken at the media's centre altitude: the variation across a cloud is below 1%
    for clouds a few km tall at sun elevations above ~5 deg, and documented as an approximation. Its elevation is
    the sunlight's (:func:`~warpsky.light.sun.light_elevation_sine`), so a setting sun stays lit down to
    the last sliver of its disk, which the kernels then weigh by its visible fraction.
    """
    if scene.atmosphere is None or scene.sun is None:
        return scene
    atm = scene.atmosphere
    t = sun_transmittance(atm.beta_sea_level, atm.gamma, media_altitude(scene), light_elevation_sine(scene.sun))
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, irradiance=scene.sun.irradiance * t))


def unattenuated_sun(scene: Scene) -> Scene:
    """The inverse of :func:`attenuated_sun`: ``scene`` with the sun as it arrives at the top of the atmosphere,
    for a technique that traces the air itself (unlit where no sunlight reached the media)."""
    if scene.atmosphere is None or scene.sun is None:
        return scene
    atm = scene.atmosphere
    t = sun_transmittance(atm.beta_sea_level, atm.gamma, media_altitude(scene), light_elevation_sine(scene.sun))
    irradiance = np.where(t > 1e-30, scene.sun.irradiance / np.maximum(t, 1e-30), 0.0)
    return dataclasses.replace(scene, sun=dataclasses.replace(scene.sun, irradiance=irradiance))


#: The sky pass's outputs (front radiance, front transmittance, back radiance): kept across frames as
#: :func:`warpsky.device_buffers.reusable` arrays ``sky:NAME``, each downloaded once at the end of a frame.
OUTPUTS = ("front", "front_transmittance", "back")


class SkyPass:
    """Air in front of the media (radiance + transmittance) and behind them (radiance, with the sun's disk): the
    ``sky`` pass of a frame, run when the scene has an atmosphere and the technique does not trace the air."""

    def __init__(self, *, device: str = "cpu"):
        self.device = device

    def render(self, scene: Scene, width: int, height: int, media_depth: np.ndarray | None = None):
        """(front Layer, back Layer); composite as [front, media, back]."""
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
            wp.launch(sky_kernel, dim=shape, inputs=[
                pinhole_camera(camera, width, height), analytic_air(atm, camera.position),
                sun_struct(sunlight(scene), unlit_direction=BELOW),
                int(scene.ground is not None), ground_struct(scene.ground, camera.position),
                depth_in, front, front_t, back,
            ])
            images = [device_buffers.download(f"sky:{name}", array) for name, array in zip(OUTPUTS, outputs,
                                                                                           strict=True)]
            front_layer = Layer(images[0], images[1], np.full(shape, far, np.float32))
            back_layer = Layer(images[2], np.zeros((height, width, 3), np.float32), np.full(shape, far, np.float32))
        return front_layer, back_layer
