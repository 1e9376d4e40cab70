"""``warpsky bench error-vs-time --family DIR``: every technique's error against a path-traced reference across
the validation family (:mod:`evaluation.family_stages`), so settings chosen on the ``tune`` half are
reported on the ``test`` half.

Per member of the chosen half: the cached path-traced reference, a noise-free mask of the pixels where the media
are visible, then each technique's quality ladder (one untimed warm-up render per technique and member; a ladder
stops once its time on the member passes the member's budget / the number of techniques). Errors are
:func:`~evaluation.error_vs_time.error_metrics` on the composited frame radiance over the covered pixels.

*Covered pixels* come from the media alone, rendered by ``single_scatter`` without ground and atmosphere (the
ground would be opaque in the layer's transmittance, the air is never in it): luminance transmittance < 0.99. On
the scenery family's stages (:mod:`evaluation.scenery_family`: terrain meshes, analytic fog, height-field
decks) they are the pixels where the composited frame without the air transmits < 0.99: everything but open sky.

*References* are keyed by :func:`family_reference_key`, a hash of the member's file contents (stage and fields),
the image size, samples, seed and warpsky's version, and nothing about the device or where the files lie, so
references rendered on a GPU machine (``--references-only``) and copied into
``$WARPSKY_CACHE/reference/family/`` are found here.

Aggregates, per technique and ladder rung, over the members that reached the rung without an error:

=================== =================================================================================
column              meaning
=================== =================================================================================
stages              members measured at this rung (a ladder stops early on a member over budget)
median, p90, worst  median, 90th percentile and largest rel_rmse over those members
median_bias         median of the members' bias (mean(x) - mean(r)) / mean(r)
mean_bias           mean of the members' bias
median_s            median render time [s], first compiles excluded
=================== =================================================================================
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from evaluation.error_vs_time import (
    LADDERS,
    VOXEL_SETTINGS,
    error_metrics,
    frame_plan,
    has_scenery,
    reference_image,
    render_frame_radiance,
    scenery_covered,
    setting_label,
    write_rows_csv,
)
from evaluation.family_stages import HALVES, load_family, make_family
from warpsky.core.errors import UsageError
from warpsky.core.files import atomic_write, cache_dir
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.core.version import __version__
from warpsky.passes.frame import render_layers
from warpsky.render.registry import technique_class

__all__ = ["FAMILY_HELP", "FamilyReport", "FamilyRow", "aggregate", "covered_pixels", "family_reference_key",
           "family_reference_path", "format_family_table", "make_family", "run_family", "write_family_outputs"]

#: The family part of ``warpsky bench error-vs-time --help``.
FAMILY_HELP = """\
the validation family (--family DIR):
  A seeded set of stages (evaluation/scripts/make_validation_family.py, make family: data/family): isolated cumulus,
  broken stratocumulus, towering cell with anvil, thin cirrus and a camera inside a cloud, spanning peak optical
  depth 0.1..300, albedo 1 and 0.9, hg / Mie cloud / isotropic phase, sun elevation 2..90 deg front-, side-
  and back-lit, with and without ground and atmosphere. Members alternate between a tune and a test half:
  choose settings on --half tune, report them on --half test. References are cached under
  $WARPSKY_CACHE/reference/family/ by a hash of the member's files, size, spp and seed, not of the device:
  render them on a GPU with --references-only and copy the .npz files over.
  Covered pixels: where the media alone (single_scatter, no ground, no air) transmit < 0.99 of the light.
  The scenery family (evaluation/scripts/make_scenery_family.py, make scenery-family: data/scenery_family, 96x64):
  terrain meshes with thin and thick valley fog, a height-field deck with haze, cumulus cut by a ridge; the path tracer
  traces all of it, the other techniques leave fog, terrain and deck to their passes. Covered pixels there:
  where the frame without the air transmits < 0.99 (terrain, ground, fog, deck, haze, media; not open sky).

