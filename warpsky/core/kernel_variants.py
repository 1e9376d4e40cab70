"""Kernel factories declare the flags they specialise on where they are defined, so every variant gets compiled.

A factory made with ``functools.cache`` that builds Warp kernels per scene feature is decorated with the domain of
each of its flags::

    @kernel_variants(has_ground=(False, True), has_tables=(False, True), has_detail=(False, True))
    @functools.cache
    def single_scatter_kernel(has_ground: bool, has_tables: bool, has_detail: bool = False) -> wp.Kernel: ...

:func:`variant_modules` then calls every registered factory with every combination of its flags (keyword
arguments) and collects the Warp modules of what it returns (a kernel, or a tuple of kernels), which is how the
CUDA code-generation test compiles all of them without a list kept by hand.
"""

from __future__ import annotations

import itertools

#: Up to this many flag combinations a factory's every variant is compiled by the code-generation test; beyond it,
#: :func:`covering_variants` (the path tracer's 64 variants take 11-76 s of NVRTC each on a 2-core CPU).
FULL_PRODUCT = 16
#: Every decorated factory with its flag domains, in registration (import) order.
_FACTORIES: list[tuple[object, dict[str, tuple]]] = []


def kernel_variants(**domains):
    """Register the decorated kernel factory with the values each keyword flag can take; returns it unchanged."""
    for name, values in domains.items():
        if not isinstance(values, tuple) or not values:
            raise TypeError(f"flag {name} needs a non-empty tuple of values, got {values!r}")

    def register(factory):
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


def covering_variants(domains: dict[str, tuple]) -> list[dict]:
    """Every combination when there are at most :data:`FULL_PRODUCT` of them; else the fewest that give every flag
    each of its values: every flag at its first value, each flag alone at each of its other values, and every flag
    at its last value (8 of 64 for six booleans). Every statically specialised branch is then compiled at least
    once, with its neighbours off and all of them on."""
    every = variants(domains)
    if len(every) <= FULL_PRODUCT:
        return every
    base = {name: values[0] for name, values in domains.items()}
    chosen = [base]
    for name, values in domains.items():
        chosen += [{**base, name: value} for value in values[1:]]
    chosen.append({name: values[-1] for name, values in domains.items()})
    unique = []
    for flags in chosen:
        if flags not in unique:
            unique.append(flags)
    return unique


def variant_modules(covering: bool = False) -> list:
    """Warp modules of every registered factory called with every combination of its flags (with ``covering``,
    with :func:`covering_variants` of them)."""
    modules = []
    for factory, domains in registered_factories():
        for flags in covering_variants(domains) if covering else variants(domains):
            built = factory(**flags)
            for kernel in built if isinstance(built, tuple) else (built,):
                if all(kernel.module is not m for m in modules):
                    modules.append(kernel.module)
    return modules
