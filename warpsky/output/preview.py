"""Pictures to look at instead of reading: a 3-D preview of a stage, and contact sheets of rendered frames.

``stage_preview`` draws, with pyvista offscreen (EGL; no X server needed): every voxel medium as a density
isosurface (coloured per species), the camera frustum (to the far end of the scene), the sun direction as an
arrow towards the sun, the ground plane and the extents of stratiform layers, with a legend. ``contact_sheet``
tiles tone-mapped EXR frames (the same tone map as ``--png``) with their frame numbers.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from warpsky.core.errors import OutputError, UsageError
from warpsky.core.files import PLACEHOLDER, atomic_write
from warpsky.output.exr import read_exr
from warpsky.output.png import DEFAULT_VIEW, auto_exposure, encode

#: Isosurface colour per species (generic density fields are white).
SPECIES_COLOURS = {"cloud": "#f2f2f2", "rain": "#4f7fd9", "ice": "#8fe3ff", "snow": "#c9b8ff", "air": "#9fc5ff"}


def _pyvista():
    # Without a display VTK would try X first and print a warning; ask for EGL directly.
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except ImportError:
        raise UsageError("warpsky preview needs pyvista: pip install 'warpsky[preview]'") from None
    pv.OFF_SCREEN = True
    return pv


def scene_bounds(scene) -> tuple[np.ndarray, np.ndarray]:
    """World box [m] around media, layers and the camera."""
    points = [scene.camera.position]
    for medium in scene.media:
        points.extend(medium.world_corners())
    for layer in getattr(scene, "stratiform_layers", ()):
        (x0, z0), (sx, sz) = layer.origin, layer.size
        top = layer.base_altitude + float(np.max(layer.thickness, initial=0.0))
        points += [(x0, layer.base_altitude, z0), (x0 + sx, top, z0 + sz)]
    points = np.asarray(points, dtype=np.float64)
    return points.min(axis=0), points.max(axis=0)


def _medium_mesh(pv, medium, level: float):
    """Isosurface of a medium's density at ``level`` x its maximum, in world metres (None if empty)."""
    density = np.asarray(medium.density, dtype=np.float32)
    peak = float(density.max())
    if peak <= 0.0:
        return None
    stride = max(1, int(np.ceil(max(density.shape) / 128)))  # keep previews quick on big grids
    grid = pv.ImageData(dimensions=density[::stride, ::stride, ::stride].shape, spacing=(stride,) * 3)
    grid.point_data["density"] = density[::stride, ::stride, ::stride].ravel(order="F")
    surface = grid.contour([level * peak], scalars="density")
    if surface.n_points == 0:
        return None
    return surface.transform(np.asarray(medium.world_from_index, dtype=np.float64), inplace=False)


def _add_legend(plotter, entries: list) -> None:
    """The legend in the image's upper right corner, wholly inside it. The box is placed here rather than by
    pyvista's ``loc``, which (0.49) offsets it from the right edge by its height instead of its width."""
    margin = 0.02  # of the image's width and height
    width, height = 0.5, min(0.045 * len(entries), 1.0 - 2 * margin)
    actor = plotter.add_legend(entries, bcolor=(0.08, 0.09, 0.1), size=(width, height), face="rectangle")
    actor.SetPosition(1.0 - width - margin, 1.0 - height - margin)
    actor.SetPosition2(width, height)


