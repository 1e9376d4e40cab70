"""Host side of the analytic fog pass (Biri, Michelin and Arquès 2002) and the fogs' shadow for other passes.

Biri et al. blend each pixel with a constant fog colour by the closed-form transparency f = exp(-int K) (their
Eq. 5-8). Here f is the layer's transmittance, per RGB channel, and the constant L_fog becomes physical: the fog
scatters once the sunlight that reaches it through itself (closed-form optical depth to the slab top, Henyey-
Greenstein phase) and the scene's ambient sky radiance (:func:`~warpsky.light.dome.ambient_radiance`). The
sky light is taken as isotropic and unshadowed by the fog, so its in-scattering is a L_ambient (1 - T) exactly
(Biri's constant L_fog with L_fog = a L_ambient); light scattered more than once is left out.

Accuracy (``tests/test_analytic_fog.py``): the closed-form optical depths match numerical quadrature of the density to
relative 3e-13 (rays of 0 to 1e6 m, every family); the float32 image rounds T to 6e-8 and its float32 ray direction
moves an optical depth by about 1e-7 of itself. The single-scattered sunlight is a Gauss-Legendre sum; on the test fog
(cosine, polynomial, point and line blobs; camera inside) it matches a nested quadrature to relative 4e-12 with 8
nodes and 16..256 pieces over 80 m and over 2000 m of fog. Its error is set by the pieces per feature (cosine
wavelength, blob radius, polynomial interval): on that 2000 m ray 64 pieces give 5e-5 and 16 give 0.16; 4 nodes per
piece give 1e-7, 2 give 4e-4. A span holding more features than ``max_pieces`` is undersampled: its mean brightness
stays right to first order, its pattern does not. The defaults (4 nodes, 4..64 pieces, each piece as long as the
shortest feature along its ray) are the speed end of that: on the valley-fog stage (cosines of 630 and 270 m, a 100 m
polynomial in height, terrain-cut rays of up to 4 km, the sun 16 deg up in the frame; 384 x 256) they differ from 8
nodes and 16..256 pieces by at most 7e-4 of the brightest pixel (the median pixel not at all), at 7 times the speed.
On the 48-member scenery family (``evaluation/scripts/choose_scenery_settings.py``: terrain that shadows the fog, so the
sunlight along a ray has edges the pieces do not follow) against 16 nodes on 16..512 pieces, relative RMS error over the
frame: tune half median 0.3 %, worst 1.7 %; test half median 0.8 %, p90 3.7 %, worst 4.8 %, mean bias -0.03 %.
8 nodes would keep the tune half within 1 % (test worst 2.2 %) but take 1.9 times as long on the valley-fog stage
at 1024 x 768 (7.4 s against 3.9 s on a shared 2-core CPU), so the default stays at 4 (``--set fog.nodes=8``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from warpsky.core.device import is_cpu, launch_rows
from warpsky.core.errors import UsageError
from warpsky.core.image import ImageLayer
from warpsky.core.resources import LAYER_BYTES, MemoryEstimate
from warpsky.core.settings import Settings, documented, setting
from warpsky.light.dome import ambient_radiance, isotropic_ambient
from warpsky.light.sun import sunlight
from warpsky.media.stratiform.stratiform_shadow import layer_shadows
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Scene
from warpsky.passes.render_pass import Pass

if TYPE_CHECKING:  # the kernels load when the pass renders, not when a frame asks whether it runs
    from warpsky.passes.fog.fog_kernels import FogMarch

#: Length [m] a horizontal sun ray is followed through the slabs by :func:`fog_sun_transmittance`.
HORIZONTAL_LENGTH = 1.0e9


@documented
@dataclass(frozen=True)
class FogSettings(Settings):
    """Settings of the fog pass (``--set fog.NAME=VALUE``). Every node costs two closed-form optical depths
    (towards the eye and towards the sun) over all terms; the module docstring gives the measured error of the
    defaults."""

    owner = "fog"
    prefix = "fog."
    nodes: int = setting(4, range="1..64", help="Gauss-Legendre nodes per piece of the in-scattering integral")
    min_pieces: int = setting(4, range=">= 1", help="pieces of the fogged span at least (a span without features)")
    max_pieces: int = setting(64, range=">= min_pieces", help="pieces at most (the span / the shortest feature "
                              "otherwise)")
    cut_depth: float = setting(40.0, range="> 0", help="optical depth (clearest channel) after which the rest of "
                               "a ray is dropped")

    def check(self) -> None:
        if self.max_pieces < self.min_pieces:
            raise UsageError(f"setting fog.max_pieces must be a whole number >= fog.min_pieces ({self.min_pieces}), "
                             f"got {self.max_pieces}")


class Fog:
    """Renders a scene's analytic fogs (``scene.fogs``) into an :class:`~warpsky.core.image.ImageLayer`. Settings are a
    :class:`FogSettings`, or its fields as keywords."""

    def __init__(self, settings: FogSettings | None = None, *, device: str = "cpu", **values):
        self.settings = settings if settings is not None else FogSettings(**values)
        self.device = device

    def __repr__(self) -> str:
        return f"Fog({self.settings!r}, device={self.device!r})"

    def march(self, scene: Scene, ambient=None, occluders=None) -> FogMarch:
        """The kernel's quadrature settings and light for ``scene`` (``ambient``: the isotropic sky radiance, RGB;
        None: :func:`~warpsky.light.dome.ambient_radiance`, the dome's; ``occluders``: the
        :class:`~warpsky.surfaces.mesh.MeshBuffers` of the frame's meshes, which shadow the fog, or None). The
        scene's stratiform layers shadow the fog's sunlight too (:mod:`~warpsky.media.stratiform.stratiform_shadow`)."""
        from warpsky.passes.fog.fog_kernels import FogMarch

        s = self.settings
        abscissae, weights = np.polynomial.legendre.leggauss(s.nodes)
        march = FogMarch()
        march.nodes = wp.array(0.5 * (abscissae + 1.0), dtype=wp.float64, device=self.device)
        march.weights = wp.array(0.5 * weights, dtype=wp.float64, device=self.device)
        march.min_pieces = s.min_pieces
        march.max_pieces = s.max_pieces
        march.cut_depth = wp.float64(s.cut_depth)
        light = sunlight(scene)
        direction = np.array([0.0, 1.0, 0.0]) if light is None else np.asarray(light.direction, dtype=np.float64)
        march.sun_direction = wp.vec3d(*direction.tolist())
        march.sun_irradiance = wp.vec3d(*(np.zeros(3) if light is None else light.irradiance).tolist())
        march.sun_on = int(light is not None and light.lit and direction[1] > 0.0)
        if occluders is None:
            from warpsky.surfaces.mesh import no_surfaces  # the meshes' module loads where fog is drawn

            march.occluders = no_surfaces(self.device)
        else:
            march.occluders = occluders.surfaces
        march.layers = layer_shadows(scene.stratiform_layers, scene.camera.position, self.device)
        ambient = ambient_radiance(scene) if ambient is None else ambient
        march.ambient = wp.vec3d(*np.asarray(ambient, dtype=np.float64).tolist())
        return march

    def render(self, scene: Scene, width: int, height: int, *, limit: np.ndarray | None = None,
               ambient=None, occluders=None) -> ImageLayer:
        """The fogs of ``scene`` at ``width`` x ``height`` (camera conformed to that aspect ratio).

        Args:
            limit: None, or (height, width) float32 camera-space depths [m] of the nearest opaque surface: the fog
                stops there (the ray distance is depth / cos of its angle to the view axis); it also stops at the
                camera's far plane.
            ambient: The isotropic sky radiance lighting the fog, RGB (None: the dome's,
                :func:`~warpsky.light.dome.ambient_radiance`).
            occluders: The frame's meshes (:class:`~warpsky.surfaces.mesh.MeshBuffers`, relative to this camera),
                whose shadows the sunlit fog lies in (terrain); None: no shadows.
        """
        started = time.perf_counter()
        camera = scene.camera.conformed(width, height)
        if not scene.fogs:
            return ImageLayer(np.zeros((height, width, 3), np.float32), np.ones((height, width, 3), np.float32),
                              np.full((height, width), camera.far, np.float32), stats={"seconds": 0.0, "fogs": 0})
        if limit is not None:
            limit = np.ascontiguousarray(limit, dtype=np.float32)
            if limit.shape != (height, width):
                raise UsageError(f"fog limit depths must have shape ({height}, {width}), got {limit.shape}")
        from warpsky.media.fog import fog_struct
        from warpsky.passes.fog.fog_kernels import fog_kernel

        device = self.device
        with wp.ScopedDevice(device):
            fogs = fog_struct(scene.fogs, camera.position, scene.time_s, device)
            limits = wp.array(limit if limit is not None else np.zeros((1, 1), np.float32), dtype=float)
            radiance = wp.zeros((height, width), dtype=wp.vec3)
            transmittance = wp.zeros((height, width), dtype=wp.vec3)
            depth = wp.zeros((height, width), dtype=float)
            inputs = [fogs, self.march(scene, ambient, occluders), pinhole_camera(camera, width, height), limits,
                      int(limit is not None), radiance, transmittance, depth]
            launch_rows(fog_kernel, height, width, inputs, device)
            wp.synchronize_device(device)
            return ImageLayer(radiance.numpy(), transmittance.numpy(), depth.numpy(),
                              stats={"seconds": time.perf_counter() - started, "fogs": len(scene.fogs),
                                "nodes": self.settings.nodes, "max_pieces": self.settings.max_pieces})


def fog_sun_transmittance(scene: Scene, points: np.ndarray, device: str = "cpu") -> np.ndarray:
    """(N, 3) RGB transmittance of all of ``scene``'s fogs from world ``points`` (N, 3) [m] towards the sun until
    the ray leaves every slab (closed form, exact; a horizontal sun is followed :data:`HORIZONTAL_LENGTH`). Ones
    without a sun or a fog. Whether the sun is up is the caller's business: this is only the fogs' shadow."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    light = sunlight(scene)
    if light is None or not scene.fogs or len(points) == 0:
        return np.ones((len(points), 3))
    from warpsky.media.fog import fog_struct
    from warpsky.passes.fog.fog_kernels import sun_transmittance_kernel

    origin = np.asarray(scene.camera.position, dtype=np.float64)
    with wp.ScopedDevice(device):
        fogs = fog_struct(scene.fogs, origin, scene.time_s, device)
        relative = wp.array(points - origin, dtype=wp.vec3d)
        out = wp.zeros(len(points), dtype=wp.vec3d)
        direction = wp.vec3d(*np.asarray(light.direction, dtype=np.float64).tolist())
        wp.launch(sun_transmittance_kernel, dim=len(points),
                  inputs=[fogs, direction, wp.float64(HORIZONTAL_LENGTH), relative, out])
        return out.numpy()


