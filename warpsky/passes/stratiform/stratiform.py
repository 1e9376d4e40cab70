"""Host side of the stratiform technique: a :class:`~warpsky.media.stratiform.thickness.StratiformLayer` over a
(textured) ground, with the ground <-> cloud-base radiosity of Bouthors 2006 §5 (see :mod:`.kernels`).

A dome's upper hemisphere, as the uniform radiance giving the same irradiance on a horizontal surface
(:func:`~warpsky.light.dome.upper_hemisphere`), is added to the uniform-equivalent sky C_sky that lights the
layer from above (T_ms C_sky below it, R_ms C_sky above it, and the radiosity's source): the slab's multiple
scattering model then stands for the occlusion. Its light from below the horizon and a texture's directional
structure are left out."""

from __future__ import annotations

import functools
import json
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpsky.core import device_buffers
from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.image import ImageLayer
from warpsky.core.resources import LAYER_BYTES, MemoryEstimate
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.dome import upper_hemisphere
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.air.multiple_kernels import air_radiance
from warpsky.media.stratiform.stratiform_voxels import LAYER_SPECIES
from warpsky.media.stratiform.thickness import (
    GroundTexture,
    StratiformLayer,
    at_time,
    layer_sun_transmittance,
    sample_thickness,
    signed_thickness,
)
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Scene
from warpsky.optics.prepare import TableNeed
from warpsky.optics.tables import modified_mie_table, phase_table
from warpsky.passes.render_pass import Pass
from warpsky.surfaces.plane import ground_struct

# The slab's optics, the radiosity and the kernels (Warp modules) load when a layer is drawn or described, not when
# a frame asks whether the pass runs.


@documented
@dataclass(frozen=True)
class StratiformSettings(Settings):
    """Settings of the stratiform pass (``--set stratiform.NAME=VALUE``).

    The ``stratiform.`` prefix sends a ``--set`` to this pass instead of the voxel technique, e.g.
    ``warpsky render usd_scenes/stratocumulus.usda out/sc.####.exr --set stratiform.radiosity=0``.
    """

    owner = "stratiform"
    prefix = "stratiform."
    radiosity: bool | None = setting(None, help="1: iterate ground <-> cloud exchanges; 0: sky and cloud light "
                                     "reach the ground once, nothing comes back to the cloud base",
                                     auto="each layer's bool warpsky:stratiform:radiosity (default true)")
    radiosity_detail: int = setting(0, range="0..4", help="buffer texels per h = 2^detail (h: ground to cloud "
                                    "base)")
    tolerance: float = setting(1e-4, range="> 0", help="stop when an iteration's exchanged energy ratio is below "
                               "this")
    max_iterations: int = setting(64, range=">= 1", help="iteration cap (warns with the residual)")

    def radiosity_for(self, layer: StratiformLayer) -> bool:
        """Whether the exchange runs for ``layer``: this setting when given, else the layer's attribute."""
        return bool(layer.radiosity) if self.radiosity is None else bool(self.radiosity)


def sky_radiance(scene: Scene, altitude: float, samples: int = 24) -> np.ndarray:
    """Uniform radiance [sun units/sr] with the same irradiance on a horizontal surface at ``altitude`` [m above
    the stage's y = 0] as the sky pass's air above it (:func:`~warpsky.media.air.multiple_kernels.air_radiance`); 0
    without
    an atmosphere or sunlight."""
    light = sunlight(scene)
    if scene.atmosphere is None or light is None or not light.lit:
        return np.zeros(3)
    atm = scene.atmosphere
    zen = (np.arange(samples) + 0.5) / samples * 0.5 * np.pi
    az = (np.arange(2 * samples) + 0.5) / (2 * samples) * 2 * np.pi
    z, a = np.meshgrid(zen, az, indexing="ij")
    dirs = np.stack([np.sin(z) * np.cos(a), np.cos(z), np.sin(z) * np.sin(a)], -1)
    radiance = air_radiance(scene, light, altitude + atm.altitude, dirs.reshape(-1, 3)).reshape(dirs.shape)
    weight = (np.cos(z) * np.sin(z))[..., None] * (0.5 * np.pi / samples) * (2 * np.pi / (2 * samples))
    return (radiance * weight).sum(axis=(0, 1)) / np.pi


