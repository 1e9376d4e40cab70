"""The sample data the shipped stages reference, and the command that makes each file.

The stages in ``usd_scenes/`` reference files under ``data/`` that the scripts in ``tools/`` generate (a fresh
checkout has none of them); ``make data`` runs every command of :data:`GENERATED`. When a stage names such a file and
it is missing, :func:`missing_file_hint` gives the commands that make it, so that the error says what to run instead
of only which file is absent. A missing file outside a checkout (no generating script beside its ``data/`` folder)
gets no hint.
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

#: (files, relative to the checkout, as a glob; the script that writes them; its command, run from the checkout).
GENERATED: tuple[tuple[str, str, str], ...] = (
    ("data/cumulus.nvdb", "tools/make_cumulus.py", "python tools/make_cumulus.py --out data"),
    ("data/storm/*.nvdb", "tools/make_storm.py", "python tools/make_storm.py --out data/storm --frames 48"),
    ("data/stratocumulus/*.npy", "tools/make_stratocumulus.py", "python tools/make_stratocumulus.py --out data"),
    ("data/sundogs/*.npy", "tools/make_sundogs.py", "python tools/make_sundogs.py --out data/sundogs"),
    ("data/terrain.usda", "tools/make_terrain.py",
     "python tools/make_terrain.py --seed 1 --valley-angle 90 --resolution 257 --out data/terrain.usda"),
)


def generating_command(path: str | os.PathLike) -> tuple[Path, str] | None:
    """(checkout folder, command run there) that writes the file at ``path`` (absolute, or relative to the current
    folder), or None when no entry of :data:`GENERATED` matches it and has its script in that checkout."""
    parts = Path(os.path.normpath(os.path.abspath(path))).parts
    for pattern, script, command in GENERATED:
        depth = len(PurePosixPath(pattern).parts)
        if len(parts) <= depth or not PurePosixPath(*parts[-depth:]).match(pattern):
            continue
        root = Path(*parts[:-depth])
        if (root / script).is_file():
            return root, command
    return None


def missing_file_hint(path: str | os.PathLike) -> str:
    """``"; run `make data` (or `COMMAND`) to generate it"`` for a missing generated file (naming the checkout when
    it is not the current folder); "" for any other file."""
    found = generating_command(path)
    if found is None:
        return ""
    root, command = found
    where = "" if root == Path.cwd().resolve() else f" in {root}"
    return f"; run `make data` (or `{command}`){where} to generate it"


def missing_asset_hint(layer_path: str | None, asset: str | None) -> str:
    """:func:`missing_file_hint` for ``asset`` as authored in the layer at ``layer_path`` (a relative asset path is
    relative to the layer's folder)."""
    if not asset:
        return ""
    if not os.path.isabs(asset) and layer_path:
        asset = os.path.join(os.path.dirname(layer_path), asset)
    return missing_file_hint(asset)
