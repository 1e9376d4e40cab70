"""Decide what a frame needs before anything runs: technique, settings, device, resolution, features.

This is where "leave out what a scene does not need" lives, and what ``warpsky info`` prints.
"""

from __future__ import annotations

import dataclasses
import enum
import json
from dataclasses import dataclass, field

import numpy as np

from warpsky.errors import UsageError
from warpsky.optics.tables import is_cached
from warpsky.passes.frame import SCENERY_SETTINGS, parse_scenery_settings
from warpsky.passes.stratiform.stratiform import StratiformSettings, radiosity_grid
from warpsky.resources import MemoryEstimate, WorkEstimate, frame_memory, frame_work
from warpsky.scene.model import Scene
from warpsky.settings import parse_settings
from warpsky.techniques.base import DEFAULT_TECHNIQUE, Technique, technique_class
from warpsky.techniques.path_tracer.deck_media import deck_voxel_features, traces_decks
from warpsky.techniques.path_tracer.layer_media import layer_voxel_features, traces_layers

DEFAULT_WIDTH = 512
#: ``--set`` names with this prefix go to the stratiform pass (``StratiformSettings``), not the voxel technique.
LAYER_SETTING_PREFIX = "stratiform."
#: Full-size (nu, nv) RGB float32 buffers the radiosity solver holds (ρ_G, ρ_C, ones, R_G, R_C, dR_G, dR_C) plus
#: about a third more for the MIP pyramid.
RADIOSITY_BUFFERS = 7 + 1 / 3


@dataclass
class RenderPlan:
    """What will run for one frame, fully resolved.

    Attributes:
        technique: Registered name of the voxel technique.
        settings: Its settings with every ``auto`` value resolved for the frame's scene.
        device: Warp device name.
        width, height: Image size [pixels].
        renderer: The technique, built once for the frame with ``settings``.
        passes: What runs, in order: ``media`` (the technique), ``stratiform`` (one layer per stratiform layer,
            merged with the media by depth), ``sky`` (air in front of and behind them, and the sun's disk).
        features: One line per feature of the scene, what ``warpsky info`` prints.
        layer_settings: StratiformSettings when the scene has stratiform layers, else None.
        settings_hash: Hash of what changes the frame's pixels, set by :func:`warpsky.render.plan_frame` (the
            batch's resume check and the EXR metadata share it); empty until then.
        memory: Bytes the frame will allocate, by part (:func:`warpsky.resources.frame_memory`).
        work: Worst-case kernel iterations of the frame (:func:`warpsky.resources.frame_work`).
        scenery_settings: ``--set heightfield.*`` / ``fog.*`` values by pass
            (:func:`warpsky.passes.frame.parse_scenery_settings`).
    """

    technique: str
    settings: object
    device: str
    width: int
    height: int
    renderer: Technique
    passes: tuple[str, ...] = ("media",)
    features: dict[str, str] = field(default_factory=dict)
    layer_settings: StratiformSettings | None = None
    settings_hash: str = ""
    memory: MemoryEstimate = field(default_factory=MemoryEstimate)
    work: WorkEstimate = field(default_factory=WorkEstimate)
    scenery_settings: dict = field(default_factory=dict)

    def settings_dict(self) -> dict:
        return dataclasses.asdict(self.settings)

    def settings_json(self) -> str:
        extra = {} if self.layer_settings is None else {"stratiform": dataclasses.asdict(self.layer_settings)}
        extra.update(self.scenery_settings)
        return json.dumps({"technique": self.technique, **self.settings_dict(), **extra}, sort_keys=True)

    def describe(self) -> str:
        lines = [
            f"technique   {self.technique}",
            f"device      {self.device}",
            f"resolution  {self.width} x {self.height}",
            "settings    " + (", ".join(f"{k}={_fmt(v)}" for k, v in self.settings_dict().items())
                              if "media" in self.passes else f"none: {self.technique} does not run (no voxel media)"),
        ]
        if self.layer_settings is not None:
            lines.append("            " + ", ".join(f"stratiform.{k}={'auto' if v is None else _fmt(v)}"
                                                  for k, v in dataclasses.asdict(self.layer_settings).items()))
        for name, values in self.scenery_settings.items():
            lines.append("            " + ", ".join(f"{name}.{k}={_fmt(v)}" for k, v in values.items()))
        lines.append(f"passes      {' -> '.join(self.passes)} -> composite")
        lines += [f"{name:<11} {state}" for name, state in self.features.items()]
        return "\n".join(lines)