def stage_preview(scene, path: str | os.PathLike, *, size: tuple[int, int] = (1024, 768), level: float = 0.2) -> Path:
    """Write a PNG overview of ``scene`` (see the module docstring); returns its path."""
    pv = _pyvista()
    lo, hi = scene_bounds(scene)
    extent = float(np.max(hi - lo)) or 1.0
    centre = 0.5 * (lo + hi)
    plotter = pv.Plotter(off_screen=True, window_size=size)
    plotter.set_background("#20252b", top="#4a6a8a")
    legend = []
    for medium in scene.media:
        mesh = _medium_mesh(pv, medium, level)
        if mesh is None:
            continue
        colour = SPECIES_COLOURS.get(medium.species or "", "#ffffff")
        plotter.add_mesh(mesh, color=colour, opacity=0.55 if medium.species in ("rain", "ice", "snow") else 0.9,
                         smooth_shading=True)
        legend.append([f"{medium.name} ({medium.species or 'density'})", colour])
    for layer in getattr(scene, "stratiform_layers", ()):
        (x0, z0), (sx, sz) = layer.origin, layer.size
        top = layer.base_altitude + float(np.max(layer.thickness, initial=0.0))
        box = pv.Box(bounds=(x0, x0 + sx, layer.base_altitude, max(top, layer.base_altitude + 1.0), z0, z0 + sz))
        plotter.add_mesh(box, color="#d0d0d0", style="wireframe", line_width=2)
        legend.append([f"{layer.name} (stratiform layer)", "#d0d0d0"])
    if scene.ground is not None:
        plane = pv.Plane(center=(centre[0], scene.ground.height, centre[2]), direction=(0, 1, 0),
                         i_size=2.0 * extent, j_size=2.0 * extent)
        plotter.add_mesh(plane, color=tuple(np.clip(scene.ground.albedo * 2.5, 0, 1)), opacity=0.8)
        legend.append([f"{scene.ground.name} (ground)", "#9aa08a"])
    camera = scene.camera
    depth = max(float(np.linalg.norm(centre - camera.position)), 0.25 * extent)  # the frustum reaches the scene
    half_w = 0.5 * camera.horizontal_aperture / camera.focal_length * depth
    half_h = 0.5 * camera.vertical_aperture / camera.focal_length * depth
    right, up, back = (camera.rotation[:, i] for i in range(3))
    apex = camera.position
    corners = [apex - back * depth + right * sx * half_w + up * sy * half_h for sx, sy in
               ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    lines = []
    for i, corner in enumerate(corners):
        lines += [apex, corner, corner, corners[(i + 1) % 4]]
    plotter.add_mesh(pv.line_segments_from_points(np.asarray(lines)), color="#ffd54a", line_width=2)
    legend.append([f"{camera.name} (frustum)", "#ffd54a"])
    if scene.sun is not None:
        arrow = pv.Arrow(start=centre, direction=scene.sun.direction, scale=0.4 * extent)
        plotter.add_mesh(arrow, color="#ff9a2e")
        legend.append([f"{scene.sun.name} (sun at {np.degrees(scene.sun.elevation):.1f} deg)", "#ff9a2e"])
    if legend:
        _add_legend(plotter, legend)
    plotter.camera_position = [tuple(centre + extent * np.array([1.1, 0.8, 1.4])), tuple(centre), (0.0, 1.0, 0.0)]
    plotter.add_axes()
    image = plotter.screenshot(return_img=True)
    plotter.close()
    from PIL import Image

    return atomic_write(path, lambda tmp: Image.fromarray(np.asarray(image)[..., :3]).save(tmp, format="PNG"))


def frame_paths(pattern: str) -> list[tuple[float, Path]]:
    """(frame number, path) of the EXRs matching a ``####`` pattern, in frame order."""
    match = PLACEHOLDER.search(Path(pattern).name)
    if match is None:
        raise UsageError(f"{pattern!r} has no frame placeholder (e.g. out/storm.####.exr)")
    name = Path(pattern).name
    regex = re.compile(re.escape(name[: match.start()]) + r"(-?[0-9]+(?:\.[0-9]+)?)" + re.escape(name[match.end():])
                       + "$")
    folder = Path(pattern).parent
    found = []
    for path in folder.iterdir() if folder.is_dir() else []:
        m = regex.match(path.name)
        if m:
            found.append((float(m.group(1)), path))
    if not found:
        raise UsageError(f"no frames match {pattern!r} in {folder}")
    return sorted(found)


def contact_sheet(pattern: str, path: str | os.PathLike, *, columns: int | None = None, tile_width: int = 256,
                  exposure: float | None = None, view: str = DEFAULT_VIEW) -> Path:
    """Tile the frames matching ``pattern`` through the display ``view`` with their numbers; unreadable frames show
    as red tiles. ``exposure`` defaults to the renderer's preview exposure stored in the first frame
    (``previewExposure``), else to the first frame's automatic one; the whole sheet uses one exposure."""
    from PIL import Image, ImageDraw

    frames = frame_paths(pattern)
    columns = columns or int(np.ceil(np.sqrt(len(frames) * 1.5)))
    images = []
    for number, frame_path in frames:
        try:
            image = read_exr(frame_path)
        except OutputError:
            images.append((number, None, {}))
            continue
        rgb = np.stack([image.channels[c] for c in ("R", "G", "B")], axis=-1).astype(np.float32)
        images.append((number, rgb, image.metadata))
    if exposure is None:  # one exposure for the whole sheet, so a sequence does not flicker
        number, rgb, metadata = next((entry for entry in images if entry[1] is not None), (0, None, {}))
        exposure = float(metadata.get("previewExposure", 0.0)) or (auto_exposure(rgb) if rgb is not None else 1.0)
    tiles = [(number, None if rgb is None else Image.fromarray(encode(rgb, exposure=exposure, view=view),
                                                               mode="RGB"))
             for number, rgb, _ in images]
    first = next((t for _, t in tiles if t is not None), None)
    aspect = first.height / first.width if first is not None else 0.75
    tile_height = max(1, round(tile_width * aspect))
    label = 18
    rows = int(np.ceil(len(tiles) / columns))
    sheet = Image.new("RGB", (columns * tile_width, rows * (tile_height + label)), "#111111")
    draw = ImageDraw.Draw(sheet)
    for i, (number, tile) in enumerate(tiles):
        x, y = (i % columns) * tile_width, (i // columns) * (tile_height + label)
        if tile is None:
            draw.rectangle([x, y, x + tile_width - 1, y + tile_height - 1], fill="#7a1010")
            text = f"{number:g} (unreadable)"
        else:
            sheet.paste(tile.resize((tile_width, tile_height), Image.Resampling.BILINEAR), (x, y))
            text = f"{number:g}"
        draw.text((x + 4, y + tile_height + 2), text, fill="#e0e0e0")
    return atomic_write(path, lambda tmp: sheet.save(tmp, format="PNG"))
