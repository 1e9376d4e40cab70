"""The Warp kernels a technique launches and how long Warp takes to compile them.

Warp compiles a kernel module on its first launch (seconds to a minute, by the size of its generated C++; see
:func:`compile_seconds`) and keeps the result in its kernel cache, one ``wp_<module name>_<hash>`` entry per module in
``wp.config.kernel_cache_dir``. A technique's kernel factories (:mod:`warpsky.core.kernel_variants`) are found from its
``kernel_modules`` (:func:`technique_factories`); :func:`compile_seconds` turns the size of a module's generated C++
into seconds by a line fitted to measured compiles (``evaluation/benchmarks/bench_compile.py``), which the compile
progress lines (:mod:`warpsky.render.compile_progress`) quote as their estimate.
"""

from __future__ import annotations


def technique_kernel_modules(technique: str) -> tuple[str, ...]:
    """The modules whose kernel factories (:mod:`warpsky.core.kernel_variants`) the technique registered as
    ``technique`` launches (its ``kernel_modules``); none for a name that is not registered."""
    from warpsky.render.registry import TECHNIQUES, technique_class

    return tuple(technique_class(technique).kernel_modules) if technique in TECHNIQUES else ()


def technique_factories(technique: str) -> list[tuple[object, dict]]:
    """(factory, flag domains) of every kernel factory ``technique`` uses, its modules imported (which registers
    them)."""
    import importlib

    from warpsky.core.kernel_variants import registered_factories

    modules = technique_kernel_modules(technique)
    for module in modules:
        importlib.import_module(module)
    return [(factory, domains) for factory, domains in registered_factories() if factory.__module__ in modules]


def built_kernels(factory, flags: dict) -> tuple:
    """The kernels ``factory`` builds for ``flags`` (a factory returns one kernel or a tuple of them)."""
    built = factory(**flags)
    return built if isinstance(built, tuple) else (built,)


def variant_module_names(technique: str) -> list[str]:
    """Warp module names of every variant of the kernel factories ``technique`` uses (builds kernel objects, does
    not compile them)."""
    from warpsky.core.kernel_variants import variants

    return [kernel.module.name for factory, domains in technique_factories(technique)
            for flags in variants(domains) for kernel in built_kernels(factory, flags)]


#: Compile time of one CPU kernel module with Warp's bundled Clang [s] = intercept + slope * megabytes of its
#: generated C++, fitted by ``evaluation/benchmarks/bench_compile.py`` on 2 CPU cores (Warp 1.19): see that file for the
#: modules, sizes and times. Other CPUs scale both by their speed; a CUDA module compiles with NVRTC instead.
COMPILE_INTERCEPT_S = 0.0
COMPILE_SECONDS_PER_MB = 7.9


def compile_seconds(source_bytes: int) -> float:
    """Estimated seconds to compile a module whose generated C++ has ``source_bytes`` bytes, on the CPU."""
    return COMPILE_INTERCEPT_S + COMPILE_SECONDS_PER_MB * source_bytes / 1e6


def module_source_bytes(module) -> int | None:
    """Bytes of the C++ Warp generates for ``module`` on the CPU (its code generator only; about 0.1-0.5 s), or
    None where this Warp's code generator cannot be called this way."""
    import warp as wp

    try:
        options = module.resolve_options(wp.config) | {"output_arch": None}
        module.get_module_hash(options.get("block_dim"))
        return len(module._run_codegen(options, True)[0])
    except Exception:  # an internal interface of Warp: without it the notice gives no estimate
        return None


def compile_estimate(technique: str) -> float | None:
    """Estimated seconds of a first frame's compiles of ``technique``: one variant (the first) of each of its kernel
    factories, each module's :func:`compile_seconds` by its generated size; None without factories or a size."""
    from warpsky.core.kernel_variants import variants

    total, counted = 0.0, 0
    for factory, domains in technique_factories(technique):
        for kernel in built_kernels(factory, variants(domains)[0]):
            size = module_source_bytes(kernel.module)
            if size is None:
                return None
            total, counted = total + compile_seconds(size), counted + 1
    return total if counted else None
