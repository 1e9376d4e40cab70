"""Choosing the fog pass's quadrature and the deck pass's steps on the tune half of the scenery family.

Both passes integrate their single scattering by quadrature (the fog: Gauss-Legendre nodes on pieces as long as
the shortest feature along the ray, :mod:`~warpsky.passes.fog.fog`; the deck and its haze: a march with steps set
from the extinction and the pattern's features, :mod:`~warpsky.passes.deck.deck`). Their error is
the quadrature's alone, so it is measured against the same pass with a much finer quadrature
(:data:`FOG_REFERENCE`, :data:`DECK_REFERENCE`), no path tracing needed, on every member of a family
(``evaluation/scripts/make_scenery_family.py``) that holds that element:

* error = RMS over the frame's covered pixels of (pass radiance - finer pass radiance), divided by the finer pass's
  mean radiance there, worst of the three channels; the deck's transmittance error (max |dT|) beside it;
* time = the pass's own seconds (its layer's ``stats``), the median of :data:`REPEATS` renders.

The chosen setting is the fastest candidate whose worst error over the tune half is at most :data:`TOLERANCE`;
the test half then reports the median, p90 and worst error and the mean signed bias (mean of the difference over
the finer pass's mean) of that choice (:func:`choose`). ``evaluation/scripts/choose_scenery_settings.py`` runs it and
writes ``docs/scenery_family/settings_choice.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evaluation.error_vs_time import frame_plan
from evaluation.family import covered_pixels
from warpsky.passes.frame import depth_layers

#: Worst relative quadrature error over the tune half a chosen setting may have: a fifth of the 5 % a frame is
#: rendered to by default, so the quadrature never decides whether a frame meets its target.
TOLERANCE = 0.01
#: Candidates for the fog pass: (nodes, min_pieces, max_pieces). Pieces follow the fog's features along the ray
#: (at least ``min_pieces``), not the terrain's shadows across it, so more pieces at least are candidates too.
FOG_CANDIDATES = ((1, 4, 16), (2, 4, 64), (2, 16, 64), (2, 32, 64), (4, 4, 16), (4, 4, 64), (4, 8, 64),
                  (4, 16, 64), (4, 32, 128), (8, 4, 64), (8, 8, 64), (8, 16, 64), (8, 32, 128))
#: The fog pass's finer quadrature every candidate is measured against: 16 nodes on 16..512 pieces.
FOG_REFERENCE = (16, 16, 512)
#: Candidates for the deck pass: (cloud step factor on its automatic value, None: automatic; the haze's
#: automatic steps per shortest feature of the deck's shadow, ``haze_steps_per_feature``; the shadow map's texels per
#: side, ``shadow_map_texels``: None automatic, 0 the sun's depth exact at every step).
DECK_CANDIDATES = ((None, 8, 0), (None, 12, 0), (None, 16, 0), (None, 24, 0), (None, 32, 0), (0.5, 16, 0),
                   (None, 8, None), (None, 16, None), (None, 32, None))
#: The finer march: the cloud step an eighth of its automatic value, the haze step a 64th of the shadow's shortest
#: feature (at most an eighth of its quarter mean free path) everywhere, the sun's depth exact at every step.
DECK_REFERENCE = (0.125, 64, 0)
#: Renders per candidate whose median time is taken.
REPEATS = 3


@dataclass
class Measured:
    """One candidate on one member."""

    member: str
    half: str
    candidate: str
    error: float  # relative RMS radiance error against the finer quadrature, worst channel
    bias: float  # mean signed radiance difference over the finer pass's mean radiance (green)
    transmittance_error: float  # max |dT| against the finer quadrature (0 for the fog: closed form)
    seconds: float


def fog_settings(candidate: tuple[int, int, int]) -> dict:
    nodes, low, high = candidate
    return {"fog.nodes": nodes, "fog.min_pieces": low, "fog.max_pieces": high}


def deck_settings(scene, candidate: tuple[float | None, int, int | None], authored: bool = False) -> dict:
    """The height-field settings of ``candidate`` (cloud factor or None, haze steps per feature, shadow map texels
    or None); ``authored``: the haze step written out (the same everywhere) instead of the automatic rule."""
    from warpsky.media.deck.deck_geometry import the_deck
    from warpsky.passes.deck.deck import automatic_steps, haze_step_bound, shadow_feature

    factor, per_feature, texels = candidate
    clouds = the_deck(scene)
    out = {"deck.haze_steps_per_feature": per_feature}
    if texels is not None:
        out["deck.shadow_map_texels"] = texels
    if factor is not None:
        out["deck.step_length"] = factor * automatic_steps(clouds, per_feature)[0]
    if authored:
        out["deck.haze_step_length"] = min(haze_step_bound(clouds) / 8.0, shadow_feature(clouds) / per_feature)
    return out


def deck_name(candidate: tuple[float | None, int, int | None]) -> str:
    factor, per_feature, texels = candidate
    cloud = "auto" if factor is None else f"x {factor:g}"
    sun = "shadow map" if texels is None else ("exact depth per step" if texels == 0 else f"shadow map {texels}")
    return f"deck cloud step {cloud}, haze {per_feature} steps per feature, {sun}"


def pass_layer(scene, values: dict, width: int, height: int, device: str, key: str, repeats: int = REPEATS):
    """The layer of the pass whose stats hold ``key`` (``nodes``: the fog's, ``mode``: the deck's) in a
    ``single_scatter`` frame with the settings ``values``; the median seconds of ``repeats`` renders."""
    plan = frame_plan(scene, "single_scatter", values, width, height, device)
    runs = []
    for _ in range(repeats):
        started = time.perf_counter()
        layer = next(layer for layer in depth_layers(plan, scene) if key in layer.stats)
        runs.append((float(layer.stats.get("seconds", time.perf_counter() - started)), layer))
    runs.sort(key=lambda run: run[0])
    return runs[len(runs) // 2][1], runs[len(runs) // 2][0]


def compare(layer, reference, covered: np.ndarray) -> tuple[float, float, float]:
    """(relative RMS radiance error, worst channel; mean signed difference / mean, green; max |dT|)."""
    ref = reference.radiance[covered].astype(np.float64)
    diff = layer.radiance[covered].astype(np.float64) - ref
    mean = np.maximum(ref.mean(axis=0), 1e-30)
    error = float(np.max(np.sqrt(np.mean(diff**2, axis=0)) / mean))
    bias = float(diff[:, 1].mean() / mean[1])
    dt = float(np.max(np.abs(layer.transmittance[covered].astype(np.float64) - reference.transmittance[covered])))
    return error, bias, dt


def measure_member(scene, member: dict, width: int, height: int, device: str, elements=("fog", "deck")
                   ) -> list[Measured]:
    """Every candidate of the ``elements`` ``scene`` holds (fog, deck) against the finer quadrature."""
    covered = covered_pixels(scene, width, height, device)
    out = []
    if scene.fogs and "fog" in elements:
        reference, _ = pass_layer(scene, fog_settings(FOG_REFERENCE), width, height, device, "nodes", 1)
        for candidate in FOG_CANDIDATES:
            layer, seconds = pass_layer(scene, fog_settings(candidate), width, height, device, "nodes")
            error, bias, dt = compare(layer, reference, covered)
            nodes, low, high = candidate
            out.append(Measured(member["name"], member["half"], f"fog {nodes} nodes, {low}..{high} pieces", error,
                                bias, dt, seconds))
    if scene.decks and "deck" in elements:
        finer = deck_settings(scene, DECK_REFERENCE, authored=True)
        reference, _ = pass_layer(scene, finer, width, height, device, "mode", 1)
        for candidate in DECK_CANDIDATES:
            layer, seconds = pass_layer(scene, deck_settings(scene, candidate), width, height, device, "mode")
            error, bias, dt = compare(layer, reference, covered)
            out.append(Measured(member["name"], member["half"], deck_name(candidate), error, bias, dt, seconds))
    return out


def choose(measured: list[Measured], prefix: str, tolerance: float = TOLERANCE) -> dict:
    """The fastest candidate starting with ``prefix`` whose worst tune-half error is at most ``tolerance`` (the
    most accurate one when none is), with its tune and test figures."""
    names = list(dict.fromkeys(m.candidate for m in measured if m.candidate.startswith(prefix)))

    def summary(name: str, half: str) -> dict:
        rows = [m for m in measured if m.candidate == name and m.half == half]
        errors = np.array([m.error for m in rows])
        if not len(errors):
            return {"members": 0}
        return {"members": len(rows), "median": float(np.median(errors)), "p90": float(np.percentile(errors, 90)),
                "worst": float(errors.max()), "mean_bias": float(np.mean([m.bias for m in rows])),
                "worst_transmittance_error": float(max(m.transmittance_error for m in rows)),
                "median_seconds": float(np.median([m.seconds for m in rows]))}

    table = {name: {"tune": summary(name, "tune"), "test": summary(name, "test")} for name in names}
    fit = [name for name in names if table[name]["tune"].get("worst", np.inf) <= tolerance]
    if fit:
        chosen = min(fit, key=lambda name: table[name]["tune"]["median_seconds"])
    else:
        chosen = min(names, key=lambda name: table[name]["tune"].get("worst", np.inf))
    return {"chosen": chosen, "tolerance": tolerance, "within_tolerance": bool(fit), "candidates": table}


def run(family_dir: str | Path, device: str = "cpu", log=print, elements=("fog", "deck")) -> dict:
    """Measure every candidate on every member of the family at ``family_dir`` holding one of ``elements`` and
    choose (JSON-ready dict)."""
    from warpsky.usd.stage import StageReader

    family_dir = Path(family_dir)
    family = json.loads((family_dir / "family.json").read_text())
    width, height = family["image_size"]
    measured = []
    for member in family["members"]:
        scene = StageReader(str(family_dir / f"{member['name']}.usda")).scene_at(None)
        if not ((scene.fogs and "fog" in elements) or (scene.decks and "deck" in elements)):
            continue
        rows = measure_member(scene, member, width, height, device, elements)
        for m in rows:
            log(f"{m.member:16s} {m.half:4s} {m.candidate:32s} error {m.error:.2e} bias {m.bias:+.2e} "
                f"dT {m.transmittance_error:.1e} {m.seconds * 1e3:8.2f} ms")
        measured += rows
    return {"family": str(family_dir), "generator": family.get("generator"), "seed": family.get("seed"),
            "image_size": [width, height], "device": device,
            **{element: choose(measured, element) for element in elements},
            "rows": [m.__dict__ for m in measured]}
