"""``warpsky bench error-vs-time``: every technique's error against a converged path-traced reference, and its time.

The reference is the path tracer at ``reference_spp`` samples with its own seed, cached on disk under
``$WARPSKY_CACHE/reference`` (keyed by a hash of the scene as read — media, camera, sun, ground —, the resolution,
device kind, samples and seed) so repeated reports do not pay for
it. Each technique then renders along its quality ladder; every rung is timed after one untimed render of that
technique (first-compile time is excluded, and the report says so). Errors are taken over *covered* pixels (the
reference's luminance transmittance below 0.99, or every lit pixel under a sky) on the frame's radiance (the
technique's layer composited with the sky pass when the scene has an atmosphere; the path tracer traces the air):

=================== ===================================================================================
column              meaning
=================== ===================================================================================
rel_rmse            sqrt(mean((x - r)^2)) / mean(r), over covered pixels and channels
mean_rel, p95_rel   mean and 95th percentile of |x - r| / max(r, 1e-2 mean(r)) per covered pixel/channel
bias                (mean(x) - mean(r)) / mean(r): the part of the error more samples do not remove
net_rmse            rel_rmse with the reference's own variance taken out (an estimate of the error against
                    the exact image; see :func:`error_metrics`)
=================== ===================================================================================

The reference's own noise is reported as ``reference_rel_noise`` (relative standard error of the covered mean,
and per-pixel relative RMS noise): errors below it are not resolved.

Stratiform layers (Bouthors 2006) are judged too: the reference path-traces them voxelised
(:mod:`warpsky.techniques.path_tracer.stratiform_media`), while the other techniques run next to the stratiform pass.
Their rows read ``<technique> + stratiform pass`` when the stage also holds voxel media; on a stage of layers
alone every voxel technique's frame is the stratiform pass's, so one row family, ``stratiform pass (Bouthors
2006)``, walks the radiosity buffers' resolution (``stratiform.radiosity_detail``). Both sides see the ground at its
uniform albedo: the ground's albedo map, which the path tracer does not trace, is left out of the measured scene.

Height-field cloud decks (Max 1986) likewise: the reference path-traces the deck and its haze voxelised
(:mod:`warpsky.techniques.path_tracer.deck_media`); on a deck stage without voxel media every voxel technique's
frame is the deck pass's, measured once per mode (``deck pass (Max 1986, exact)``, ``max``,
``sexp``) along ``deck.step_length``. That pass is single scattering only, so its bias against the
path-traced multiple scattering is expected to be negative.

Terrain meshes and analytic fog (Biri et al. 2002) likewise: the reference traces them
(:mod:`warpsky.techniques.path_tracer.surface_hits`, :mod:`~warpsky.techniques.path_tracer.fog_media`), the other
techniques leave them to the surfaces and fog passes, so on a stage of fog over terrain without voxel media each
technique's rows measure those passes. On a stage with meshes or fog the covered pixels are
:func:`scenery_covered`'s (everything but open sky): a sun's disk in frame would otherwise dominate the mean and
the reference's variance (on valley_fog.usda at 96 x 64 it made the per-pixel noise 1.6 of the mean).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.core.files import atomic_write, cache_dir
from warpsky.core.version import __version__
from warpsky.passes.composite import composite
from warpsky.passes.frame import render_layers
from warpsky.passes.media import scenery_traceable
from warpsky.render.plan import RenderPlan, make_plan
from warpsky.render.registry import technique_class
from warpsky.techniques.path_tracer.deck_media import traces_decks

#: Techniques the report knows how to walk, with their quality ladders.
LADDERS = {
    "slicing": [{"slice_count": n} for n in (16, 32, 64, 128, 256, 512)],
    "single_scatter": [{"step_length": k, "shadow_step_length": k} for k in (4.0, 2.0, 1.0, 0.5, 0.25)],
    "path_tracer": [{"spp": n} for n in (1, 2, 4, 8, 16, 32, 64, 128, 256)],
    "hybrid": [{"spp": n, "target_error": 0.0} for n in (1, 2, 4, 8, 16, 32, 64)],
}
#: Ladder settings given in voxel edges (multiplied by the scene's smallest voxel edge).
VOXEL_SETTINGS = ("step_length", "shadow_step_length")
#: Row name of the stratiform pass measured on a stage of layers without voxel media, and its ladder.
STRATIFORM_ROW = "stratiform pass (Bouthors 2006)"
STRATIFORM_LADDER = [{"stratiform.radiosity_detail": d} for d in (0, 1, 2)]
#: Row names of the deck pass (Max 1986) measured on a deck stage without voxel media, one per mode, and
#: its ladder: ``deck.step_length`` as these multiples of the pass's automatic cloud step.
HEIGHTFIELD_ROW = "deck pass (Max 1986, {mode})"
HEIGHTFIELD_MODES = ("exact", "max", "sexp")
HEIGHTFIELD_STEPS = (2.0, 1.0, 0.5)


@dataclass
class Row:
    technique: str
    setting: str
    seconds: float
    rel_rmse: float
    mean_rel: float
    p95_rel: float
    bias: float
    net_rmse: float = math.nan


@dataclass
class Report:
    rows: list[Row]
    reference: dict = field(default_factory=dict)


def _reference_key(scene, width, height, device, spp, seed) -> str:
    """Hash of everything the reference's pixels depend on: the scene as read (media, camera, sun, ground)."""
    digest = hashlib.sha256(pickle.dumps(scene, protocol=4))
    digest.update(json.dumps([width, height, "cuda" in str(device), spp, seed, __version__]).encode())
    return digest.hexdigest()[:20]


