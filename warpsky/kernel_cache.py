"""Whether a technique's Warp kernels were ever compiled on this machine, so a first run can say it is compiling.

Warp compiles a kernel module on its first launch (30-60 s per module on a 2-core CPU) and keeps the result in its
kernel cache, one ``wp_<module name>_<hash>`` entry per module in ``wp.config.kernel_cache_dir``; without a word
a first render on a fresh machine spends minutes there. A factory-made kernel's module name carries a hash of its
code, so an entry under that name means this code was compiled here. The check is coarse on purpose and cheap (no
code generation): a technique counts as compiled once any variant of its kernel factories is cached, so the first
run is announced and a later one that compiles one more variant (another scene feature) is not.
"""

from __future__ import annotations

from pathlib import Path


def technique_kernel_modules(technique: str) -> tuple[str, ...]:
    """The modules whose kernel factories (:mod:`warpsky.kernel_variants`) the technique registered as
    ``technique`` launches (its ``kernel_modules``); none for a name that is not registered."""
    from warpsky.registry import TECHNIQUES, technique_class

    return tuple(technique_class(technique).kernel_modules) if technique in TECHNIQUES else ()


def variant_module_names(technique: str) -> list[str]:
    """Warp module names of every variant of the kernel factories ``technique`` uses (builds kernel objects, does
    not compile them)."""
    import importlib

    from warpsky.kernel_variants import registered_factories, variants

    modules = technique_kernel_modules(technique)
    for module in modules:
        importlib.import_module(module)  # registers its factories
    names = []
    for factory, domains in registered_factories():
        if factory.__module__ in modules:
            for flags in variants(domains):
                built = factory(**flags)
                names += [kernel.module.name for kernel in (built if isinstance(built, tuple) else (built,))]
    return names


def compile_notice(technique: str) -> str | None:
    """``compiling Warp kernels for <technique> (first run ...)`` when no variant of the technique's kernels is in
    Warp's kernel cache, else None (also for techniques without kernel factories)."""
    import warp as wp

    from warpsky.device import init_warp

    init_warp()
    names = variant_module_names(technique)
    cache = Path(wp.config.kernel_cache_dir)
    entries = {p.name for p in cache.iterdir()} if cache.is_dir() else set()
    if not names or any(entry.startswith(f"wp_{name}_") for entry in entries for name in names):
        return None
    return (f"compiling Warp kernels for {technique} (first run on this machine: 30-60 s per kernel module on 2 "
            f"CPU cores; then loaded from {cache})")
