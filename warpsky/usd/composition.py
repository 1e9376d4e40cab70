"""How the stage is composed before anything is read: payloads, variant selections and purposes, as pipeline
tools (usdview, husk, usdrecord) honour them.

:class:`StageOptions` holds the choices a command line makes (``--load``, ``--variant SET=SELECTION``,
``--purpose``); :class:`~warpsky.usd.stage.StageReader` opens the stage with them:

=================  ==================================  ==============================================================
option             default                             meaning
=================  ==================================  ==============================================================
``load``           ``"all"``                           ``"all"``: payloads are loaded (usdview, husk); ``"none"``:
                                                       none is (usdview ``--unloaded``): the prims under a payload
                                                       are absent and a missing payload file is no error (one that
                                                       exists is still parsed, to report a broken file early).
``variants``       ``()``                              ``(set, selection)`` pairs applied in order on the stage's
                                                       session layer, so the files on disk never change; every prim
                                                       offering the set gets the selection (a later pair can select a
                                                       set that an earlier selection brought in).
``purposes``       ``("default", "render")``           computed ``purpose`` values that render; ``proxy`` and
                                                       ``guide`` prims are skipped unless named (husk's default).
=================  ==================================  ==============================================================

Purpose applies to what warpsky renders as geometry: Volumes, the ground plane, stratiform layer prims and the
atmosphere prim. Lights and cameras ignore it, as in Hydra (usdview, husk): they are sprims, and Hydra's render tags
(its form of purpose) filter rprims only, so a proxy-purpose DistantLight still lights a husk render.
Visibility (time-sampled too) and ``active = false`` apply to every prim kind.
"""

from __future__ import annotations

from dataclasses import dataclass

from warpsky.core.errors import SceneError, UsageError

LOAD_CHOICES = ("all", "none")
PURPOSE_CHOICES = ("default", "render", "proxy", "guide")


def parse_variant(text: str) -> tuple[str, str]:
    """``"SET=SELECTION"`` (one ``--variant`` argument) as ``(set, selection)``; raises :class:`UsageError`."""
    name, sep, selection = text.partition("=")
    name, selection = name.strip(), selection.strip()
    if not sep or not name or not selection:
        raise UsageError(f"--variant SET=SELECTION expects a variant set and a selection (e.g. shape=big), "
                         f"got {text!r}")
    return name, selection


@dataclass(frozen=True)
class StageOptions:
    """How to compose a stage (the table is in this module's docstring). Frozen, hashable and picklable: batch
    workers receive it with the stage path.

    Args:
        load: ``"all"`` (payloads loaded) or ``"none"`` (usdview ``--unloaded``).
        variants: ``(variant set, selection)`` pairs, applied in order on the session layer.
        purposes: Computed purposes that render, a non-empty subset of default, render, proxy, guide.
    """

    load: str = "all"
    variants: tuple[tuple[str, str], ...] = ()
    purposes: tuple[str, ...] = ("default", "render")

    def __post_init__(self):
        if self.load not in LOAD_CHOICES:
            raise UsageError(f"--load must be one of {', '.join(LOAD_CHOICES)}, got {self.load!r}")
        variants = []
        for pair in self.variants:
            if isinstance(pair, str):
                pair = parse_variant(pair)
            if (not isinstance(pair, (tuple, list)) or len(pair) != 2
                    or not all(isinstance(part, str) and part.strip() for part in pair) or "=" in pair[0]):
                raise UsageError(f"--variant SET=SELECTION expects a variant set and a selection, got {pair!r}")
            variants.append((pair[0].strip(), pair[1].strip()))
        object.__setattr__(self, "variants", tuple(variants))
        purposes = (self.purposes,) if isinstance(self.purposes, str) else tuple(self.purposes)
        unknown = [p for p in purposes if p not in PURPOSE_CHOICES]
        if unknown or not purposes:
            raise UsageError(f"--purpose takes one or more of {', '.join(PURPOSE_CHOICES)}, got "
                             f"{', '.join(map(repr, unknown)) if unknown else 'none'}")
        object.__setattr__(self, "purposes", tuple(dict.fromkeys(purposes)))

    def initial_load_set(self):
        """``Usd.Stage.InitialLoadSet`` for ``Usd.Stage.Open``."""
        from pxr import Usd

        return Usd.Stage.LoadAll if self.load == "all" else Usd.Stage.LoadNone