def frame_plan(scene, technique: str, values: dict, width: int, height: int, device: str) -> RenderPlan:
    """The plan of one measured frame: ``technique`` with the settings ``values`` (numbers), resolved for
    ``scene``."""
    return make_plan(scene, technique=technique,
                     settings={k: v if isinstance(v, str) else repr(v) for k, v in values.items()},
                     resolution=(width, height), device=device)


def render_frame_radiance(plan: RenderPlan, scene):
    """(frame radiance (H, W, 3), transmittance, frame aovs, technique layer): the plan's passes composited (the
    technique's layer with the sky pass when the scene has an atmosphere), so techniques compare on what a frame
    shows."""
    layer, layers = render_layers(plan, scene)
    frame = composite(layers, far=scene.camera.far)
    return frame.rgba[..., :3], frame.transmittance, frame.aovs, layer


def reference_image(scene, width, height, device, *, spp: int, seed: int, use_cache: bool = True,
                    cache_path: Path | None = None, max_bounces: int | None = None):
    """(radiance, transmittance, variance, seconds, cached) of the path-traced reference frame, cached at
    ``cache_path`` (default: under ``$WARPSKY_CACHE/reference`` by a hash of the scene and the device kind). The
    file also holds ``capped_paths``, the paths cut at ``max_bounces`` (the path tracer's default when None)."""
    path = cache_path or cache_dir() / "reference" / f"{_reference_key(scene, width, height, device, spp, seed)}.npz"
    if use_cache and path.is_file():
        with np.load(path) as data:
            return data["radiance"], data["transmittance"], data["variance"], float(data["seconds"]), True
    values = {"spp": spp, "seed": seed} | ({} if max_bounces is None else {"max_bounces": max_bounces})
    plan = frame_plan(scene, "path_tracer", values, width, height, device)
    radiance, transmittance, aovs, layer = render_frame_radiance(plan, scene)
    arrays = {"radiance": radiance, "transmittance": transmittance, "variance": aovs["variance"],
              "seconds": np.float64(layer.stats["seconds"]),
              "capped_paths": np.int64(layer.stats.get("capped_paths", 0))}
    atomic_write(path, lambda tmp: np.savez(tmp, **arrays))
    return radiance, transmittance, aovs["variance"], layer.stats["seconds"], False


def has_scenery(scene) -> bool:
    """Whether ``scene`` holds terrain meshes, analytic fog or a height-field deck."""
    return bool(scene.meshes or scene.fogs or scene.decks)


