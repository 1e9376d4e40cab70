"""The optics tables a frame needs, built before any frame runs.

A batch on several workers used to have every worker build the same tables at once on its first frame (the storm's
rain, ice and snow tables take minutes on a 2-core machine, and four workers building them share those cores). The
batch client calls :func:`prepare_tables` on the first frame's plan instead: it builds what is missing from the cache
(``$WARPSKY_CACHE/optics``), printing a line per table, and the workers then load every table from the cache.

Which tables a plan needs:

============================== ============================================================================
what the plan holds            tables
============================== ============================================================================
voxel media with species       ``phase`` per species (every technique); ``ams`` (Ams_0..orders, F_n) per
                               species for ``slicing``, at its ``orders`` setting
stratiform layers              ``phase`` and ``bouthors`` (modified Mie split at 5°) of ``stratus``
============================== ============================================================================
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

from warpsky.optics import tables


@dataclass(frozen=True)
class TableNeed:
    """One table a plan needs: its species and kind (as in the cache's file names) and how to get it."""

    species: str
    kind: str
    load: Callable[[], object]
    extra: str = ""  # the cache name's suffix: Ams order count, forward cut

    @property
    def cached(self) -> bool:
        return tables.is_cached(self.species, self.kind, self.extra)


def tables_needed(scene, plan) -> list[TableNeed]:
    """The tables rendering ``scene`` with ``plan`` (:class:`~warpsky.plan.RenderPlan`) loads, in build order."""
    from warpsky.passes.stratiform.optics import FORWARD_CUT_DEG

    needs = []
    if "media" in plan.passes:
        for name in scene.species:
            needs.append(TableNeed(name, "phase", functools.partial(tables.phase_table, name)))
            if plan.technique == "slicing":
                orders = int(plan.settings.orders)
                needs.append(TableNeed(name, "ams", functools.partial(tables.ams_table, name, orders), f"{orders}"))
    if "stratiform" in plan.passes and scene.layers:
        needs.append(TableNeed("stratus", "phase", functools.partial(tables.phase_table, "stratus")))
        needs.append(TableNeed("stratus", "bouthors", functools.partial(tables.modified_mie_table, "stratus",
                                                                        FORWARD_CUT_DEG), f"{FORWARD_CUT_DEG:g}"))
    return needs


def prepare_tables(scene, plan) -> list[TableNeed]:
    """Build the tables ``plan`` needs that the cache lacks (each prints its progress line, see
    :func:`warpsky.optics.tables.build_progress`); returns those that were missing."""
    missing = [need for need in tables_needed(scene, plan) if not need.cached]
    for need in missing:
        need.load()
    return missing