def _fmt(value) -> str:
    if value is None:
        return "auto"
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, enum.Enum):
        return str(value.value)
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def resolve_resolution(scene: Scene, resolution: tuple[int, int | None] | None) -> tuple[int, int]:
    """Image size: ``--res``, else the stage's render settings, else 512 wide at the camera's aspect ratio."""
    camera = scene.camera
    aspect = camera.horizontal_aperture / camera.vertical_aperture / camera.pixel_aspect  # in pixels
    if resolution is None:
        resolution = scene.resolution or (DEFAULT_WIDTH, None)
    width, height = resolution
    if height is None:
        height = max(1, round(width / aspect))
    if width <= 0 or height <= 0:
        raise UsageError(f"resolution must be positive, got {width}x{height}")
    return int(width), int(height)


def make_plan(
    scene: Scene,
    *,
    technique: str = DEFAULT_TECHNIQUE,
    settings: dict[str, str] | None = None,
    resolution: tuple[int, int | None] | None = None,
    device: str = "cpu",
) -> RenderPlan:
    """Plan a frame of ``scene``: parse the settings (``stratiform.``-prefixed ones go to the stratiform pass),
    build the technique once with its settings resolved for the scene, decide the passes, describe the features
    and estimate the frame's memory and work (nothing is allocated)."""
    cls = technique_class(technique)
    settings = dict(settings or {})
    layer_values = {k[len(LAYER_SETTING_PREFIX):]: settings.pop(k) for k in list(settings)
                    if k.startswith(LAYER_SETTING_PREFIX)}
    scenery_settings = parse_scenery_settings({k: settings.pop(k) for k in list(settings)
                                               if k.split(".")[0] in SCENERY_SETTINGS})
    renderer = cls(parse_settings(cls.Settings, settings), device=device)
    renderer.settings = renderer.resolved_settings(scene)
    width, height = resolve_resolution(scene, resolution)
    layer_settings = None
    traced_layers = bool(scene.layers) and traces_layers(cls)  # voxelised by the technique: no stratiform pass
    if scene.layers and not traced_layers:
        if not cls.renders_layers:
            raise UsageError(f"technique {technique} does not render stratiform layers "
                             f"({', '.join(layer.name for layer in scene.layers)}); use slicing or single_scatter")
        layer_settings = parse_settings(StratiformSettings, layer_values)
    scenery = scene_has_scenery(scene)
    traced_deck = bool(scene.heightfield_clouds) and traces_decks(cls)  # voxelised by it: no height-field pass
    refused = [(what, objects) for what, objects in (
        ("meshes", scene.meshes), ("analytic fog", scene.fogs),
        ("height-field clouds", () if traced_deck else scene.heightfield_clouds)) if objects]
    if refused and cls.traces_air:
        named = "; ".join(f"{what} ({', '.join(o.name for o in objects)})" for what, objects in refused)
        raise UsageError(f"technique {technique} does not render {named}; use hybrid, slicing or single_scatter")
    passes = tuple(name for name, runs in (
        ("surfaces", surfaces_pass_runs(scene) and not traced_deck),
        ("media", bool(scene.media) or traced_layers or traced_deck or not (scene.layers or scenery)),
        ("stratiform", bool(scene.layers) and not traced_layers),
        ("heightfield", bool(scene.heightfield_clouds) and not traced_deck),
        ("fog", bool(scene.fogs)),
        ("sky", scene.atmosphere is not None and not cls.traces_air),
    ) if runs)
    plan = RenderPlan(technique, renderer.settings, device, width, height, renderer, passes,
                      _features(scene, technique, layer_settings, layer_values), layer_settings,
                      scenery_settings=scenery_settings)
    if traced_layers:
        plan.features = layer_voxel_features(scene, renderer.settings, plan.features)
    if traced_deck:
        plan.features = deck_voxel_features(scene, renderer.settings, width, height, plan.features)
    plan.memory, plan.work = frame_memory(scene, plan), frame_work(scene, plan)
    return plan