def scenery_covered(scene, width: int, height: int, device: str, level: float = 0.99) -> np.ndarray:
    """(H, W) bool: pixels where the frame without the air (``single_scatter`` and the scenery passes) transmits
    less than ``level`` of the luminance: terrain, ground, fog, deck, haze and media, not open sky nor the sun's
    disk in it. Noise-free."""
    clear = dataclasses.replace(scene, atmosphere=None)
    _, transmittance, _, _ = render_frame_radiance(frame_plan(clear, "single_scatter", {}, width, height, device),
                                                   clear)
    seen = (transmittance @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)) < level
    return seen & ~sun_disk_pixels(scene, width, height)


def sun_disk_pixels(scene, width: int, height: int) -> np.ndarray:
    """(H, W) bool: pixels of a pinhole camera whose centre ray lies within the sun's angular radius plus the
    pixel's diagonal of a sun's centre (every sun of the scene): where the disk may show, through fog or thin
    cloud, at 1e4 times the scene's radiance."""
    out = np.zeros((height, width), dtype=bool)
    camera = scene.camera.conformed(width, height)
    suns = [sun for sun in (scene.sun, *scene.extra_suns) if sun is not None]
    if not suns or camera.projection.name == "ORTHOGRAPHIC":
        return out
    sx = ((np.arange(width) + 0.5) / width - 0.5) * camera.horizontal_aperture + camera.horizontal_aperture_offset
    sy = (0.5 - (np.arange(height) + 0.5) / height) * camera.vertical_aperture + camera.vertical_aperture_offset
    local = np.stack(np.broadcast_arrays(sx[None, :], sy[:, None], -float(camera.focal_length)), axis=-1)
    rays = local @ np.asarray(camera.rotation, dtype=np.float64).reshape(3, 3).T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    pixel = math.hypot(camera.horizontal_aperture / width, camera.vertical_aperture / height) / camera.focal_length
    for sun in suns:
        reach = 0.5 * float(sun.angular_diameter) + pixel
        out |= rays @ np.asarray(sun.direction, dtype=np.float64) > math.cos(reach)
    return out


def error_metrics(image: np.ndarray, reference: np.ndarray, covered: np.ndarray,
                  reference_variance: np.ndarray | None = None) -> dict:
    """The report's error columns for ``image`` against ``reference`` over ``covered`` pixels (H, W) bool. With
    the reference's per-pixel ``reference_variance`` (of its mean), ``net_rmse`` is the relative RMSE with the
    reference's own noise taken out: sqrt(max(MSE - mean variance, 0)) / mean(r), an estimate of the error
    against the exact image (NaN without it)."""
    x = image[covered].astype(np.float64)
    r = reference[covered].astype(np.float64)
    if r.size == 0:
        raise UsageError("the reference covers no pixel: nothing to measure (is the camera looking at the media?)")
    mean_r = float(r.mean())
    if mean_r <= 0.0:
        raise UsageError("the reference is black over the covered pixels: is the sun below the horizon?")
    rel = np.abs(x - r) / np.maximum(r, 1e-2 * mean_r)
    out = {
        "rel_rmse": float(np.sqrt(np.mean((x - r) ** 2)) / mean_r),
        "mean_rel": float(rel.mean()),
        "p95_rel": float(np.percentile(rel, 95)),
        "bias": float((x.mean() - mean_r) / mean_r),
        "net_rmse": math.nan,
    }
    if reference_variance is not None:
        mse = float(np.mean((x - r) ** 2)) - float(np.mean(reference_variance[covered].astype(np.float64)))
        out["net_rmse"] = math.sqrt(max(mse, 0.0)) / mean_r
    return out


def setting_label(values: dict) -> str:
    return ", ".join(f"{k.split('.')[-1]}={v if isinstance(v, str) else format(v, '.4g')}"
                     for k, v in values.items() if k not in ("shadow_step_length", "deck.mode"))


def comparable_scene(scene, log=print):
    """``scene`` as both sides of the report can render it: with stratiform layers, the ground's albedo map (which
    only the stratiform pass reads) is left out, so both see the ground's uniform albedo."""
    ground = scene.ground
    if not scene.stratiform_layers or ground is None or ground.albedo_map is None:
        return scene
    log(f"ground {ground.name}: albedo map left out of the comparison (the path tracer traces a uniform ground); "
        f"both sides use albedo {np.round(ground.albedo, 3).tolist()}")
    return dataclasses.replace(scene, ground=dataclasses.replace(ground, albedo_map=None))