def _sample(map2d: np.ndarray, origin, size, xs: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """Nearest-texel lookup of a (nx, nz[, C]) map at world points (clamped at its edges)."""
    nx, nz = map2d.shape[:2]
    i = np.clip(((xs - origin[0]) / size[0] * nx).astype(int), 0, nx - 1)
    j = np.clip(((zs - origin[1]) / size[1] * nz).astype(int), 0, nz - 1)
    return map2d[i, j]


#: The pass's per-pixel outputs: kept across frames as :func:`warpsky.core.device_buffers.reusable` arrays
#: ``stratiform:NAME``, each downloaded once at the end of a frame.
OUTPUTS = (("radiance", wp.vec3), ("transmittance", wp.vec3), ("depth", float))


def _device_rgb(name: str, values, device):
    """``values`` (nu, nv, 3) as a vec3 device array: as they are when already on the device (the radiosity's
    buffers), else refilled under ``name``."""
    if isinstance(values, wp.array):
        return values
    return device_buffers.refill(name, np.asarray(values, dtype=np.float32), wp.vec3, device)


class Stratiform:
    """Bouthors 2006 stratiform layer + radiosity. ``render`` takes the layer (and ground texture) explicitly."""

    name = "stratiform"
    Settings = StratiformSettings

    def __init__(self, settings: StratiformSettings | None = None, *, device: str = "cpu"):
        self.settings = settings or StratiformSettings()
        self.device = device

    def resolved_settings(self, scene: Scene) -> StratiformSettings:
        return self.settings

    def radiosity_inputs(self, scene: Scene, layer: StratiformLayer, texture: GroundTexture | None, optics,
                         sky: np.ndarray):
        """(grid box (x0, z0, sx, sz), R_G, R_C, RadiosityResult or None) on the shared low-resolution grid; R_G
        and R_C are the solver's device arrays when it ran, host arrays otherwise."""
        from warpsky.passes.stratiform.model1d import order_energies, reference_thickness
        from warpsky.passes.stratiform.radiosity import Radiosity, ground_direct, radiosity_grid

        s = self.settings
        ground = scene.ground
        h = layer.base_altitude - ground.height
        detail = int(s.radiosity_detail)
        (x0, z0), pixel, shape = radiosity_grid(layer, ground.height, detail)
        box = (x0, z0, shape[0] * pixel, shape[1] * pixel)
        # area averages of the maps over each texel (4 x 4 sub-samples)
        sub = (np.arange(4) + 0.5) / 4
        xs = x0 + (np.arange(shape[0])[:, None] + sub[None, :]).reshape(-1) * pixel
        zs = z0 + (np.arange(shape[1])[:, None] + sub[None, :]).reshape(-1) * pixel
        X, Z = np.meshgrid(xs, zs, indexing="ij")
        thick = sample_thickness(signed_thickness(layer.thickness), layer.origin, layer.size, X, Z)
        light = sunlight(scene)
        sun = light.direction if light is not None else np.array([0.0, 1.0, 0.0])
        irradiance = light.irradiance if light is not None and light.lit else np.zeros(3)
        mu_l = max(float(sun[1]), 1e-6)
        e = order_energies(reference_thickness(thick, optics.kappa), np.degrees(np.arccos(min(mu_l, 1.0))),
                           float(optics.kappa_s[1] / optics.to_reference))

        def texel_mean(values):
            return values.reshape(shape[0], 4, shape[1], 4, *values.shape[2:]).mean(axis=(1, 3))

        t_c = texel_mean(e.t0 + e.t1 + e.t2)
        rho_c = texel_mean(e.r_ms)
        source = texel_mean(e.t3p)[..., None] * irradiance * mu_l + texel_mean(e.t_ms)[..., None] * np.pi * sky
        if texture is not None:
            rho_g = texel_mean(_sample(texture.albedo, texture.origin, texture.size, X, Z))
        else:
            rho_g = np.broadcast_to(ground.albedo, (*shape, 3))
        direct = ground_direct(t_c, pixel=pixel, h=h, sun_direction=sun, sun_irradiance=irradiance,
                               device=self.device)
        solver = Radiosity(pixel_over_h=2.0**-detail, tolerance=s.tolerance, max_iterations=int(s.max_iterations),
                           device=self.device)
        if s.radiosity_for(layer):
            result = solver.solve(ground_albedo=rho_g, cloud_reflectance=rho_c, ground_direct=direct,
                                  cloud_source=source)
            return box, *result.device_received, result
        return box, solver.gather(source), np.zeros((*shape, 3), np.float32), None

    def render(self, scene: Scene, width: int, height: int, *, layer: StratiformLayer,
               ground_texture: GroundTexture | None = None, draw_ground: bool = True) -> ImageLayer:
        """Render ``layer`` (at its time, when advected) over the scene's ground, textured by ``ground_texture``
        (default: the ground's ``albedo_map``). ``draw_ground=False`` leaves the ground out of the image (another
        layer draws it) while the radiosity still lights this layer's base."""
        from warpsky.passes.stratiform.optics import stratiform_optics
        from warpsky.passes.stratiform.stratiform_kernels import LayerGeometry, stratiform_kernel

        started = time.perf_counter()
        layer = at_time(layer, self.device)
        if ground_texture is None and scene.ground is not None:
            ground_texture = scene.ground.albedo_map
        camera = scene.camera.conformed(width, height)
        eye = camera.position
        optics = stratiform_optics(layer.number_density, layer.effective_radius)
        sky = sky_radiance(scene, layer.base_altitude + float(layer.thickness.max()))
        if scene.dome is not None:
            sky = sky + upper_hemisphere(scene.dome)[1]  # the dome joins the uniform-equivalent sky above it
        stats = {"radiosity": bool(self.settings.radiosity_for(layer))}
        warnings: list[str] = []
        # the radiosity's R_G and R_C stay in its kept arrays until the shading kernel has read them
        with (wp.ScopedDevice(self.device), device_buffers.exclusive("stratiform", self.device),
              device_buffers.exclusive("radiosity", self.device)):
            slab_optics, tables, params = optics.device_inputs(self.device, cache_name="stratiform")
            g = LayerGeometry()
            g.base = float(layer.base_altitude - eye[1])
            g.x0 = float(layer.origin[0] - eye[0])
            g.z0 = float(layer.origin[1] - eye[2])
            g.sx, g.sz = float(layer.size[0]), float(layer.size[1])
            g.top = g.base + float(layer.thickness.max())
            ground = scene.ground
            if ground is not None and ground.height < layer.base_altitude:
                box, r_g, r_c, result = self.radiosity_inputs(scene, layer, ground_texture, optics, sky)
                if result is not None:
                    stats.update(radiosity_iterations=result.iterations, radiosity_residual=result.residual,
                                 radiosity_seconds=result.seconds, radiosity_converged=result.converged)
                    if result.warning:
                        warnings.append(f"{layer.name}: {result.warning}")
            else:
                box, r_g, r_c = (0.0, 0.0, 1.0, 1.0), np.zeros((2, 2, 3)), np.zeros((2, 2, 3))
            if ground_texture is not None:
                albedo, abox = ground_texture.albedo, (*ground_texture.origin, *ground_texture.size)
            else:
                albedo = np.broadcast_to(ground.albedo if ground is not None else np.zeros(3), (2, 2, 3))
                abox = (-1e9, -1e9, 2e9, 2e9)
            rel = lambda b: wp.vec4(b[0] - eye[0], b[1] - eye[2], b[2], b[3])  # noqa: E731
            radiance, transmittance, depth = outputs = [
                device_buffers.reusable(f"stratiform:{name}", (height, width), dtype, self.device)
                for name, dtype in OUTPUTS]
            for array in outputs:
                array.zero_()
            thickness = device_buffers.refill("stratiform:thickness", signed_thickness(layer.thickness), float,
                                              self.device)
            inputs = [
                pinhole_camera(camera, width, height), thickness, g,
                tables.values, params, slab_optics,
                sun_struct(sunlight(scene), unlit_direction=(0.0, -1.0, 0.0)), wp.vec3(*sky.tolist()),
                int(ground is not None and draw_ground), ground_struct(ground, eye),
                device_buffers.refill("stratiform:albedo", np.asarray(albedo, dtype=np.float32), wp.vec3, self.device),
                rel(abox), _device_rgb("stratiform:ground_received", r_g, self.device),
                _device_rgb("stratiform:cloud_received", r_c, self.device), rel(box),
                radiance, transmittance, depth,
            ]
            render_started = time.perf_counter()
            launch_rows(stratiform_kernel, height, width, inputs, self.device)
            wp.synchronize_device(self.device)
            stats["shading_seconds"] = time.perf_counter() - render_started
            out = ImageLayer(*(device_buffers.download(f"stratiform:{name}", array)
                          for (name, _), array in zip(OUTPUTS, outputs, strict=True)), stats, warnings=warnings)
        stats["seconds"] = time.perf_counter() - started
        return out


class StratiformPass(Pass):
    """Every stratiform layer of the scene as its own ImageLayer (Bouthors slab, plus the ground <-> cloud-base
    radiosity when a ground lies below), each lit by the sun through the air down to its mid altitude; the lowest
    layer draws the ground (textured, in the layer's shadow, lit by the radiosity)."""

    name = "stratiform"
    Settings = StratiformSettings
    ground_rank = 0
    ground_note = "drawn by the stratiform pass (layer shadows, radiosity), voxel media cast no shadow"
    draws = ("stratiform_layers",)

    @classmethod
    def runs(cls, scene, technique) -> bool:
        return bool(scene.stratiform_layers) and not technique.traces_layers

    def draws_ground(self, scene) -> bool:
        """Not where the technique's paths trace the scenery under the layers
        (:meth:`~warpsky.techniques.technique.Technique.scenery_paths`): the surfaces pass draws the ground's sunlight
        in the layers' shadow then, and the paths its light from the layers (the radiosity's part)."""
        return not (self.technique is not None and self.technique.scenery_paths(scene))

    @classmethod
    def refusal(cls, scene, technique):
        if cls.runs(scene, technique) and not technique.renders_layers:
            return "stratiform layers", [layer.name for layer in scene.stratiform_layers]
        return None

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if not scene.stratiform_layers:
            return {"layers": 'no layers (no prim with warpsky:kind = "stratiformLayer"): stratiform pass and '
                              "radiosity not built"}
        if technique.traces_layers:
            return {"layers": f"traced by {technique.name} itself: no stratiform pass, no radiosity model"}
        return layer_features(scene, settings)

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        """The thickness maps, one layer image per layer (and its host copy on a GPU), the merge's copies and the
        radiosity buffers of every layer above the ground."""
        from warpsky.passes.stratiform.radiosity import radiosity_bytes

        pixels, layers = width * height, len(scene.stratiform_layers)
        copies = 0 if is_cpu(self.device) else layers
        estimate = MemoryEstimate()
        for layer in scene.stratiform_layers:
            estimate.add("stratiform maps", device=4 * layer.thickness.size)
        estimate.add("stratiform layers", host=pixels * (LAYER_BYTES * copies + 40 * (layers + 1)),
                     device=pixels * LAYER_BYTES * layers)
        ground, settings = scene.ground, self.settings
        return estimate.add("radiosity", device=sum(
            radiosity_bytes(layer, ground.height, int(settings.radiosity_detail)) for layer in scene.stratiform_layers
            if ground is not None and ground.height < layer.base_altitude and settings.radiosity_for(layer)))

    def tables(self, scene) -> list[TableNeed]:
        """The ``stratus`` phase table and Bouthors' modified Mie table split at the forward cut."""
        from warpsky.passes.stratiform.optics import FORWARD_CUT_DEG

        return [TableNeed(LAYER_SPECIES, "phase", functools.partial(phase_table, LAYER_SPECIES)),
                TableNeed(LAYER_SPECIES, "bouthors", functools.partial(modified_mie_table, LAYER_SPECIES,
                                                                        FORWARD_CUT_DEG), f"{FORWARD_CUT_DEG:g}")]

    def shadow(self, scene):
        if scene.sun is None:
            return None

        def through_layers(points):
            out = 1.0
            for layer in scene.stratiform_layers:
                out = out * layer_sun_transmittance(layer, points, scene.sun.direction, self.device)
            return out

        return through_layers

    def header(self, parts: list[dict]) -> dict:
        """``stratiform``: per layer its name, whether the radiosity ran, its iterations, residual, convergence
        and seconds (JSON)."""
        keys = ("layer", "radiosity", "radiosity_iterations", "radiosity_residual", "radiosity_converged", "seconds")
        return {"stratiform": json.dumps([{k: part[k] for k in keys if k in part} for part in parts
                                          if "layer" in part])}

    def render(self, frame) -> list[ImageLayer]:
        """One ImageLayer per stratiform layer, in the scene's order; ``stats["layer"]`` names it."""
        scene, parts = frame.scene, []
        lowest = min(range(len(scene.stratiform_layers)), key=lambda i: scene.stratiform_layers[i].base_altitude)
        renderer = Stratiform(self.settings, device=self.device)
        for index, layer in enumerate(scene.stratiform_layers):
            lit = frame.light.lit_at(scene, layer.base_altitude + 0.5 * float(layer.thickness.max()))
            part = renderer.render(lit, frame.width, frame.height, layer=layer,
                                   draw_ground=index == lowest and frame.ground == self.name)
            part.stats["layer"] = layer.name
            parts.append(part)
        return parts


def layer_features(scene, settings) -> dict[str, str]:
    """One ``layer`` line per stratiform layer and one ``radiosity`` line per layer: what the stratiform pass
    builds (map, optics, advection; the radiosity buffers and their size, or why there are none)."""
    features = {}
    count = len(scene.stratiform_layers)
    for number, layer in enumerate(scene.stratiform_layers, start=1):
        suffix = "" if count == 1 else f" {number}"
        nx, nz = layer.thickness.shape
        line = (f"{layer.name}: stratiform (Bouthors 2006), base {layer.base_altitude:g} m, "
                f"{layer.size[0]:g} x {layer.size[1]:g} m, map {nx}x{nz}, cover {layer.cover:.0%}, max "
                f"{float(layer.thickness.max()):g} m, kappa {layer.extinction:.4g} 1/m")
        adv = layer.advection
        if adv is None:
            line += ", static map"
        else:
            scale = "half the layer" if adv.curl_scale_m is None else f"{adv.curl_scale_m:g} m"
            line += (f", advected at t = {layer.time_s:g} s: wind {list(adv.wind_m_s)} m/s, curl "
                     f"{adv.curl_speed_m_s:g} m/s at {scale}, period {adv.period_s:g} s, seed {adv.seed}")
        features["layer" + suffix] = line
        features["radiosity" + suffix] = _radiosity_feature(scene, layer, settings)
    return features


def _radiosity_feature(scene, layer, settings) -> str:
    ground = scene.ground
    if ground is None or ground.height >= layer.base_altitude:
        return "off: no ground below the layer"
    if not settings.radiosity_for(layer):
        why = ("stratiform.radiosity=0" if settings.radiosity is not None
               else f"warpsky:stratiform:radiosity = false on {layer.name}")
        return f"off ({why}): sky and cloud light reach the ground once"
    from warpsky.passes.stratiform.radiosity import radiosity_bytes, radiosity_grid

    detail = int(settings.radiosity_detail)
    _, pixel, (nu, nv) = radiosity_grid(layer, ground.height, detail)
    mib = radiosity_bytes(layer, ground.height, detail) / 2**20
    return (f"on: ground <-> cloud base, buffers {nu}x{nv} texels of {pixel:g} m (h / 2^{detail}), {mib:.2f} MiB; "
            f"rings gather, tolerance {settings.tolerance:g}, cap {int(settings.max_iterations)} iterations")
