"""Launches of the solver's kernels over every CPU core: Warp runs one CPU launch on one thread (releasing the
GIL), so a launch over cells is split into slabs of x, one per thread, each a launch of its own. Kernels that take
this take ``x_offset`` as their last input and index x as ``x_offset + tid``; their slabs write disjoint cells and
add nothing across slabs, so results do not depend on the split. On CUDA one launch covers the grid."""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor

import warp as wp

from warpsky.core.device import cpu_thread_count, is_cpu


@functools.cache
def _pool(threads: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="warpsky-simulate")


def launch_slabs(kernel, dim: tuple[int, ...], inputs: list, device: str) -> None:
    """Launch ``kernel`` over ``dim`` (its first axis x) with ``inputs`` and the trailing ``x_offset``."""
    threads = min(cpu_thread_count(), dim[0]) if is_cpu(device) else 1
    if threads <= 1:
        wp.launch(kernel, dim=dim, inputs=[*inputs, 0], device=device)
        return
    wp.load_module(kernel.module, device=device)  # compile once, not by racing threads
    edges = [dim[0] * n // threads for n in range(threads + 1)]
    futures = [_pool(threads).submit(wp.launch, kernel, dim=(b - a, *dim[1:]), inputs=[*inputs, a], device=device)
               for a, b in zip(edges, edges[1:], strict=False) if b > a]
    for future in futures:
        future.result()
