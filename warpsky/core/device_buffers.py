"""Device memory that outlives a frame: work buffers reused by every frame of a batch, uploads keyed by their
content, and downloads through pinned host memory on CUDA.

A batch renders frame after frame in one process (or one per Dask worker) with the same resolution and, often, the
same grids; allocating and uploading them anew each frame costs time on a GPU (allocation, page-locking, copies
from pageable memory). Three tools, each named by the caller so that different uses never share an array:

- :func:`reusable`: a device array of a given shape and dtype, the same one each time it is asked for with the
  same name, shape, dtype and device (its contents are whatever the last user left: clear it if that matters);
  asking for another shape replaces it. One array per name is kept.
- :func:`upload`: a device copy of a host array, skipped when the same name already holds the same bytes (a
  BLAKE2 digest of the contents: about 1 ms per 2.5 MB on the CPU).
- :func:`refill`: a :func:`reusable` array filled with host values that may change from frame to frame (an
  advected thickness map, a depth image): no allocation while the shape holds, no copy while the bytes do.
- :func:`download`: a host copy of a device array; on CUDA through a pinned staging buffer kept per name (a copy
  from pinned memory runs at the bus's full rate; from pageable memory the driver stages it itself).

Kept arrays are one set per name and device in a process, so a user of :func:`reusable` or :func:`refill` arrays
holds :func:`exclusive` for their names from filling them to its last download: two frames rendered at once by
threads of one process (a multi-threaded Dask worker, the Python API called from threads) then take turns instead
of writing into each other's arrays. :func:`upload` needs no lock: it replaces a kept array rather than writing
into it, and whoever holds the previous one keeps it.

:func:`allocation_count` counts the arrays these functions allocated, for tests and benchmarks.
"""

from __future__ import annotations

import hashlib
import threading

import numpy as np
import warp as wp

_LOCK = threading.Lock()
_ARRAYS: dict[tuple[str, str], tuple[tuple, wp.array]] = {}  # (name, device) -> ((shape, dtype), array)
_UPLOADS: dict[tuple[str, str], tuple[tuple, wp.array]] = {}  # (name, device) -> ((digest, shape, dtype), array)
_STAGING: dict[tuple[str, str], tuple[tuple, wp.array]] = {}  # (name, device) -> ((shape, dtype), pinned array)
_FILLED: dict[tuple[str, str], tuple] = {}  # (name, device) -> ((digest, dtype), the filled array)
_SCOPES: dict[tuple[str, str], threading.RLock] = {}  # (scope, device) -> its lock
_COUNT = [0]


def allocation_count() -> int:
    """How many arrays :func:`reusable`, :func:`upload` and :func:`download` have allocated in this process."""
    return _COUNT[0]


def clear() -> None:
    """Forget every kept array (they are freed when no one else holds them)."""
    with _LOCK:
        _ARRAYS.clear()
        _UPLOADS.clear()
        _STAGING.clear()
        _FILLED.clear()


def _device_name(device) -> str:
    return str(wp.get_device(device))


def exclusive(scope: str, device) -> threading.RLock:
    """The lock of the arrays named ``scope:*`` on ``device``, to hold (``with``) while using them; reentrant, so a
    function holding it may call another that takes it too. Locks of different scopes nest in one order only."""
    key = (scope, _device_name(device))
    with _LOCK:
        return _SCOPES.setdefault(key, threading.RLock())


def reusable(name: str, shape, dtype, device) -> wp.array:
    """The device array kept under ``name`` for this ``shape``, ``dtype`` and ``device`` (allocated on first use or
    when the shape changes; contents not cleared)."""
    shape = (int(shape),) if np.isscalar(shape) else tuple(int(n) for n in shape)
    return _kept(_ARRAYS, (name, _device_name(device)), (shape, dtype),
                 lambda: wp.empty(shape, dtype=dtype, device=device))


def _kept(store: dict, key: tuple, spec: tuple, make):
    """``store``'s array under ``key`` when it was made for ``spec``, else a new one from ``make()`` kept there."""
    with _LOCK:
        kept = store.get(key)
        if kept is not None and kept[0] == spec:
            return kept[1]
        array = make()
        _COUNT[0] += 1
        store[key] = (spec, array)
        return array


def _digest(values: np.ndarray) -> str:
    return hashlib.blake2b(np.ascontiguousarray(values).view(np.uint8).reshape(-1), digest_size=16).hexdigest()


def upload(name: str, values: np.ndarray, dtype, device) -> wp.array:
    """A device array holding ``values`` (converted to ``dtype``), uploaded only when ``name`` does not already hold
    the same contents on ``device``. Callers must not write into the returned array."""
    values = np.ascontiguousarray(values)
    spec = (_digest(values), values.shape, str(values.dtype), dtype)
    return _kept(_UPLOADS, (name, _device_name(device)), spec, lambda: wp.array(values, dtype=dtype, device=device))


def download(name: str, array: wp.array) -> np.ndarray:
    """A host copy of ``array`` (owned by the caller); on CUDA staged through a pinned buffer kept under ``name``."""
    if not array.device.is_cuda:
        return array.numpy().copy()
    key, spec = (name, _device_name(array.device)), (array.shape, array.dtype)
    with _LOCK:
        kept = _STAGING.get(key)
        if kept is None or kept[0] != spec:
            kept = (spec, wp.empty(array.shape, dtype=array.dtype, device="cpu", pinned=True))
            _COUNT[0] += 1
            _STAGING[key] = kept
        staging = kept[1]
        wp.copy(staging, array)
        wp.synchronize_device(array.device)
        return staging.numpy().copy()


def refill(name: str, values: np.ndarray, dtype, device) -> wp.array:
    """The :func:`reusable` array ``name`` holding ``values`` (converted to ``dtype``, a scalar or vector type: a
    vector's components are the last axis of ``values``), copied only when its bytes differ from the last fill.
    Callers must not write into it; the next fill under ``name`` overwrites it."""
    values = np.ascontiguousarray(values)
    length = getattr(dtype, "_length_", 1)
    shape = values.shape if length == 1 else values.shape[:-1]
    array = reusable(name, shape, dtype, device)
    key, spec = (name, _device_name(device)), (_digest(values), str(values.dtype))
    with _LOCK:
        kept = _FILLED.get(key)
        if kept is not None and kept[0] == spec and kept[1] is array:
            return array
    wp.copy(array, wp.array(values, dtype=dtype, device="cpu"))
    with _LOCK:
        _FILLED[key] = (spec, array)
    return array