def measured_rows(scene, techniques: list[str]) -> list[tuple[str, str, list[dict]]]:
    """(row name, technique that renders it, ladder) per measured row family. Next to stratiform layers a voxel
    technique's rows name the stratiform pass too; on a stage of layers alone its frame is the stratiform pass's,
    measured once along :data:`STRATIFORM_LADDER`."""
    out = []
    for name in techniques:
        cls = technique_class(name)
        if scene.decks and cls.scatters_scenery and scenery_traceable(scene):
            out.append((name, name, LADDERS[name]))  # its paths carry the deck's multiple scattering
        elif scene.decks and not traces_decks(cls):
            out += deck_rows(scene, name, out)
        elif not scene.stratiform_layers or not cls.renders_layers:
            out.append((name, name, LADDERS[name]))
        elif scene.media:
            out.append((f"{name} + stratiform pass", name, LADDERS[name]))
        elif STRATIFORM_ROW not in (row for row, _, _ in out):
            out.append((STRATIFORM_ROW, name, STRATIFORM_LADDER))
    return out


def deck_rows(scene, name: str, so_far: list) -> list[tuple[str, str, list[dict]]]:
    """The rows of a voxel technique ``name`` on a stage with a height-field deck: with voxel media, its own
    ladder next to the deck pass; without, the deck pass's frame alone, once per mode along
    :data:`HEIGHTFIELD_STEPS` (none when ``so_far`` already holds them)."""
    if scene.media:
        return [(f"{name} + deck pass", name, LADDERS[name])]
    first = HEIGHTFIELD_ROW.format(mode=HEIGHTFIELD_MODES[0])
    if first in (row for row, _, _ in so_far):
        return []
    from warpsky.media.deck.deck_geometry import the_deck
    from warpsky.passes.deck.deck import automatic_steps

    step = automatic_steps(the_deck(scene))[0]
    return [(HEIGHTFIELD_ROW.format(mode=mode), name,
             [{"deck.mode": mode, "deck.step_length": factor * step} for factor in HEIGHTFIELD_STEPS])
            for mode in HEIGHTFIELD_MODES]


def run_report(
    scene,
    *,
    techniques: list[str],
    width: int,
    height: int,
    device: str,
    budget: float = 60.0,
    reference_spp: int = 1024,
    reference_seed: int = 1_000_003,
    use_cache: bool = True,
    log=print,
) -> Report:
    """Render the reference and every technique's ladder; stop a ladder once its cumulative time passes
    ``budget`` / len(techniques) seconds."""
    unknown = [t for t in techniques if t not in LADDERS]
    if unknown:
        raise UsageError(f"error-vs-time cannot measure {', '.join(unknown)} (yet); available: "
                         f"{', '.join(LADDERS)}")
    if not (scene.media or scene.stratiform_layers or scene.decks or scene.fogs or scene.meshes):
        raise UsageError("the stage holds no media, no stratiform layers, no height-field clouds, no analytic fog "
                         "and no meshes: nothing to measure")
    scene = comparable_scene(scene, log)
    radiance_ref, trans_ref, var_ref, ref_seconds, cached = reference_image(
        scene, width, height, device, spp=reference_spp, seed=reference_seed, use_cache=use_cache)
    log(f"reference: path_tracer {reference_spp} spp, {'loaded from cache' if cached else f'{ref_seconds:.1f} s'}")
    if scene.meshes or scene.fogs:  # every pixel but open sky (and the sun's disk in it), noise-free
        covered = scenery_covered(scene, width, height, device)
    else:
        luminance_t = trans_ref @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
        covered = (luminance_t < 0.99) & (radiance_ref.max(axis=-1) > 0.0)
    mean_r = float(radiance_ref[covered].mean()) if covered.any() else 0.0
    noise_mean = float(np.sqrt(var_ref[covered].sum()) / max(radiance_ref[covered].sum(), 1e-30))
    noise_pixel = float(np.sqrt(var_ref[covered].mean()) / max(mean_r, 1e-30))
    voxel = min((float(m.voxel_size.min()) for m in scene.media), default=1.0)
    rows = []
    share = budget / max(len(techniques), 1)
    for label, name, ladder in measured_rows(scene, techniques):
        spent = 0.0
        warmed = False
        for rung in ladder:
            values = {k: (v * voxel if k in VOXEL_SETTINGS else v) for k, v in rung.items()}
            plan = frame_plan(scene, name, values, width, height, device)
            if not warmed:  # compile / load every pass of the frame: not timed
                render_frame_radiance(frame_plan(scene, name, values, min(width, 8), min(height, 8), device), scene)
                warmed = True
            started = time.perf_counter()
            radiance, _, _, _ = render_frame_radiance(plan, scene)
            seconds = time.perf_counter() - started
            spent += seconds
            row = Row(label, setting_label(rung), seconds,
                      **error_metrics(radiance, radiance_ref, covered, reference_variance=var_ref))
            rows.append(row)
            log(f"  {label:<15} {row.setting:<22} {seconds:8.3f} s  rel RMSE {row.rel_rmse:.4f}")
            if spent > share:
                break
    return Report(rows, {"spp": reference_spp, "seconds": ref_seconds, "cached": cached,
                         "covered_pixels": int(covered.sum()), "rel_noise_of_mean": noise_mean,
                         "rel_noise_per_pixel": noise_pixel, "width": width, "height": height, "device": device})