family columns (per technique and ladder rung, over the stages that reached it):
  stages     stages measured at this rung (a ladder stops on a stage once it passes budget / techniques)
  median     median relative RMSE: sqrt(mean((x - r)^2)) / mean(r) over covered pixels of the frame radiance
  p90, worst 90th percentile and largest relative RMSE over the stages
  med bias   median of the stages' bias (mean(x) - mean(r)) / mean(r); mean bias: their mean
  median s   median render time per stage [s], first compiles excluded
  net med/p90 the median and p90 of the relative RMSE with the reference's own noise taken out,
             sqrt(max(MSE - mean reference variance, 0)) / mean(r): the error against the exact image
  The CSV holds one row per stage, technique and rung (error names a failed measurement); the JSON adds the
  aggregate and the references; the PNG plots median (solid) and p90 (dashed) relative RMSE against time.

examples:
  warpsky bench error-vs-time usd_scenes/cumulus.usda --techniques single_scatter,slicing,path_tracer
  warpsky bench error-vs-time --family data/family --half all --references-only --device cuda
  warpsky bench error-vs-time --family data/family --half tune --res 64 -o out/family_tune
"""

#: Luminance transmittance of the media below which a pixel counts as covered.
COVERED_TRANSMITTANCE = 0.99


@dataclass
class FamilyRow:
    """One technique at one ladder rung on one member; ``error`` holds the message when it could not be measured
    (the metric columns are then NaN)."""

    stage: str
    half: str
    kind: str
    technique: str
    setting: str
    rung: int
    seconds: float
    rel_rmse: float
    mean_rel: float
    p95_rel: float
    bias: float
    net_rmse: float = math.nan  # rel_rmse with the reference's own noise taken out
    error: str = ""


@dataclass
class FamilyReport:
    """Per-member rows, their aggregate (see the module docstring), per-member reference figures and what ran."""

    rows: list[FamilyRow]
    aggregate: list[dict]
    references: list[dict] = field(default_factory=list)
    settings: dict = field(default_factory=dict)


#: The references' cap on scattering events per path: far above what a path in the thick family needs (in a
#: storm of peak optical depth 1000, 0.56 % of the paths pass the techniques' default of 1024), and within the
#: plan's work limit at 1024 paths per pixel.
REFERENCE_MAX_BOUNCES = 65536


def family_reference_key(scene, width: int, height: int, spp: int, seed: int) -> str:
    """Hash of the member's inputs by content (the stage file and every medium's field file), the image size,
    samples, seed, the bounce cap and warpsky's version; independent of the device and of where the files lie."""
    digest = hashlib.sha256()
    for path in [scene.source, *(m.source for m in scene.media)]:
        digest.update(hashlib.sha256(Path(path).read_bytes()).digest())
    digest.update(json.dumps([width, height, spp, seed, REFERENCE_MAX_BOUNCES, __version__]).encode())
    return digest.hexdigest()[:20]


def family_reference_path(key: str) -> Path:
    """Where a family reference of ``key`` is cached: ``$WARPSKY_CACHE/reference/family/KEY.npz``."""
    return cache_dir() / "reference" / "family" / f"{key}.npz"


def covered_pixels(scene, width: int, height: int, device: str) -> np.ndarray:
    """(H, W) bool: pixels where the media's luminance transmittance is below ``COVERED_TRANSMITTANCE``, from a
    ``single_scatter`` render of the media alone (no ground, no atmosphere): noise-free. On a stage with scenery
    (:func:`has_scenery`), the composited frame's transmittance without the air instead: every pixel that shows
    terrain, ground, fog, the deck or its haze, or the media (open sky is left out)."""
    if has_scenery(scene):
        return scenery_covered(scene, width, height, device, COVERED_TRANSMITTANCE)
    media_only = dataclasses.replace(scene, ground=None, atmosphere=None, stratiform_layers=())
    plan = frame_plan(media_only, "single_scatter", {}, width, height, device)
    layer, _ = render_layers(plan, media_only)
    return (layer.transmittance @ LUMINANCE_WEIGHTS.astype(np.float32)) < COVERED_TRANSMITTANCE


