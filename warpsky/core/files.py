"""File helpers shared by outputs and caches: the cache root, writes that are never seen half-done, and the frame
placeholder of output paths."""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from warpsky.core.errors import OutputError

#: The frame in an output path (usdrecord's rule): a run of ``#``, optionally ``.`` and more ``#`` for subframes.
PLACEHOLDER = re.compile(r"#+(\.#+)?")


def cache_dir() -> Path:
    """Root of warpsky's on-disk cache (``$WARPSKY_CACHE``, default ``~/.cache/warpsky``)."""
    return Path(os.environ.get("WARPSKY_CACHE") or Path.home() / ".cache" / "warpsky")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path: str | os.PathLike, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it onto ``path``.

    The temporary file is removed on any failure; ``path`` either keeps its old content or gets the new one whole.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp" + path.suffix, dir=directory)
    except OSError as exc:
        raise OutputError(f"cannot write into directory {directory}: {exc.strerror or exc}") from None
    os.close(fd)
    try:
        write(tmp)
        # mkstemp makes the file private (0600); give it the permissions a plain open() would.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def cached_array(folder: str, name: str, identity: tuple, build, *, keep: int | None = None):
    """The array ``build()`` returns, kept on disk: ``$WARPSKY_CACHE/FOLDER/NAME-<hash>.npy``, the hash of
    ``repr(identity)`` (everything the array depends on: its inputs, its shape, the device's kind, the building
    kernel's Warp module hash). Read back when present and readable (bit for bit what was built), else built and
    written there atomically; with ``keep``, at most that many NAME files stay, the least recently used go."""
    import hashlib

    import numpy as np

    digest = hashlib.sha256(repr(identity).encode()).hexdigest()[:20]
    path = cache_dir() / folder / f"{name}-{digest}.npy"
    try:
        values = np.load(path, allow_pickle=False)
        if keep is not None:
            os.utime(path)  # recently used
        return values
    except (OSError, ValueError, EOFError):
        pass  # missing or unreadable: built and (over)written
    values = np.asarray(build())
    atomic_write(path, lambda tmp: np.save(tmp, values))
    if keep is not None:
        _keep_newest(path.parent.glob(f"{name}-*.npy"), keep)
    return values


def _keep_newest(paths, keep: int) -> None:
    """Remove all but the ``keep`` most recently modified of ``paths`` (files another process removes are skipped)."""
    dated = []
    for path in paths:
        try:
            dated.append((path.stat().st_mtime_ns, path))
        except OSError:
            pass
    for _, path in sorted(dated, reverse=True)[keep:]:
        try:
            path.unlink()
        except OSError:
            pass
