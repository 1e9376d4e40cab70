"""Every kernel module compiles for CUDA (sm_90 PTX), even on a machine without a GPU: every plain module and every
variant of every kernel factory (none has more than 16, which ``kernel_variants`` enforces)."""

from __future__ import annotations

import ast
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from warpsky.cli.kernel_registry import compile_ptx, kernel_modules
from warpsky.core.kernel_variants import MAX_VARIANTS, kernel_variants, registered_factories, variants

#: Every plain kernel module and every variant of each kernel factory.
MODULES = kernel_modules()


@pytest.fixture(scope="module")
def ptx_builds(request):
    """The selected modules' sm_90 compiles, started at once on a pool of processes (one per core, at most 4): each
    NVRTC compile uses one core, so the suite's longest part runs side by side. Each test then waits for its own.

    The PTX goes to Warp's kernel cache, named by the module's hash (its kernels' and functions' code and the
    compile options), as Warp's own compiles are: a module compiled before with the same code is found there, and
    any change to it compiles it again. The 16 variants of the path tracer take 40-150 s of NVRTC each on this
    2-core CPU, which a fresh folder per run would pay on every ``make test``."""
    selected = {item.callspec.params["module"].name for item in request.session.items
                if getattr(item, "originalname", "") == "test_module_compiles_to_sm90_ptx"}
    pool = ProcessPoolExecutor(max(1, min(os.cpu_count() or 1, 4)), mp_context=multiprocessing.get_context("spawn"))
    futures = {m.name: pool.submit(compile_ptx, i, None, 90) for i, m in enumerate(MODULES) if m.name in selected}
    yield futures
    pool.shutdown(wait=True, cancel_futures=True)


@pytest.mark.slow
@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.name)
def test_module_compiles_to_sm90_ptx(module, ptx_builds):
    outputs = ptx_builds[module.name].result()
    ptx = [Path(p) for p in outputs if str(p).endswith(".ptx")]
    assert ptx, f"no PTX produced for {module.name}: {outputs}"
    text = ptx[0].read_text()
    assert ".target sm_90" in text and ".entry" in text


def test_registry_finds_every_module_with_kernels():
    """Every source file with a module-level ``@wp.kernel`` (read from its syntax tree, not imported) is one of the
    modules the registry compiles: a new technique or pass needs no entry anywhere for its kernels to be tested."""
    import warpsky
    from warpsky.cli.kernel_registry import plain_kernel_modules

    package = Path(warpsky.__file__).parent
    expected = set()
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text())
        if any(isinstance(node, ast.FunctionDef) and "kernel" in _decorator_names(node) for node in tree.body):
            parts = path.relative_to(package.parent).with_suffix("").parts
            expected.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    found = set(plain_kernel_modules())
    assert expected <= found, f"kernel modules the registry misses: {sorted(expected - found)}"
    assert {"warpsky.passes.sky.sky_kernels", "warpsky.passes.fog.fog_kernels", "warpsky.media.voxels.fields"} <= found


def _decorator_names(node) -> set[str]:
    """Last dotted part of each decorator of a function (``functools.cache`` -> ``cache``)."""
    names = set()
    for d in node.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        names.add(target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", ""))
    return names


def test_every_kernel_factory_declares_its_variants():
    """A cached function that builds ``@wp.kernel``s must carry ``@kernel_variants``, so that every combination of
    its flags reaches the compile test above."""
    import warpsky

    package = Path(warpsky.__file__).parent
    undeclared = []
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef) or "cache" not in _decorator_names(node):
                continue
            builds_kernel = any(isinstance(inner, ast.FunctionDef) and "kernel" in _decorator_names(inner)
                                for inner in ast.walk(node) if inner is not node)
            if builds_kernel and "kernel_variants" not in _decorator_names(node):
                undeclared.append(f"{path.relative_to(package.parent)}:{node.name}")
    registered = {factory.__wrapped__.__name__ for factory, _ in registered_factories()}
    undeclared = [name for name in undeclared if name.split(":")[1] not in registered]
    assert not undeclared, f"kernel factories without @kernel_variants: {undeclared}"


def test_no_factory_has_more_variants_than_the_cap():
    """Every registered factory is within the cap, and a factory that declares more combinations (five boolean
    flags: 32) is refused at decoration time, with its name and its count, and not registered."""
    assert MAX_VARIANTS == 16
    assert all(len(variants(domains)) <= MAX_VARIANTS for _, domains in registered_factories())

    def too_many(**flags):
        return None

    five = {f"f{i}": (False, True) for i in range(5)}
    with pytest.raises(ValueError, match=r"test_cuda_codegen\.test_no_factory.*too_many declares 32 variants"):
        kernel_variants(**five)(too_many)
    assert all(f is not too_many for f, _ in registered_factories())
