"""Kernel factories declare the flags they specialise on where they are defined, so every variant gets compiled.

A factory made with ``functools.cache`` that builds Warp kernels per scene feature is decorated with the domain of
each of its flags::

    @kernel_variants(has_tables=(False, True), has_detail=(False, True))
    @functools.cache
    def single_scatter_kernel(has_tables: bool, has_detail: bool = False) -> wp.Kernel: ...

:func:`variant_modules` then calls every registered factory with every combination of its flags (keyword
arguments) and collects the Warp modules of what it returns (a kernel, or a tuple of kernels), which is how the
CUDA code-generation test compiles all of them without a list kept by hand.

Which branches are specialised (the rule):

- **Compile-time** (a factory flag, ``wp.static``): a branch that changes what the kernel reads, which arrays,
  structs or tables are bound and looked up (tabulated species' phase tables, animated detail's second grid, the
  meshes' BVH, the analytic fogs' terms), or that changes its register footprint or the cost of an inner loop
  (per tracking step, per march step). A scene without the feature then runs none of its code.
- **Runtime** (a field of a ``wp.struct`` the kernel already gets, or a plain ``int`` argument): a branch that is
  cheap and uniform across the launch, the same for every thread, such as whether a ground plane or a dome exists:
  one test per path event, a few registers (``Ground.enabled``, ``DomeLight.enabled``, ``Air.enabled``; the sky
  and stratiform kernels' ``has_ground`` argument). The ground's and the dome's code is small next to a path's, so
  it is compiled into every variant.
- **The cap**: no factory has more than :data:`MAX_VARIANTS` flag combinations (each compile of a large kernel takes
  tens of seconds of NVRTC, and every variant is a CUDA module the code-generation test compiles and a user may wait
  for). :func:`kernel_variants` raises when a factory declares more: make a flag runtime by the rule above first.
"""

from __future__ import annotations

import itertools
import math

#: The most flag combinations a kernel factory may declare; every one is compiled by the code-generation test.
MAX_VARIANTS = 16
#: Every decorated factory with its flag domains, in registration (import) order.
_FACTORIES: list[tuple[object, dict[str, tuple]]] = []


def kernel_variants(**domains):
    """Register the decorated kernel factory with the values each keyword flag can take; returns it unchanged.
    Raises ValueError when the flags have more than :data:`MAX_VARIANTS` combinations."""
    for name, values in domains.items():
        if not isinstance(values, tuple) or not values:
            raise TypeError(f"flag {name} needs a non-empty tuple of values, got {values!r}")
    count = math.prod(len(values) for values in domains.values())

    def register(factory):
        if count > MAX_VARIANTS:
            name = f"{factory.__module__}.{getattr(factory, '__qualname__', factory)}"
            raise ValueError(f"kernel factory {name} declares {count} variants ({', '.join(domains)}), more than "
                             f"the {MAX_VARIANTS} allowed: make a cheap branch that is uniform across the launch a "
                             f"runtime struct field (see warpsky.core.kernel_variants)")
        if all(f is not factory for f, _ in _FACTORIES):
            _FACTORIES.append((factory, dict(domains)))
        return factory

    return register


def registered_factories() -> list[tuple[object, dict[str, tuple]]]:
    """(factory, flag domains) of every decorated factory imported so far."""
    return list(_FACTORIES)


def variants(domains: dict[str, tuple]) -> list[dict]:
    """Every combination of the flags' values, as keyword-argument dictionaries."""
    names = list(domains)
    return [dict(zip(names, values, strict=True)) for values in itertools.product(*(domains[n] for n in names))]


def variant_modules() -> list:
    """Warp modules of every registered factory called with every combination of its flags."""
    modules = []
    for factory, domains in registered_factories():
        for flags in variants(domains):
            built = factory(**flags)
            for kernel in built if isinstance(built, tuple) else (built,):
                if all(kernel.module is not m for m in modules):
                    modules.append(kernel.module)
    return modules
