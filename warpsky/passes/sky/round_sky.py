"""Host side of the sky pass on a round earth (:mod:`~warpsky.passes.sky.round_kernels`): the tables it needs, the
frame's view table, the launch, and what ``warpsky info`` says of it."""

from __future__ import annotations

import hashlib

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.files import cached_array
from warpsky.light.sun import Sunlight, sun_struct, sunlight
from warpsky.media.air.analytic import analytic_air
from warpsky.media.air.multiple import floor_of
from warpsky.media.air.round_earth import air_lit, sun_radius
from warpsky.media.air.round_earth_kernels import DEPTH_MUS, DEPTH_RADII, air_top, round_struct
from warpsky.media.air.round_earth_multiple import HEIGHTS, SUNS, multiple_struct, round_table
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Projection
from warpsky.passes.sky.round_kernels import RoundView, round_sky_kernel, view_table_kernel

#: The frame's view table: elevations (uniform in sign(mu) sqrt(|mu|)) x azimuths from the sun on [0, pi].
VIEW_ELEVATIONS = 256
VIEW_AZIMUTHS = 48
#: View tables kept on disk (0.6 MB each) before the oldest go.
VIEW_TABLES_KEPT = 64


def kernel_input_identity(value) -> tuple | str:
    """Everything a kernel reads from the argument ``value``, by value: a struct field by field, an array by its
    shape, type and a hash of its contents, a number or vector by its bytes."""
    if isinstance(value, wp.array):
        return (value.shape, str(value.dtype), hashlib.sha256(value.numpy().tobytes()).hexdigest())
    if hasattr(value, "_cls"):  # a wp.struct instance
        return tuple((name, kernel_input_identity(getattr(value, name))) for name in value._cls.vars)
    value = getattr(value, "value", value)  # Warp's scalar types
    array = np.asarray(value)
    if array.dtype == object:
        raise TypeError(f"no identity for a kernel input of type {type(value).__name__}")
    return f"{array.dtype.str}:{array.tobytes().hex()}"


def view_table(inputs: list, device) -> wp.array:
    """The frame's view table for ``inputs`` (air, round earth, multiple-scattering table, sun, sun radius). On the
    CPU (0.08-0.15 s on 2 cores) it is kept on disk by the value of everything the kernel reads and the kernel's
    module hash: the frames of a shot whose sun and eye altitude stay put build it once."""
    table = device_buffers.reusable("sky:round_views", (VIEW_ELEVATIONS, VIEW_AZIMUTHS, 4), wp.vec3, device)

    def build():
        launch_rows(view_table_kernel, VIEW_ELEVATIONS, VIEW_AZIMUTHS, [*inputs, table], device)
        return table.numpy()

    if not is_cpu(device):
        build()
        return table
    identity = (VIEW_ELEVATIONS, VIEW_AZIMUTHS, view_table_kernel.module.get_module_hash().hex(),
                [kernel_input_identity(value) for value in inputs])
    table.assign(cached_array("air", "round-views", identity, build, keep=VIEW_TABLES_KEPT))
    return table


def unlit(light: Sunlight | None) -> bool:
    return light is None or not light.lit


def round_front_inputs(scene, camera, width: int, height: int, device) -> list:
    """The round sky kernel's inputs before the media depth: camera, air, round earth, multiple-scattering table,
    the frame's view table (built here), sun and its radius."""
    atm = scene.atmosphere
    light = sunlight(scene)
    floor, albedo = floor_of(scene)
    ra = round_struct(atm, floor, device)
    table = round_table(atm, floor, albedo, device) if atm.multiple_scattering and not unlit(light) else None
    ms = multiple_struct(table, device, name="sky:round_multiple")
    sun = sun_struct(light, unlit_direction=(0.0, -1.0, 0.0))
    radius = sun_radius(light.angular_diameter) if light is not None else 0.0
    air = analytic_air(atm, camera.position)
    view = RoundView()
    view.count = 0
    if camera.projection == Projection.PERSPECTIVE and not unlit(light):
        view.table = view_table([air, ra, ms, sun, radius], device)
        view.count = VIEW_ELEVATIONS * VIEW_AZIMUTHS
    else:
        view.table = device_buffers.reusable("sky:round_no_views", (2, 2, 4), wp.vec3, device)
    return [pinhole_camera(camera, width, height), air, ra, ms, view, sun, radius]


def launch_round_sky(scene, camera, width: int, height: int, depth, outputs, device):
    """Draw the round earth's sky into ``outputs`` (front radiance, front transmittance, back radiance) for the
    media depth ``depth`` (device array)."""
    wp.launch(round_sky_kernel, dim=(height, width), device=device,
              inputs=[*round_front_inputs(scene, camera, width, height, device), depth, *outputs])


def round_description(scene, technique, how: str) -> dict[str, str]:
    """``warpsky info``'s lines for a round earth's sky."""
    atm = scene.atmosphere
    floor, albedo = floor_of(scene)
    sun = scene.sun
    out = {}
    twilight = ""
    if sun is not None and sun.direction[1] <= 0.0:
        lit = air_lit(atm, floor, sun.elevation, sun_radius(sun.angular_diameter))
        twilight = ("; the sun has set: twilight (the high air still sees it)" if lit
                    else "; the sun is below the horizon of the whole air: night (black sky)")
    out["earth"] = (f"round, radius {atm.planet_radius / 1e3:g} km; air from {floor:g} m to {air_top(atm) / 1e3:.1f} "
                    f"km{twilight}")
    if technique.traces_air:
        return out
    out["sky table"] = (f"round earth: optical depth to the top {DEPTH_RADII} x {DEPTH_MUS} (altitude x direction), "
                        + (f"multiple scattering {HEIGHTS} altitudes x {SUNS} sun elevations (every order, "
                           f"isotropic after the second, floor albedo {np.round(albedo, 3).tolist()}), "
                           if atm.multiple_scattering else "multiple scattering off, ")
                        + "both built on the render device once per air and floor; a view table per frame")
    return out