def _members(family: dict, half: str) -> list[dict]:
    if half not in (*HALVES, "all"):
        raise UsageError(f"half must be tune, test or all, got {half!r}")
    return [m for m in family["members"] if half == "all" or m["half"] == half]


def _walk_ladder(scene, member: dict, name: str, width: int, height: int, device: str, share: float,
                 reference: np.ndarray, covered: np.ndarray, log, reference_variance=None) -> list[FamilyRow]:
    """``name``'s ladder on one member, after an untimed warm-up; stops once its time passes ``share``."""
    voxel = min((float(m.voxel_size.min()) for m in scene.media), default=1.0)
    rows, spent = [], 0.0
    for rung_index, rung in enumerate(LADDERS[name]):
        values = {k: (v * voxel if k in VOXEL_SETTINGS else v) for k, v in rung.items()}
        plan = frame_plan(scene, name, values, width, height, device)
        if rung_index == 0 and has_scenery(scene):  # compile / load every pass of the frame: not timed
            render_frame_radiance(frame_plan(scene, name, values, min(width, 8), min(height, 8), device), scene)
        elif rung_index == 0:
            plan.renderer.render(scene, min(width, 8), min(height, 8))  # compile / load: not timed
        started = time.perf_counter()
        radiance, _, _, _ = render_frame_radiance(plan, scene)
        seconds = time.perf_counter() - started
        spent += seconds
        try:
            metrics, error = error_metrics(radiance, reference, covered, reference_variance), ""
        except UsageError as exc:
            metrics, error = dict.fromkeys(("rel_rmse", "mean_rel", "p95_rel", "bias", "net_rmse"), math.nan), str(exc)
        row = FamilyRow(member["name"], member["half"], member["kind"], name, setting_label(rung), rung_index,
                        seconds, **metrics, error=error)
        rows.append(row)
        log(f"  {name:<15} {row.setting:<28} {seconds:8.3f} s  "
            + (f"rel RMSE {row.rel_rmse:.4f}" if not error else f"error: {error}"))
        if spent > share:
            break
    return rows


def _reference(scene, member: dict, width, height, device, spp, seed, use_cache, log):
    """The member's cached reference and a line of figures about it."""
    key = family_reference_key(scene, width, height, spp, seed)
    path = family_reference_path(key)
    radiance, transmittance, variance, seconds, cached = reference_image(
        scene, width, height, device, spp=spp, seed=seed, use_cache=use_cache, cache_path=path,
        max_bounces=REFERENCE_MAX_BOUNCES)
    with np.load(path) as data:
        capped = int(data["capped_paths"]) if "capped_paths" in data else -1
    log(f"{member['name']:<24} reference path_tracer {spp} spp, "
        + ("loaded from cache" if cached else f"{seconds:.1f} s on {device}")
        + (f", {capped} path(s) capped at {REFERENCE_MAX_BOUNCES} events" if capped > 0 else ""))
    return radiance, variance, {"stage": member["name"], "half": member["half"], "kind": member["kind"],
                                "key": key, "seconds": float(seconds), "cached": bool(cached),
                                "capped_paths": capped}


