"""Host side of the surfaces pass: opaque Lambertian meshes (terrain) and the ground plane as one ImageLayer.

The pass draws what :mod:`warpsky.passes.surfaces.surfaces_kernels` hits and shades: the scene's meshes
(:class:`~warpsky.model.terrain.TerrainMesh`, through one BVH, :mod:`warpsky.surfaces.mesh`) and, when asked, its
ground plane (with its albedo map), lit by the sun (self-shadowed, through the voxel media and a transmittance the
caller computes at the hit points) and by the sky. The ImageLayer is opaque where something is hit, so the lead
composites it with the media by depth; :meth:`Surfaces.depth_only` gives the other passes that depth as the
limit of their marches.

Lighting (see the kernels' docstring for the formula): the sun is :func:`~warpsky.light.sun.sunlight`
of the scene as given (a caller that wants it reddened by the air passes a scene whose sun is); the sky is the
dome's upper hemisphere as a uniform radiance L_sky = E / pi of a horizontal plane
(:func:`~warpsky.light.dome.upper_hemisphere`), the light a flat ground under that dome receives, so a flat
mesh and the ground plane shade alike. Left out: light between surfaces (terrain lit by terrain, the ground's
light on slopes) and the sky hidden by the terrain itself.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from warpsky.core.device import launch_rows
from warpsky.core.errors import UsageError
from warpsky.core.image import ImageLayer
from warpsky.core.resources import LAYER_BYTES, MemoryEstimate
from warpsky.light.dome import upper_hemisphere
from warpsky.light.sun import sun_struct, sunlight
from warpsky.media.voxels.voxel import VoxelMediaBuffers
from warpsky.model.camera_rays import pinhole_camera
from warpsky.model.scene import Scene
from warpsky.passes.media import scenery_paths
from warpsky.passes.render_pass import Pass

if TYPE_CHECKING:  # the kernels and meshes (Warp modules) load when the pass draws, not when a frame asks if it runs
    from warpsky.passes.surfaces.surfaces_kernels import SurfaceImage, SurfacePlane
    from warpsky.surfaces.mesh import MeshBuffers


class Surfaces:
    """Opaque Lambertian surfaces: the scene's meshes and (``draw_ground``) its ground plane, as one ImageLayer.

    Keeps its BVH between renders: a frame whose meshes have the triangles of the last one (points moved, or the
    camera did) refits it instead of building it again.
    """

    def __init__(self, *, device: str = "cpu"):
        self.device = device
        self._buffers: MeshBuffers | None = None
        self._key: tuple = ()

    # --------------------------------------------------------------------------------------------- public
    def render(self, scene: Scene, width: int, height: int, *, draw_ground: bool = True,
               sun_transmittance=None, sky=None) -> ImageLayer:
        """Render the meshes (and the ground plane when ``draw_ground`` and the scene has one).

        Args:
            scene: The scene; its ``meshes`` and ``ground`` are drawn, its voxel ``media`` shadow them.
            width, height: Image size [pixels]; the camera is conformed to it.
            draw_ground: Whether to draw ``scene.ground`` (False: another pass draws it).
            sun_transmittance: Optional ``f(points_world (N, 3) float64 [m]) -> (N, 3)`` transmittance towards the
                sun at the hit points (fog, height-field cloud shadows), multiplied into the sunlight.
            sky: E / pi [RGB] of the sky's upper hemisphere lighting the surfaces (None: the dome's).

        Returns:
            An ImageLayer: radiance, transmittance 0 where a surface is hit and 1 elsewhere, depth of the hit (the
            camera's far distance elsewhere). Under the terrain (:meth:`camera_buried`) it is black and opaque at
            the near distance, with one line in its ``warnings``.
        """
        from warpsky.passes.surfaces.surfaces_kernels import SurfaceLighting, shade_kernel
        from warpsky.surfaces.mesh import SHADOW_BIAS

        started = time.perf_counter()
        camera = scene.camera.conformed(width, height)
        with wp.ScopedDevice(self.device):
            buffers, plane = self._prepare(scene, camera.position, draw_ground)
            stats = self._stats(buffers)
            buried = self._buried_warning(scene, buffers, plane, camera.position)
            if buried is not None:
                stats["seconds"] = time.perf_counter() - started
                return ImageLayer(np.zeros((height, width, 3), np.float32), np.zeros((height, width, 3), np.float32),
                                  np.full((height, width), camera.near, np.float32), {**stats, "buried": True},
                                  warnings=[buried])
            image = self._trace(buffers, plane, pinhole_camera(camera, width, height), width, height)
            hit = image.hit.numpy().astype(bool)
            factor = self._host_factor(sun_transmittance, image, hit, camera.position)
            media = VoxelMediaBuffers.upload(scene.media, camera.position, self.device, scene.species,
                                             time_s=scene.time_s)
            lighting = SurfaceLighting()
            if sky is None:
                sky = upper_hemisphere(scene.dome)[1] if scene.dome is not None else np.zeros(3)
            lighting.sky = wp.vec3(*np.asarray(sky, np.float64).tolist())
            lighting.sky_on = int(np.any(np.asarray(sky) > 0.0))
            lighting.shadow_step = float(media.min_voxel_size)
            lighting.shadow_bias = SHADOW_BIAS
            radiance = wp.zeros((height, width), dtype=wp.vec3)
            transmittance = wp.zeros((height, width), dtype=wp.vec3)
            inputs = [buffers.surfaces, media.media, sun_struct(sunlight(scene)), lighting, image, factor, radiance,
                      transmittance]
            launch_rows(shade_kernel(media.has_detail), height, width, inputs, self.device)
            wp.synchronize_device(self.device)
            stats.update(hits=int(hit.sum()), seconds=time.perf_counter() - started)
            return ImageLayer(radiance.numpy(), transmittance.numpy(), image.depth.numpy(), stats)

    @property
    def occluders(self) -> MeshBuffers | None:
        """The meshes of the last frame this pass drew, on its device relative to that frame's camera (for other
        passes' shadow rays); None before the first."""
        return self._buffers

    def depth_only(self, scene: Scene, width: int, height: int, *, draw_ground: bool = True) -> np.ndarray:
        """(H, W) float32 camera-space depth [m] of the nearest surface (far where none; near everywhere when the
        camera is under the terrain), for the other passes' ``limit``; no shading."""
        camera = scene.camera.conformed(width, height)
        with wp.ScopedDevice(self.device):
            buffers, plane = self._prepare(scene, camera.position, draw_ground)
            if self.camera_buried(buffers, plane) >= 0:
                return np.full((height, width), camera.near, np.float32)
            image = self._trace(buffers, plane, pinhole_camera(camera, width, height), width, height)
            return image.depth.numpy()

    def camera_buried(self, buffers: MeshBuffers, plane: SurfacePlane) -> int:
        """The material the eye is under (the ray straight up from it meets that surface's back first, or the eye
        is below the drawn ground plane), else -1."""
        from warpsky.passes.surfaces.surfaces_kernels import camera_buried

        out = wp.zeros(1, dtype=wp.int32, device=self.device)
        wp.launch(camera_buried, dim=1, inputs=[buffers.surfaces, plane, out], device=self.device)
        return int(out.numpy()[0])

    # -------------------------------------------------------------------------------------------- helpers
    def _prepare(self, scene: Scene, eye: np.ndarray, draw_ground: bool) -> tuple[MeshBuffers, SurfacePlane]:
        """The meshes' buffers relative to ``eye`` (kept, refitted or rebuilt) and the plane's struct."""
        from warpsky.passes.surfaces.surfaces_kernels import SurfacePlane
        from warpsky.surfaces.mesh import MeshBuffers

        ground = scene.ground if draw_ground else None
        extra = [(ground.albedo, ground.albedo_map)] if ground is not None else []
        key = (tuple(id(m) for m in scene.meshes), tuple(np.asarray(eye, np.float64).tolist()),
               None if ground is None else id(ground))
        if self._buffers is None:
            self._buffers = MeshBuffers.build(scene.meshes, eye, self.device, extra_materials=extra)
        elif key != self._key:
            self._buffers = self._buffers.update(scene.meshes, eye, extra_materials=extra)
        self._key = key
        plane = SurfacePlane()
        plane.on = int(ground is not None)
        plane.offset = float(ground.height - eye[1]) if ground is not None else 0.0
        plane.material = self._buffers.extra_material_base
        return self._buffers, plane

    def _trace(self, buffers: MeshBuffers, plane: SurfacePlane, cam, width: int, height: int) -> SurfaceImage:
        from warpsky.passes.surfaces.surfaces_kernels import SurfaceImage, surface_hits

        image = SurfaceImage()
        image.point = wp.zeros((height, width), dtype=wp.vec3)
        image.normal = wp.zeros((height, width), dtype=wp.vec3)
        image.albedo = wp.zeros((height, width), dtype=wp.vec3)
        image.depth = wp.zeros((height, width), dtype=float)
        image.hit = wp.zeros((height, width), dtype=wp.int32)
        image.scale = wp.zeros((height, width), dtype=float)
        launch_rows(surface_hits, height, width, [buffers.surfaces, plane, cam, image], self.device)
        wp.synchronize_device(self.device)
        return image

    def _host_factor(self, callback, image: SurfaceImage, hit: np.ndarray, eye: np.ndarray) -> wp.array:
        """The caller's sun transmittance at the hit points as an (H, W) vec3 array (ones where none is asked)."""
        factor = np.ones((*hit.shape, 3), np.float32)
        if callback is not None and hit.any():
            points = image.point.numpy()[hit].astype(np.float64) + np.asarray(eye, np.float64)
            values = np.asarray(callback(points), dtype=np.float64)
            if values.shape != points.shape or not np.all(np.isfinite(values)) or values.min() < 0.0:
                raise UsageError(f"sun_transmittance must return finite values >= 0 of shape {points.shape}, got "
                                 f"shape {values.shape}")
            factor[hit] = values
        return wp.array(factor, dtype=wp.vec3, device=self.device)

    def _buried_warning(self, scene: Scene, buffers: MeshBuffers, plane: SurfacePlane,
                        eye: np.ndarray) -> str | None:
        """The warning when the camera is under a surface, else None."""
        material = self.camera_buried(buffers, plane)
        if material < 0:
            return None
        names = [m.name for m in scene.meshes] + [scene.ground.name if scene.ground is not None else "ground"]
        return (f"surfaces: the camera at {np.round(eye, 3).tolist()} m is under the surface {names[material]}; "
                "the surfaces pass draws black")

    @staticmethod
    def _stats(buffers: MeshBuffers) -> dict:
        return {"triangles": buffers.triangle_count, "bvh_seconds": buffers.build_seconds,
                "bvh_refitted": buffers.refitted}


#: One renderer per device for the process: it keeps its BVH, which the next frame refits when only the points or
#: the camera moved (an animated batch, a turntable).
_RENDERERS: dict[str, Surfaces] = {}


def kept_renderer(device: str) -> Surfaces:
    """The process's :class:`Surfaces` renderer on ``device``."""
    if device not in _RENDERERS:
        _RENDERERS[device] = Surfaces(device=device)
    return _RENDERERS[device]


class SurfacesPass(Pass):
    """The meshes (terrain) and, in a scene of such scenery without voxel media and stratiform layers, the ground
    plane; lit through the frame's air, in the shadows of every other pass that casts one (:meth:`Pass.shadow`).
    Its depth stops the passes after it (Max: "bounded by the distance to the nearest opaque surface"; Biri: the fog
    integral runs to the depth buffer)."""

    name = "surfaces"
    ground_rank = 2
    ground_note = "drawn by the surfaces pass (in the shadows of fog, height-field clouds and stratiform layers)"

    @classmethod
    def runs(cls, scene, technique) -> bool:
        if technique.traces_meshes or (scene.decks and technique.traces_decks):
            return False
        fog = bool(scene.fogs) and not technique.traces_fog  # else the technique draws the ground with its fog
        scenery = bool(scene.meshes or scene.decks or fog)
        # under stratiform layers only where the technique's paths carry the layers' light on the ground
        layered = bool(scene.stratiform_layers) and not scenery_paths(scene, technique)
        return bool(scene.meshes) or (scene.ground is not None and scenery and not scene.media and not layered)

    @classmethod
    def refusal(cls, scene, technique):
        if scene.meshes and technique.traces_air and not technique.traces_meshes:
            return "meshes", [mesh.name for mesh in scene.meshes]
        return None

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        if not scene.meshes:
            return {"meshes": "none (no Mesh prim): no BVH built"}
        triangles = sum(len(m.triangles) for m in scene.meshes)
        drawn = (f"traced by {technique.name} inside its paths" if technique.traces_meshes else "surfaces pass")
        return {"meshes": f"{len(scene.meshes)} mesh(es) ({', '.join(m.name for m in scene.meshes)}), "
                          f"{triangles:,} triangles: one Warp BVH, {drawn}"}

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        """Points (12 B) and indices (12 B per triangle) plus Warp's BVH (about 64 B per triangle), per-pixel hits."""
        triangles = sum(len(m.triangles) for m in scene.meshes)
        return MemoryEstimate().add("meshes", host=40 * triangles,
                                    device=88 * triangles + width * height * LAYER_BYTES)

    def render(self, frame) -> list[ImageLayer]:
        seen = frame.light.lit_at_media(frame.scene)
        shadows = [shadow for runner in frame.runners if runner is not self
                   for shadow in [runner.shadow(seen)] if shadow is not None]

        def sun_transmittance(points):
            out = 1.0
            for shadow in shadows:
                out = out * shadow(points)
            return out

        # the sky's light on the surfaces, unless the technique's paths gather it (their first event on a surface
        # takes no sunlight, then bounces: what the sky term approximates, occlusion and light between faces too)
        sky = np.zeros(3) if frame.technique.scenery_paths(frame.scene) else frame.light.sky[1]
        renderer = kept_renderer(self.device)
        layer = renderer.render(seen, frame.width, frame.height, draw_ground=frame.ground == self.name,
                                sun_transmittance=sun_transmittance if shadows else None, sky=sky)
        frame.limit = layer.depth
        frame.occluders = renderer.occluders if seen.meshes else None
        return [layer]
