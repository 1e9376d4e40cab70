"""A warpsky scene's voxel cloud in Blender Cycles 5: the peer renderer of ``evaluation/benchmarks/bench_cycles.py``.

The file has two halves that run in two Pythons. :func:`write_description` runs beside warpsky (``.venv``): it
takes a :class:`~warpsky.model.scene.Scene` already read from a stage and writes what Blender needs as plain data,
a JSON file and the density as ``.npy``, converted to Blender's frame. The command line (:func:`main`) runs in
bpy's Python (``.venv-cycles``, ``make cycles-env``: bpy 5.0 wants numpy < 2, which ``.venv`` does not have): it
writes the density as an OpenVDB grid once (``write-vdb``) and renders it (``render``). This module imports only
numpy at the top, so both Pythons can load it.

What the conversion keeps equal:

=============== ===================================================================================================
warpsky         Cycles
=============== ===================================================================================================
Y up, metres    Z up, metres (one Blender unit = 1 m): ``blender = (x, -z, y)``, a +90 deg turn about x
camera          pinhole looking down its local -Z with +Y up, as Blender's; the film back conformed to the image
                (USD's fit policy), given as ``sensor_fit='HORIZONTAL'`` with the same focal length / width ratio
sun             a Sun lamp of strength = the largest irradiance channel [W/m^2] and colour = irradiance / strength,
                angle 0: warpsky's media see the sun as one direction (its disc only shows to the camera)
medium          extinction ``extinction_scale * field`` [1/m] and albedo per RGB channel: Volume Scatter (HG, the
                stage's g) of density ``field * max(extinction)`` and colour ``albedo * extinction / max``, plus
                Volume Absorption of colour ``1 - (1 - albedo) * extinction / max`` when anything absorbs; the
                grid's index-to-world matrix in the VDB, float precision, density in world space
frame           black world, no ground, box pixel filter 1 px wide, 1024 bounces of every kind, no clamping, no
                adaptive sampling, Standard view transform (the EXR is linear Rec.709 radiance either way)
=============== ===================================================================================================

Cycles 5 renders volumes unbiased by default (null scattering against majorant grids, ``volume_biased=False``),
so it has no step length to choose. Variants (``--variant``): ``path`` (plain path tracing), ``oidn`` (+ Open Image
Denoise on the RGB, albedo and normal passes), ``guided_oidn`` (+ path guiding in volumes, CPU only, then OIDN).

Run (bpy's Python):
    .venv-cycles/bin/python evaluation/cycles_scene.py write-vdb DESCRIPTION.json
    .venv-cycles/bin/python evaluation/cycles_scene.py render DESCRIPTION.json OUT.exr --samples 64 --variant oidn
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

#: Rotation from warpsky's world (Y up) to Blender's (Z up), both right-handed, for column vectors.
BLENDER_FROM_WARPSKY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: Cycles' largest bounce count, used for every kind of bounce.
MAX_BOUNCES = 1024
VARIANTS = ("path", "oidn", "guided_oidn")
#: Blender's sensor width the camera is given [mm]; only its ratio to the focal length matters.
SENSOR_WIDTH = 36.0


def affine(rotation: np.ndarray, translation) -> np.ndarray:
    """4x4 matrix (column vectors) of a 3x3 ``rotation`` then a ``translation``."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def camera_description(camera, width: int, height: int) -> dict:
    """Blender's camera for warpsky's ``camera`` conformed to ``width`` x ``height`` pixels: ``matrix_world``
    (4x4, Blender's frame), ``lens`` and ``sensor_width`` [mm] for a horizontal sensor fit, ``shift_x``,
    ``shift_y`` (fractions of the sensor width, Blender's unit when the fit is horizontal) and clipping [m]."""
    if getattr(camera.projection, "name", "PERSPECTIVE") != "PERSPECTIVE":
        raise ValueError(f"camera {camera.name}: only perspective cameras convert to Cycles")
    conformed = camera.conformed(width, height)
    aperture = float(conformed.horizontal_aperture)
    rotation = BLENDER_FROM_WARPSKY @ np.asarray(camera.rotation, dtype=np.float64)
    position = BLENDER_FROM_WARPSKY @ np.asarray(camera.position, dtype=np.float64)
    return {"matrix_world": affine(rotation, position).tolist(),
            "lens": SENSOR_WIDTH * float(conformed.focal_length) / aperture,
            "sensor_width": SENSOR_WIDTH,
            "shift_x": float(conformed.horizontal_aperture_offset) / aperture,
            "shift_y": float(conformed.vertical_aperture_offset) / aperture,
            "clip_start": float(camera.near), "clip_end": float(camera.far)}