def run_family(
    family_dir: str | Path,
    techniques: list[str],
    width: int,
    height: int,
    device: str,
    *,
    half: str = "test",
    reference_spp: int = 1024,
    reference_seed: int = 1_000_003,
    budget_per_stage: float = 60.0,
    use_cache: bool = True,
    references_only: bool = False,
    log=print,
) -> FamilyReport:
    """Measure ``techniques`` on every member of ``half`` (``tune``, ``test`` or ``all``) of the family in
    ``family_dir``; with ``references_only``, only render and cache the references (rows stay empty)."""
    from warpsky.usd.stage import StageReader

    unknown = [t for t in techniques if t not in LADDERS]
    if unknown:
        raise UsageError(f"error-vs-time cannot measure {', '.join(unknown)} (yet); available: "
                         f"{', '.join(LADDERS)}")
    for name in techniques:
        technique_class(name)  # an unregistered technique fails here, before any reference renders
    family_dir = Path(family_dir)
    members = _members(load_family(family_dir), half)
    rows, references = [], []
    share = budget_per_stage / max(len(techniques), 1)
    for member in members:
        scene = StageReader(family_dir / member["stage"]).scene_at(None)
        if not scene.media and not has_scenery(scene):
            raise UsageError(f"{member['stage']} holds no media and no scenery: is {family_dir} a validation "
                             "family?")
        radiance_ref, var_ref, info = _reference(scene, member, width, height, device, reference_spp,
                                                 reference_seed, use_cache, log)
        references.append(info)
        if references_only:
            continue
        covered = covered_pixels(scene, width, height, device)
        mean_r = float(radiance_ref[covered].mean()) if covered.any() else 0.0
        info.update(covered_pixels=int(covered.sum()), mean_radiance=mean_r,
                    rel_noise_per_pixel=float(np.sqrt(var_ref[covered].mean()) / mean_r) if mean_r > 0 else math.nan)
        for name in techniques:
            rows += _walk_ladder(scene, member, name, width, height, device, share, radiance_ref, covered, log,
                                 var_ref)
    settings = {"family": str(family_dir), "half": half, "stages": len(members), "width": width, "height": height,
                "device": device, "techniques": list(techniques), "reference_spp": reference_spp,
                "reference_seed": reference_seed, "budget_per_stage": budget_per_stage}
    return FamilyReport(rows, aggregate(rows), references, settings)


def aggregate(rows: list[FamilyRow]) -> list[dict]:
    """Per technique and rung, in first-seen order: the statistics the module docstring tables."""
    groups: dict[tuple[str, int], list[FamilyRow]] = {}
    for row in rows:
        groups.setdefault((row.technique, row.rung), []).append(row)
    out = []
    for (technique, rung), members in groups.items():
        good = [r for r in members if not r.error and math.isfinite(r.rel_rmse)]
        errors = np.array([r.rel_rmse for r in good])
        bias = np.array([r.bias for r in good])
        stats = {"technique": technique, "setting": members[0].setting, "rung": rung, "stages": len(good),
                 "errors": len(members) - len(good)}
        if good:
            worst = good[int(np.argmax(errors))]
            net = np.array([r.net_rmse for r in good])
            stats.update(median_net_rmse=float(np.nanmedian(net)) if np.isfinite(net).any() else math.nan,
                         p90_net_rmse=float(np.nanpercentile(net, 90)) if np.isfinite(net).any() else math.nan)
            stats.update(median_rel_rmse=float(np.median(errors)), p90_rel_rmse=float(np.percentile(errors, 90)),
                         worst_rel_rmse=float(errors.max()), worst_stage=worst.stage,
                         median_bias=float(np.median(bias)), mean_bias=float(bias.mean()),
                         median_seconds=float(np.median([r.seconds for r in good])))
        out.append(stats)
    order = list(dict.fromkeys(r.technique for r in rows))
    return sorted(out, key=lambda s: (order.index(s["technique"]), s["rung"]))


