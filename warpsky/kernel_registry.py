"""Every Warp module warpsky launches, including each specialisation of factory-made kernels.

The CUDA code-generation test compiles all of them to sm_90 PTX (Warp's bundled NVRTC works without a GPU), so
CPU-only CI catches CUDA-only compile errors. Modules with plain ``@wp.kernel`` definitions are listed below (the
test fails when one is missing); kernel factories declare their flags with
:func:`~warpsky.kernel_variants.kernel_variants` where they are defined, and every combination is compiled.
"""

from __future__ import annotations

import warp as wp

import warpsky.evaluation.stratiform_reference as stratiform_reference
import warpsky.evaluation.stratiform_slab as evaluation_slab
import warpsky.media.advection_kernels as advection_kernels
import warpsky.media.air_front as air_front
import warpsky.media.fields as fields
import warpsky.media.heightfield as heightfield_media
import warpsky.optics.ice_kernels as ice_kernels
import warpsky.optics.kernels as optics
import warpsky.optics.oriented_ice_kernels as oriented_ice_kernels
import warpsky.passes.fog.kernels as fog_kernels
import warpsky.passes.heightfield.kernels as heightfield_kernels
import warpsky.passes.sky.kernels as sky
import warpsky.passes.stratiform.kernels as stratiform_kernels
import warpsky.passes.stratiform.radiosity_kernels as radiosity
import warpsky.passes.surfaces.kernels as surfaces_kernels
import warpsky.techniques.path_tracer.kernels  # noqa: F401  (registers its kernel factory)
import warpsky.techniques.single_scatter.kernels  # noqa: F401  (registers its kernel factories)
import warpsky.techniques.slicing.ground  # noqa: F401  (registers its kernel factory)
import warpsky.techniques.slicing.kernels as slicing  # (also registers its kernel factories)
from warpsky.kernel_variants import variant_modules

#: Modules holding plain (not factory-made) kernels.
PLAIN_MODULES = (fields, optics, ice_kernels, sky, evaluation_slab, stratiform_reference, radiosity, stratiform_kernels,
                 advection_kernels, slicing, surfaces_kernels, fog_kernels, heightfield_media, heightfield_kernels,
                 oriented_ice_kernels, air_front)

def kernel_modules() -> list:
    """Warp ``Module`` objects for every kernel warpsky can launch."""
    return [wp.get_module(m.__name__) for m in PLAIN_MODULES] + variant_modules()


def compile_ptx(index: int, folder: str, arch: int = 90) -> list[str]:
    """Compile ``kernel_modules()[index]`` to PTX for ``arch`` into ``folder``; the output paths. A function of
    plain arguments, so that separate processes can compile modules side by side (NVRTC uses one core)."""
    module = kernel_modules()[index]
    return [str(p) for p in wp.compile_aot_module(module, arch=arch, use_ptx=True, module_dir=folder)]