def sun_rotation(towards_sun: np.ndarray) -> np.ndarray:
    """3x3 rotation whose local +Z is ``towards_sun`` (unit, Blender's frame): a Sun lamp shines down its local -Z."""
    z = np.asarray(towards_sun, dtype=np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def sun_description(sun) -> dict:
    """Blender's Sun lamp for warpsky's ``sun``: ``matrix_world`` (rotation only), ``strength`` [W/m^2] (Blender's
    sun strength is the irradiance at normal incidence) and ``color`` (irradiance / strength, each <= 1)."""
    irradiance = np.asarray(sun.irradiance, dtype=np.float64) * np.asarray(sun.transmittance, dtype=np.float64)
    strength = float(irradiance.max())
    if strength <= 0.0:
        raise ValueError(f"sun {sun.name}: no irradiance")
    towards = BLENDER_FROM_WARPSKY @ np.asarray(sun.direction, dtype=np.float64)
    return {"matrix_world": affine(sun_rotation(towards), np.zeros(3)).tolist(), "strength": strength,
            "color": (irradiance / strength).tolist(), "angle": 0.0}


def medium_description(medium) -> dict:
    """Blender's volume material for warpsky's voxel ``medium``: ``density_scale`` [1/m per field unit] (the
    largest extinction channel), the Volume Scatter and Volume Absorption colours, the HG asymmetry ``g``, and
    ``vdb_matrix``, the grid's index-to-world matrix in Blender's frame (4x4, column vectors)."""
    if medium.species is not None or medium.phase.kind.name != "HG":
        raise ValueError(f"medium {medium.name}: Cycles gets Henyey-Greenstein media only (species "
                         f"{medium.species}, phase {medium.phase!r}); use a stage variant with warpsky:phase = 'hg'")
    if medium.detail is not None:
        raise ValueError(f"medium {medium.name}: animated density detail has no Cycles counterpart")
    extinction = np.asarray(medium.extinction_scale, dtype=np.float64)
    albedo = np.asarray(medium.albedo, dtype=np.float64)
    scale = float(extinction.max())
    blender_from_world = affine(BLENDER_FROM_WARPSKY, np.zeros(3))
    return {"density_scale": scale,
            "scatter_color": (albedo * extinction / scale).tolist(),
            "absorption_color": (1.0 - (1.0 - albedo) * extinction / scale).tolist(),
            "g": float(medium.phase.g),
            "vdb_matrix": (blender_from_world @ np.asarray(medium.world_from_index, dtype=np.float64)).tolist()}


def write_description(scene, width: int, height: int, folder: Path) -> Path:
    """Write ``folder/cycles_scene.json`` and ``folder/density.npy`` (float32 [x, y, z]) for ``scene``'s one
    voxel medium, camera and sun at ``width`` x ``height``; the scene must hold nothing Cycles is not given (no
    air, ground, dome, other suns, meshes, fog, decks or stratiform layers). Returns the JSON's path."""
    extra = [name for name, value in (("atmosphere", scene.atmosphere), ("ground", scene.ground),
                                      ("dome", scene.dome), ("extra_suns", scene.extra_suns),
                                      ("meshes", scene.meshes), ("fogs", scene.fogs), ("decks", scene.decks),
                                      ("stratiform_layers", scene.stratiform_layers)) if value]
    if extra or len(scene.media) != 1 or scene.sun is None:
        raise ValueError(f"Cycles gets one voxel medium under one sun, nothing else: the scene has {extra}, "
                         f"{len(scene.media)} media, sun {scene.sun is not None}")
    folder.mkdir(parents=True, exist_ok=True)
    medium = scene.media[0]
    np.save(folder / "density.npy", np.ascontiguousarray(medium.density, dtype=np.float32))
    description = {"width": width, "height": height, "source": str(scene.source),
                   "camera": camera_description(scene.camera, width, height), "sun": sun_description(scene.sun),
                   "medium": medium_description(medium), "density": "density.npy", "vdb": "density.vdb"}
    path = folder / "cycles_scene.json"
    path.write_text(json.dumps(description, indent=1))
    return path


# ---- the bpy half: everything below runs in bpy's Python -------------------------------------------------------

def _import_openvdb():
    """bpy 5 bundles the openvdb module inside its own site-packages, which is not on sys.path."""
    import bpy

    root = Path(bpy.__file__).resolve().parents[3]  # .../bpy/5.0/scripts/modules/bpy/__init__.py -> .../bpy/5.0
    sys.path.append(str(root / "python" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}"
                        / "site-packages"))
    import openvdb

    return openvdb