def format_family_table(report: FamilyReport) -> str:
    s = report.settings
    lines = [f"family {s['family']}, {s['half']} half: {s['stages']} stages at {s['width']}x{s['height']} on "
             f"{s['device']}; reference path_tracer {s['reference_spp']} spp",
             f"{'technique':<15} {'setting':<28} {'stages':>6} {'median':>8} {'p90':>8} {'worst':>8} "
             f"{'med bias':>9} {'mean bias':>9} {'median s':>9} {'net med':>8} {'net p90':>8}"]
    for a in report.aggregate:
        if a["stages"] == 0:
            lines.append(f"{a['technique']:<15} {a['setting']:<28} {0:>6}   (no measurement: {a['errors']} errors)")
            continue
        lines.append(f"{a['technique']:<15} {a['setting']:<28} {a['stages']:>6} {a['median_rel_rmse']:>8.4f} "
                     f"{a['p90_rel_rmse']:>8.4f} {a['worst_rel_rmse']:>8.4f} {a['median_bias']:>+9.4f} "
                     f"{a['mean_bias']:>+9.4f} {a['median_seconds']:>9.3f} {a['median_net_rmse']:>8.4f} "
                     f"{a['p90_net_rmse']:>8.4f}")
    noise = [r["rel_noise_per_pixel"] for r in report.references if math.isfinite(r.get("rel_noise_per_pixel",
                                                                                             math.nan))]
    if noise:
        lines.append(f"reference noise per pixel (relative): median {np.median(noise):.4f}, worst {max(noise):.4f}; "
                     "errors below it are not resolved.")
    failed = [r for r in report.rows if r.error]
    if failed:
        lines.append(f"{len(failed)} measurement(s) failed, e.g. {failed[0].stage} {failed[0].technique}: "
                     f"{failed[0].error}")
    lines.append("rel RMSE over covered pixels of the frame radiance; times exclude first compiles.")
    return "\n".join(lines)


def _finite(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value


def write_family_outputs(report: FamilyReport, out_dir: str | Path, stem: str = "family_error_vs_time") -> list[Path]:
    """CSV (per-stage rows), JSON (rows, aggregate, references, settings) and a log-log PNG of median rel RMSE vs
    median time per technique (p90 dashed; hollow: rungs that fewer stages reached), into ``out_dir``."""
    import matplotlib  # heavy: loads only when the report's plot is written

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.csv", out_dir / f"{stem}.json", out_dir / f"{stem}.png"]
    write_rows_csv(paths[0], FamilyRow, report.rows)
    rows = [{k: _finite(v) for k, v in dataclasses.asdict(r).items()} for r in report.rows]
    references = [{k: _finite(v) for k, v in r.items()} for r in report.references]
    blob = json.dumps({"settings": report.settings, "aggregate": report.aggregate, "rows": rows,
                       "references": references, "note": "seconds exclude first-compile time"}, indent=2)
    atomic_write(paths[1], lambda tmp: Path(tmp).write_text(blob))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for name in dict.fromkeys(a["technique"] for a in report.aggregate):
        points = [a for a in report.aggregate if a["technique"] == name and a["stages"] > 0]
        if not points:
            continue
        full = max(a["stages"] for a in points)  # rungs on fewer stages (ladders cut by the budget): hollow
        whole = [a for a in points if a["stages"] == full]
        seconds = [max(a["median_seconds"], 1e-6) for a in whole]
        (line,) = ax.loglog(seconds, [max(a["median_rel_rmse"], 1e-6) for a in whole], "o-", label=f"{name} median")
        ax.loglog(seconds, [max(a["p90_rel_rmse"], 1e-6) for a in whole], "--", color=line.get_color(), lw=1.0,
                  label=f"{name} p90")
        partial = [a for a in points if a["stages"] < full]
        if partial:
            ax.loglog([max(a["median_seconds"], 1e-6) for a in partial],
                      [max(a["median_rel_rmse"], 1e-6) for a in partial], "o", mfc="none", color=line.get_color(),
                      label=f"{name} median, fewer stages")
    s = report.settings
    ax.set_xlabel("median render time [s] (excluding first compile)")
    ax.set_ylabel("relative RMSE vs path-traced reference")
    ax.set_title(f"family {s.get('half', '')} half ({s.get('stages', 0)} stages), {s.get('width')}x{s.get('height')} "
                 f"on {s.get('device')}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_write(paths[2], lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return paths