def apply_variants(stage, variants) -> list[str]:
    """Select each ``(set, selection)`` in order, on the session layer, on every prim whose variant set offers it;
    returns one summary line per prim. Prims are found anew for each pair, so a set that an earlier selection
    brought in can be selected next. Raises :class:`SceneError` when no prim has the set (listing the sets there
    are) or none of the prims having it offers the selection (listing what they offer)."""
    from pxr import Usd

    lines = []
    for name, selection in variants:
        owners = [prim for prim in _with_unloaded(stage) if prim.GetVariantSets().HasVariantSet(name)]
        if not owners:
            raise SceneError(_no_such_set(stage, name))
        offering = [p for p in owners if selection in p.GetVariantSets().GetVariantSet(name).GetVariantNames()]
        if not offering:
            offered = sorted({v for p in owners for v in p.GetVariantSets().GetVariantSet(name).GetVariantNames()})
            where = ", ".join(str(p.GetPath()) for p in owners[:3]) + (" ..." if len(owners) > 3 else "")
            raise SceneError(f"--variant {name}={selection}: variant set {name!r} ({where}) offers "
                             f"{', '.join(offered) or 'no variants'}, not {selection!r}")
        paths = [p.GetPath() for p in offering]
        with Usd.EditContext(stage, stage.GetSessionLayer()):
            for path in paths:  # the prim objects of earlier paths stay valid: recomposition keeps the paths
                stage.GetPrimAtPath(path).GetVariantSets().GetVariantSet(name).SetVariantSelection(selection)
        skipped = len(owners) - len(offering)
        note = f"; {skipped} prim(s) whose set lacks {selection!r} keep their selection" if skipped else ""
        lines += [f"variants: {path} {name}={selection} (session layer){note}" for path in paths]
    return lines


def _with_unloaded(stage):
    """Every active, defined, concrete prim, unloaded payload holders included: their variant sets are authored
    outside the payload and select whatever it loads."""
    from pxr import Usd

    return stage.Traverse(Usd.PrimIsActive & Usd.PrimIsDefined & ~Usd.PrimIsAbstract)


def _no_such_set(stage, name: str) -> str:
    """Why ``--variant name=...`` selects nothing: the variant sets the stage has, or where the set hides."""
    from pxr import Usd

    inside = [p for p in stage.Traverse(Usd.TraverseInstanceProxies())
              if p.IsInstanceProxy() and p.GetVariantSets().HasVariantSet(name)]
    if inside:
        return (f"--variant {name}=...: variant set {name!r} exists only inside instances (e.g. "
                f"{inside[0].GetPath()}), whose prims cannot be edited; select it in the instanced asset or make "
                "the prim non-instanceable")
    sets: dict[str, set[str]] = {}
    for prim in _with_unloaded(stage):
        for set_name in prim.GetVariantSets().GetNames():
            sets.setdefault(set_name, set()).update(prim.GetVariantSets().GetVariantSet(set_name).GetVariantNames())
    listed = "; ".join(f"{s} ({', '.join(sorted(v))})" for s, v in sorted(sets.items()))
    return f"--variant {name}=...: no prim has a variant set {name!r}; " + (
        f"the stage's variant sets: {listed}" if sets else "the stage has no variant sets")


def composition_summary(stage, options: StageOptions, variant_lines: list[str]) -> list[str]:
    """One line per thing composition did: payloads, references, variants, instances, purposes."""
    from pxr import Usd

    lines = []
    loadable = stage.FindLoadable()  # payloaded prims, inside instances too (GetLoadSet counts a prototype once)
    if loadable:
        loaded = sum(1 for path in loadable if stage.GetPrimAtPath(path).IsLoaded())
        if loaded:
            lines.append(f"payloads: {loaded} loaded" + (f", {len(loadable) - loaded} not" if loaded < len(loadable)
                                                          else ""))
        else:
            lines.append(f"payloads: {len(loadable)} not loaded (--load {options.load})")
    prims = list(stage.Traverse(Usd.TraverseInstanceProxies()))
    referencing = sum(1 for p in prims if p.HasAuthoredReferences())
    if referencing:
        lines.append(f"references: {referencing} prim(s) with references")
    lines += variant_lines
    instances = sum(1 for p in prims if p.IsInstance())
    if instances:
        lines.append(f"instances: {instances} instance(s) of {len(stage.GetPrototypes())} prototype(s)")
    lines.append(f"purposes rendered: {', '.join(options.purposes)}")
    return lines