class FogPass(Pass):
    """Biri's analytic fogs, stopped by the nearest opaque surface, lit through the frame's air and shadowed by the
    frame's meshes."""

    name = "fog"
    shades_air = True
    Settings = FogSettings

    @classmethod
    def runs(cls, scene, technique) -> bool:
        return bool(scene.fogs) and not technique.traces_fog

    @classmethod
    def refusal(cls, scene, technique):
        if cls.runs(scene, technique) and technique.traces_air:
            return "analytic fog", [fog.name for fog in scene.fogs]
        return None

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if not scene.fogs:
            return {"fog": 'none (no prim with warpsky:kind = "analyticFog")'}
        if technique.traces_fog:
            return {"fog": "; ".join(f"{fog.name}: {fog.describe()}" for fog in scene.fogs)
                    + f" (Biri 2002): traced by {technique.name} as a participating medium, closed-form density "
                    "and sun transmittance; no fog pass"}
        return {"fog": "; ".join(f"{fog.name}: {fog.describe()}" for fog in scene.fogs)
                + " (Biri 2002, closed-form optical depths)"}

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        pixels = width * height
        return MemoryEstimate().add("fog", host=pixels * (0 if is_cpu(self.device) else LAYER_BYTES),
                                    device=pixels * LAYER_BYTES)

    def shadow(self, scene):
        return lambda points: fog_sun_transmittance(scene, points, self.device)

    def own_layer(self, frame) -> ImageLayer:
        """The fog's single scattering of the sun, and its ambient term unless the technique path traces the
        sky's light on the fog (:meth:`~warpsky.techniques.technique.Technique.scenery_paths`: its paths' first event
        takes no sunlight but gathers the sky's and the dome's light, the light the ambient term approximates);
        drawn once per frame (the media pass hands it to those paths' error estimate)."""

        def draw() -> ImageLayer:
            seen = frame.light.lit_at_media(frame.scene)
            ambient = isotropic_ambient(seen, frame.light.sky)
            if frame.technique.scenery_paths(frame.scene):
                ambient = np.zeros(3)
            return Fog(self.settings, device=self.device).render(seen, frame.width, frame.height, limit=frame.limit,
                                                                 ambient=ambient, occluders=frame.occluders)

        return self.keep(frame, draw)

    def render(self, frame) -> list[ImageLayer]:
        """:meth:`own_layer`; for deep output with its depth profile."""
        layer = self.own_layer(frame)
        if frame.deep_samples > 0:  # deep output: the fog's closed-form depth profile on the same rays
            from warpsky.passes.depth_profile import fog_depth_profile

            layer.profile = fog_depth_profile(frame.light.lit_at_media(frame.scene), frame.width, frame.height,
                                              frame.deep_samples, self.device, limit=frame.limit)
        return [layer]