def scene_has_scenery(scene: Scene) -> bool:
    """Whether ``scene`` holds meshes, height-field clouds or analytic fog (each drawn by its own pass)."""
    return bool(scene.meshes or scene.heightfield_clouds or scene.fogs)


def surfaces_pass_runs(scene: Scene) -> bool:
    """The surfaces pass draws the meshes, and the ground plane when no other pass would (no voxel media, no
    stratiform layers) in a scene of terrain, height-field clouds or fog."""
    return bool(scene.meshes) or (scene.ground is not None and scene_has_scenery(scene)
                                  and not scene.media and not scene.layers)


def surfaces_draw_ground(scene: Scene) -> bool:
    """Whether the surfaces pass, rather than the voxel technique or the stratiform pass, draws the ground plane."""
    return scene.ground is not None and not scene.media and not scene.layers


def _features(scene: Scene, technique: str, layer_settings, layer_values: dict) -> dict[str, str]:
    """What ``warpsky info`` prints about the scene, one line per feature."""
    features = {}
    if scene.sun is None:
        features["sun"] = "none (no visible DistantLight): media render black, transmittance only"
    else:
        sun = scene.sun
        features["sun"] = (
            f"{sun.name}: elevation {np.degrees(sun.elevation):.2f} deg, "
            f"irradiance {np.round(sun.irradiance, 4).tolist()}"
        )
    if scene.extra_suns:
        features["extra suns"] = (", ".join(f"{s.name} (elevation {np.degrees(s.elevation):.2f} deg)"
                                            for s in scene.extra_suns)
                                  + f": every pass runs {1 + len(scene.extra_suns)} times, once per light")
    if scene.dome is not None:
        features["dome"] = _dome_feature(scene, technique)
    if scene.media:
        voxels = sum(int(np.prod(m.shape)) for m in scene.media)
        features["media"] = f"{len(scene.media)} voxel grid(s), {voxels:,} voxels, {voxels * 4 / 2**20:.1f} MiB"
    elif scene.layers:
        features["media"] = f"none: {technique} does not run, the layers are rendered by the stratiform pass"
    else:
        features["media"] = "none"
    if layer_settings is not None:
        features.update(_layer_features(scene, layer_settings))
    else:
        unused = f" (unused: {', '.join(LAYER_SETTING_PREFIX + k for k in layer_values)})" if layer_values else ""
        features["layers"] = ('no layers (no prim with warpsky:kind = "stratiformLayer"): stratiform pass and '
                              "radiosity not built" + unused)
    features.update(_scenery_features(scene))
    species = scene.species
    if species:
        states = [f"{name} ({'cached' if is_cached(name) else 'to build'})" for name in species]
        features["optics"] = "phase tables for " + ", ".join(states)
    else:
        features["optics"] = "analytic phase only: no species fields, no tables built"
    features["sky"] = _sky_feature(scene)
    features["ground"] = (
        f"{scene.ground.name} at y = {scene.ground.height:g} m, albedo {np.round(scene.ground.albedo, 3).tolist()}"
        if scene.ground is not None
        else "off (no Plane prim): kernel built without the ground branch"
    )
    if scene.ground is not None and scene.ground.albedo_map is not None:
        tex = scene.ground.albedo_map
        features["ground"] += (f"; albedo map {tex.albedo.shape[0]}x{tex.albedo.shape[1]} over "
                               f"{tex.size[0]:g} x {tex.size[1]:g} m (stratiform pass only)")
    if scene.ground is not None and scene.layers:
        features["ground"] += "; drawn by the stratiform pass (layer shadows, radiosity), voxel media cast no shadow"
    elif scene.ground is not None and surfaces_pass_runs(scene) and surfaces_draw_ground(scene):
        features["ground"] += "; drawn by the surfaces pass (shadows of fog and height-field clouds)"
    return features