def write_vdb(description_path: Path) -> Path:
    """The description's density as an OpenVDB float grid named ``density`` (a fog volume), its index-to-world
    transform in Blender's frame, zero background."""
    vdb = _import_openvdb()
    description = json.loads(description_path.read_text())
    density = np.load(description_path.parent / description["density"]).astype(np.float32)
    grid = vdb.FloatGrid(0.0)
    grid.copyFromArray(density, ijk=(0, 0, 0), tolerance=0.0)
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    # OpenVDB's matrices act on row vectors: the transpose of ours.
    grid.transform = vdb.createLinearTransform(np.asarray(description["medium"]["vdb_matrix"]).T.tolist())
    out = description_path.parent / description["vdb"]
    vdb.write(str(out), grids=[grid])
    return out


def _volume_material(bpy, medium: dict):
    """Volume Scatter (HG) + Volume Absorption reading the grid's ``density`` attribute scaled to 1/m."""
    material = bpy.data.materials.new("cloud")
    tree = material.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type, attribute.attribute_name = "GEOMETRY", "density"
    scale = tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = medium["density_scale"]
    tree.links.new(attribute.outputs["Fac"], scale.inputs[0])
    scatter = tree.nodes.new("ShaderNodeVolumeScatter")
    scatter.phase = "HENYEY_GREENSTEIN"
    scatter.inputs["Anisotropy"].default_value = medium["g"]
    scatter.inputs["Color"].default_value = (*medium["scatter_color"], 1.0)
    tree.links.new(scale.outputs[0], scatter.inputs["Density"])
    shader = scatter.outputs[0]
    if min(medium["absorption_color"]) < 1.0:
        absorption = tree.nodes.new("ShaderNodeVolumeAbsorption")
        absorption.inputs["Color"].default_value = (*medium["absorption_color"], 1.0)
        tree.links.new(scale.outputs[0], absorption.inputs["Density"])
        add = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(shader, add.inputs[0])
        tree.links.new(absorption.outputs[0], add.inputs[1])
        shader = add.outputs[0]
    tree.links.new(shader, output.inputs["Volume"])
    return material


def _matrix(bpy_matrix_type, rows):
    return bpy_matrix_type([list(row) for row in rows])


def build_scene(description: dict, folder: Path):
    """A fresh Blender scene of the description: the cloud, camera, sun and a black world."""
    import bpy
    from mathutils import Matrix

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    volume = bpy.data.volumes.new("cloud")
    volume.filepath = str(folder / description["vdb"])
    volume.render.precision, volume.render.space = "FULL", "WORLD"
    cloud = bpy.data.objects.new("cloud", volume)
    cloud.data.materials.append(_volume_material(bpy, description["medium"]))
    scene.collection.objects.link(cloud)
    spec = description["camera"]
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.sensor_fit, camera.data.sensor_width, camera.data.lens = "HORIZONTAL", spec["sensor_width"], \
        spec["lens"]
    camera.data.shift_x, camera.data.shift_y = spec["shift_x"], spec["shift_y"]
    camera.data.clip_start, camera.data.clip_end = spec["clip_start"], spec["clip_end"]
    camera.matrix_world = _matrix(Matrix, spec["matrix_world"])
    scene.collection.objects.link(camera)
    scene.camera = camera
    spec = description["sun"]
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", type="SUN"))
    sun.data.energy, sun.data.color, sun.data.angle = spec["strength"], spec["color"], spec["angle"]
    sun.matrix_world = _matrix(Matrix, spec["matrix_world"])
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("black")
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def configure(scene, description: dict, *, samples: int, variant: str, seed: int, threads: int) -> None:
    """Cycles' settings of one measured render (see the module docstring)."""
    render, cycles = scene.render, scene.cycles
    render.engine = "CYCLES"
    render.resolution_x, render.resolution_y, render.resolution_percentage = (description["width"],
                                                                             description["height"], 100)
    render.threads_mode, render.threads = ("FIXED", threads) if threads else ("AUTO", 1)
    render.film_transparent = False
    cycles.device = "CPU"
    cycles.samples, cycles.seed = samples, seed
    cycles.use_adaptive_sampling = False
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.pixel_filter_type, cycles.filter_width = "BOX", 1.0
    for name in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces",
                 "transparent_max_bounces"):
        setattr(cycles, name, MAX_BOUNCES)
    cycles.volume_biased = False
    cycles.use_denoising = variant != "path"
    if cycles.use_denoising:
        cycles.denoiser, cycles.denoising_input_passes = "OPENIMAGEDENOISE", "RGB_ALBEDO_NORMAL"
        cycles.denoising_prefilter, cycles.denoising_quality = "ACCURATE", "HIGH"
    cycles.use_guiding = variant == "guided_oidn"
    cycles.use_volume_guiding, cycles.use_surface_guiding = True, False
    view = scene.view_settings
    view.view_transform, view.look, view.exposure, view.gamma = "Standard", "None", 0.0, 1.0
    scene.display_settings.display_device = "sRGB"
    image = render.image_settings
    image.file_format, image.color_depth, image.exr_codec = "OPEN_EXR", "32", "ZIP"
    image.color_mode = "RGBA"


