"""Every Warp module warpsky launches, including each specialisation of factory-made kernels, found by walking the
package: a new technique or pass needs no entry here.

The CUDA code-generation test compiles all of them to sm_90 PTX (Warp's bundled NVRTC works without a GPU), so
CPU-only CI catches CUDA-only compile errors. Plain ``@wp.kernel`` definitions are found in every module of the
package; kernel factories declare their flags with :func:`~warpsky.core.kernel_variants.kernel_variants` where they are
defined, and every combination is compiled.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil

import warp as wp

#: Modules not walked: entry points that run on import.
SKIPPED = ("warpsky.__main__",)


@functools.cache
def package_modules() -> tuple[str, ...]:
    """The name of every module of the warpsky package, imported (so their kernels and factories register)."""
    import warpsky

    names = []
    for info in pkgutil.walk_packages(warpsky.__path__, "warpsky."):
        if info.name in SKIPPED:
            continue
        importlib.import_module(info.name)
        names.append(info.name)
    return tuple(names)


def plain_kernel_modules() -> list[str]:
    """Names of the modules that define plain (not factory-made) ``@wp.kernel`` functions."""
    import sys

    found = []
    for name in package_modules():
        module = sys.modules[name]
        if any(isinstance(value, wp.Kernel) and value.module.name == name for value in vars(module).values()):
            found.append(name)
    return found


def kernel_modules() -> list:
    """Warp ``Module`` objects for every kernel warpsky can launch: every plain module and every variant of every
    kernel factory (at most :data:`~warpsky.core.kernel_variants.MAX_VARIANTS` each)."""
    from warpsky.core.kernel_variants import variant_modules

    plain = [wp.get_module(name) for name in plain_kernel_modules()]
    return plain + variant_modules()


def compile_ptx(index: int, folder: str | None = None, arch: int = 90) -> list[str]:
    """Compile ``kernel_modules()[index]`` to PTX for ``arch`` into ``folder`` (None: Warp's kernel cache, where a
    module whose code is unchanged since its last compile is found under its hash and not compiled again); the
    output paths. A function of plain arguments, so that separate processes can compile modules side by side
    (NVRTC uses one core)."""
    module = kernel_modules()[index]
    return [str(p) for p in wp.compile_aot_module(module, arch=arch, use_ptx=True, module_dir=folder)]