def _scenery_features(scene: Scene) -> dict[str, str]:
    """One line each for the meshes, the height-field clouds and the analytic fog: what is built for them, or that
    nothing is."""
    features = {}
    if scene.meshes:
        triangles = sum(len(m.triangles) for m in scene.meshes)
        features["meshes"] = (f"{len(scene.meshes)} mesh(es) ({', '.join(m.name for m in scene.meshes)}), "
                              f"{triangles:,} triangles: one Warp BVH, surfaces pass")
    else:
        features["meshes"] = "none (no Mesh prim): no BVH built"
    if scene.heightfield_clouds:
        lines = []
        for clouds in scene.heightfield_clouds:
            haze = "with haze" if clouds.haze is not None else "no haze"
            lines.append(f"{clouds.name}: mean plane {clouds.mean_altitude:g} m, {len(clouds.amplitudes)} waves, "
                         f"density {clouds.density:g} 1/m, {haze}")
        features["heightfield"] = "; ".join(lines) + " (Max 1986; single scattering, mode heightfield.mode)"
    else:
        features["heightfield"] = 'none (no prim with warpsky:kind = "heightFieldClouds")'
    if scene.fogs:
        features["fog"] = "; ".join(f"{fog.name}: {fog.describe()}" for fog in scene.fogs) + \
            " (Biri 2002, closed-form optical depths)"
    else:
        features["fog"] = 'none (no prim with warpsky:kind = "analyticFog")'
    return features


def _dome_feature(scene: Scene, technique: str) -> str:
    """How the dome lights this technique, and what it is."""
    from warpsky.light.dome import mean_radiance

    dome = scene.dome
    kind = f"lat-long texture {dome.source}" if dome.texture is not None else "uniform"
    how = ("path traced exactly" if technique in ("path_tracer", "hybrid")
           else "ambient: its mean radiance, occluded towards the zenith")
    return (f"{dome.name}: {kind}, mean radiance {np.round(mean_radiance(dome), 4).tolist()}; {how}; "
            "shown behind everything")


def _sky_feature(scene: Scene) -> str:
    if scene.atmosphere is None:
        return "off (no warpsky:atmosphere prim): black background, no sky pass"
    atm = scene.atmosphere
    night = scene.sun is None or scene.sun.direction[1] <= 0.0
    return (
        f"{atm.name}: analytic Riley single-scattering sky, aerial perspective and sun disk; betaSeaLevel "
        f"{np.round(atm.beta_sea_level * 1e6, 3).tolist()} /Mm, scale height {atm.scale_height:g} m, altitude "
        f"{atm.altitude:g} m" + ("; sun below the horizon: night (black sky)" if night else "")
    )


def _layer_features(scene: Scene, settings) -> dict[str, str]:
    """One ``layer`` line per stratiform layer and one ``radiosity`` line per layer: what the stratiform pass
    builds (map, optics, advection; the radiosity buffers and their size, or why there are none)."""
    features = {}
    count = len(scene.layers)
    for number, layer in enumerate(scene.layers, start=1):
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
        ground = scene.ground
        if ground is None or ground.height >= layer.base_altitude:
            state = "off: no ground below the layer"
        elif not settings.radiosity_for(layer):
            why = ("stratiform.radiosity=0" if settings.radiosity is not None
                   else f"warpsky:stratiform:radiosity = false on {layer.name}")
            state = f"off ({why}): sky and cloud light reach the ground once"
        else:
            detail = int(settings.radiosity_detail)
            _, pixel, (nu, nv) = radiosity_grid(layer, ground.height, detail)
            mib = nu * nv * 12 * RADIOSITY_BUFFERS / 2**20
            state = (f"on: ground <-> cloud base, buffers {nu}x{nv} texels of {pixel:g} m (h / 2^{detail}), "
                     f"{mib:.2f} MiB; rings gather, tolerance {settings.tolerance:g}, cap "
                     f"{int(settings.max_iterations)} iterations")
        features["radiosity" + suffix] = state
    return features
