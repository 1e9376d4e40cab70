"""Every Warp module warpsky launches, including each specialisation of factory-made kernels.

The CUDA code-generation test compiles all of them to sm_90 PTX (Warp's bundled NVRTC works without a GPU), so
CPU-only CI catches CUDA-only compile errors. A new kernel module or specialisation must be listed here.
"""

from __future__ import annotations


def kernel_modules() -> list:
    """Warp ``Module`` objects for every kernel warpsky can launch."""
    import warp as wp

    import warpsky.media.fields as fields
    import warpsky.optics.ice_kernels as ice_kernels
    import warpsky.optics.kernels as optics
    import warpsky.techniques.sky.kernels as sky
    from warpsky.techniques.path_tracer.kernels import path_trace_kernel
    from warpsky.techniques.single_scatter.kernels import single_scatter_kernel
    from warpsky.techniques.slicing.kernels import slicing_kernels

    modules = [wp.get_module(fields.__name__), wp.get_module(optics.__name__), wp.get_module(ice_kernels.__name__),
               wp.get_module(sky.__name__)]
    modules += [
        single_scatter_kernel(has_ground, has_tables, has_detail).module
        for has_ground in (False, True)
        for has_tables in (False, True)
        for has_detail in (False, True)
    ]
    modules += [
        path_trace_kernel(has_ground, has_tables, has_detail).module
        for has_ground in (False, True) for has_tables in (False, True) for has_detail in (False, True)
    ]
    modules += [k.module for low in (False, True) for eq in (0, 24, 25) for has_detail in (False, True)
                for k in slicing_kernels(low, eq, has_detail)]
    from warpsky.techniques.slicing.kernels import ground_kernel

    modules += [ground_kernel(has_detail).module for has_detail in (False, True)]
    import warpsky.evaluation.stratiform_reference as stratiform_reference
    import warpsky.evaluation.stratiform_slab as stratiform_slab
    import warpsky.techniques.radiosity.kernels as radiosity

    modules += [wp.get_module(stratiform_slab.__name__), wp.get_module(stratiform_reference.__name__),
                wp.get_module(radiosity.__name__)]
    import warpsky.techniques.stratiform.kernels as stratiform_kernels

    modules.append(wp.get_module(stratiform_kernels.__name__))
    modules.append(wp.get_module(__import__("warpsky.media.advection_kernels", fromlist=["*"]).__name__))
    return modules
