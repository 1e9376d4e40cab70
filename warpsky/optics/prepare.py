"""The optics tables a frame needs, built before any frame runs.

A batch on several workers used to have every worker build the same tables at once on its first frame (the storm's
rain, ice and snow tables take minutes on a 2-core machine, and four workers building them share those cores). The
batch client calls :func:`prepare_tables` on the first frame's plan instead: it builds what is missing from the cache
(``$WARPSKY_CACHE/optics``), printing a line per table, and the workers then load every table from the cache.

Which tables a plan needs is said by what runs: its technique (``Technique.tables``: a ``phase`` table per species,
and slicing's ``ams`` tables at its ``orders`` setting) when the media pass runs, and each running pass
(``Pass.tables``: the stratiform pass's ``phase`` and ``bouthors`` tables of ``stratus``).
"""

from __future__ import annotations

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
    """The tables rendering ``scene`` with ``plan`` (:class:`~warpsky.render.plan.RenderPlan`) loads, in build order,
    each once: those of every pass that runs (the technique's through the media pass)."""
    needs: dict[tuple, TableNeed] = {}
    for runner in plan.pass_runners:
        for need in runner.tables(scene):
            needs.setdefault((need.species, need.kind, need.extra), need)
    return list(needs.values())


def prepare_tables(scene, plan) -> list[TableNeed]:
    """Build the tables ``plan`` needs that the cache lacks (each prints its progress line, see
    :func:`warpsky.optics.tables.build_progress`); returns those that were missing."""
    missing = [need for need in tables_needed(scene, plan) if not need.cached]
    for need in missing:
        need.load()
    return missing