def format_table(report: Report) -> str:
    wide = max([15, *(len(r.technique) for r in report.rows)])
    lines = [f"{'technique':<{wide}} {'setting':<22} {'seconds':>9} {'rel RMSE':>9} {'mean rel':>9} {'p95 rel':>9} "
             f"{'bias':>8} {'net RMSE':>9}"]
    for r in report.rows:
        lines.append(f"{r.technique:<{wide}} {r.setting:<22} {r.seconds:>9.3f} {r.rel_rmse:>9.4f} {r.mean_rel:>9.4f} "
                     f"{r.p95_rel:>9.4f} {r.bias:>+8.4f} {r.net_rmse:>9.4f}")
    ref = report.reference
    lines.append(f"reference: path_tracer {ref['spp']} spp on {ref['width']}x{ref['height']}, "
                 f"{ref['covered_pixels']} covered pixels; its own noise: {ref['rel_noise_per_pixel']:.4f} per pixel, "
                 f"{ref['rel_noise_of_mean']:.5f} of the mean. Times exclude first compiles.")
    return "\n".join(lines)


def write_rows_csv(path: Path, row_type, rows) -> None:
    """``rows`` (dataclasses of ``row_type``) as a CSV with one column per field, written atomically."""
    columns = [f.name for f in dataclasses.fields(row_type)]

    def write(tmp):
        with open(tmp, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(columns)
            for r in rows:
                writer.writerow([getattr(r, c) for c in columns])

    atomic_write(path, write)


def write_outputs(report: Report, out_dir: Path, stem: str = "error_vs_time") -> list[Path]:
    """CSV, JSON and a log-log PNG (one curve per technique) into ``out_dir``."""
    import matplotlib  # heavy: loads only when the report's plot is written

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.csv", out_dir / f"{stem}.json", out_dir / f"{stem}.png"]
    write_rows_csv(paths[0], Row, report.rows)
    blob = json.dumps({"rows": [dataclasses.asdict(r) for r in report.rows], "reference": report.reference,
                       "note": "seconds exclude first-compile time"}, indent=2)
    atomic_write(paths[1], lambda tmp: Path(tmp).write_text(blob))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for name in dict.fromkeys(r.technique for r in report.rows):
        rows = [r for r in report.rows if r.technique == name]
        ax.loglog([r.seconds for r in rows], [max(r.rel_rmse, 1e-6) for r in rows], "o-", label=name)
    ax.axhline(report.reference["rel_noise_per_pixel"], color="grey", ls="--", lw=0.8,
               label="reference noise (per pixel)")
    ax.set_xlabel("render time [s] (excluding first compile)")
    ax.set_ylabel("relative RMSE vs path-traced reference")
    ax.set_title(f"error vs time, {report.reference['width']}x{report.reference['height']} on "
                 f"{report.reference['device']}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_write(paths[2], lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return paths