def _status_times(stats: list[tuple[float, str]]) -> list[tuple[float, str]]:
    """Cycles' status lines (the text after the last ``|``) with the seconds into the render call each first
    showed: where the time before the first sample goes."""
    out: list[tuple[float, str]] = []
    for seconds, text in stats:
        status = text.rsplit("|", 1)[-1].strip()
        status = status.split(" Sample ")[0] if "Sample" in status else status
        if not out or out[-1][1] != status:
            out.append((round(seconds, 3), status))
    return out


def render(description_path: Path, out: Path, *, samples: int, variant: str, seed: int = 0,
           threads: int = 0) -> dict:
    """Render the description to ``out`` (32-bit float EXR, linear radiance) and write ``out`` with ``.json``:
    ``render_seconds`` (the wall time of Cycles' render call: scene sync, BVH, volume upload, sampling,
    denoising; not Blender's start-up nor the EXR write) and ``cycles_status``, Cycles' status lines with the
    seconds each first showed."""
    import bpy

    description = json.loads(description_path.read_text())
    scene = build_scene(description, description_path.parent)
    configure(scene, description, samples=samples, variant=variant, seed=seed, threads=threads)
    scene.render.filepath = str(out)
    stats: list[tuple[float, str]] = []
    started = time.perf_counter()
    bpy.app.handlers.render_stats.append(lambda text: stats.append((time.perf_counter() - started, str(text))))
    bpy.ops.render.render(write_still=False)
    seconds = time.perf_counter() - started
    bpy.data.images["Render Result"].save_render(str(out), scene=scene)
    record = {"render_seconds": seconds, "samples": samples, "variant": variant, "seed": seed,
              "blender": bpy.app.version_string, "cycles_status": _status_times(stats),
              "threads": scene.render.threads}
    record["first_sample_seconds"] = next((t for t, text in record["cycles_status"] if text.startswith("Sample")),
                                          math.nan)
    out.with_suffix(".json").write_text(json.dumps(record, indent=1))
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("write-vdb", help="write the description's density as OpenVDB").add_argument(
        "description", type=Path)
    run = commands.add_parser("render", help="render the description with Cycles to an EXR")
    run.add_argument("description", type=Path)
    run.add_argument("out", type=Path)
    run.add_argument("--samples", type=int, default=16)
    run.add_argument("--variant", choices=VARIANTS, default="path")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--threads", type=int, default=0, help="render threads (default 0: every core)")
    args = parser.parse_args(argv)
    if args.command == "write-vdb":
        print(write_vdb(args.description))
        return 0
    record = render(args.description.resolve(), args.out.resolve(), samples=args.samples, variant=args.variant,
                    seed=args.seed, threads=args.threads)
    print(f"{args.out}: {record['render_seconds']:.2f} s in Cycles' render call, the first sample at "
          f"{record['first_sample_seconds']:.2f} s")
    return 0 if math.isfinite(record["render_seconds"]) else 1


if __name__ == "__main__":
    sys.exit(main())
