"""Every kernel module compiles for CUDA (sm_90 PTX), even on a machine without a GPU."""

from __future__ import annotations

import pytest
import warp as wp

from warpsky.kernel_registry import kernel_modules


@pytest.mark.slow
@pytest.mark.parametrize("module", kernel_modules(), ids=lambda m: m.name)
def test_module_compiles_to_sm90_ptx(module, tmp_path):
    outputs = wp.compile_aot_module(module, arch=90, use_ptx=True, module_dir=tmp_path)
    ptx = [p for p in outputs if str(p).endswith(".ptx")]
    assert ptx, f"no PTX produced for {module.name}: {outputs}"
    text = ptx[0].read_text()
    assert ".target sm_90" in text and ".entry" in text


def test_registry_lists_every_kernel_module():
    """Any module-level @wp.kernel in the package must belong to a module the registry compiles."""
    import importlib
    import pkgutil

    import warpsky

    registered = {m.name for m in kernel_modules()}
    missing = []
    for info in pkgutil.walk_packages(warpsky.__path__, "warpsky."):
        if info.name.endswith("cli") or info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for value in vars(module).values():
            if isinstance(value, wp.Kernel) and value.module.name not in registered:
                missing.append(f"{info.name}.{value.key}")
    assert not missing, f"kernels not in warpsky.kernel_registry: {missing}"
