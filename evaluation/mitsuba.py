"""Cross-check with an independent renderer: a warpsky scene as a Mitsuba 3 scene, rendered with ``volpath``.

Optional (extra ``compare``: ``pip install warpsky[compare]``); Mitsuba's ``llvm_ad_rgb`` variant needs a system
LLVM: Debian's ``libllvm19`` is found automatically, or set ``DRJIT_LIBLLVM_PATH``.

========================= ====================================================================================
warpsky                   Mitsuba 3
========================= ====================================================================================
voxel medium (one)        ``cube`` shape with a ``null`` BSDF whose interior is a ``heterogeneous`` medium;
                          ``sigma_t`` a ``gridvolume`` (trilinear, clamped, values at voxel centres like
                          warpsky's ``.npy`` grids) mapped to the same index box [-0.5, n - 0.5]^3
phase                     ``hg`` (g), ``isotropic``, ``rayleigh`` (species tables: not yet)
sun                       ``directional``, direction = light travel (-sun), ``irradiance`` = RGB irradiance
camera                    ``perspective`` with the horizontal field of view of the conformed film back; box
                          pixel filter, ``independent`` sampler (warpsky's ``pixel_jitter = 1`` matches it)
========================= ====================================================================================

Not exported (an error says so): ground planes, several media, film-back offsets, per-channel extinction,
species phase tables.
"""

from __future__ import annotations

import glob
import math
import os
import time

import numpy as np

from warpsky.core.errors import UsageError
from warpsky.model.scene import PhaseKind

#: Where Debian and Ubuntu put the LLVM shared library Dr.Jit's LLVM backend loads (LLVM 14 and 15 abort it).
LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM-1[6-9].so", "/usr/lib/x86_64-linux-gnu/libLLVM-2*.so",
                   "/usr/lib/llvm-1[6-9]/lib/libLLVM.so", "/usr/lib/llvm-2*/lib/libLLVM.so")


def import_mitsuba():
    """Import Mitsuba with the ``llvm_ad_rgb`` variant, pointing Dr.Jit at a system LLVM when needed."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = sorted(p for pattern in LLVM_CANDIDATES for p in glob.glob(pattern))
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise UsageError("the Mitsuba cross-check needs `pip install warpsky[compare]` (mitsuba)") from exc
    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception as exc:  # Dr.Jit raises plain exceptions when LLVM is missing
        raise UsageError(f"Mitsuba's llvm_ad_rgb variant is unavailable ({exc}); install Debian's libllvm19 or "
                         "set DRJIT_LIBLLVM_PATH") from exc
    return mi


def _transform(mi, matrix: np.ndarray):
    return mi.ScalarTransform4f(np.asarray(matrix, dtype=np.float64).tolist())


def scene_dict(scene, width: int, height: int, spp: int, *, max_depth: int = -1) -> dict:
    """The Mitsuba scene description of ``scene`` rendered at ``width`` x ``height``."""
    mi = import_mitsuba()
    if scene.ground is not None:
        raise UsageError("Mitsuba export: ground planes are not exported yet")
    if len(scene.media) != 1:
        raise UsageError(f"Mitsuba export: exactly one medium is supported, the scene has {len(scene.media)}")
    medium = scene.media[0]
    camera = scene.camera.conformed(width, height)
    if camera.horizontal_aperture_offset or camera.vertical_aperture_offset:
        raise UsageError("Mitsuba export: film-back offsets are not supported")
    scale = np.asarray(medium.extinction_scale, dtype=np.float64)
    albedo = np.asarray(medium.albedo, dtype=np.float64)
    if np.ptp(scale) > 0 or np.ptp(albedo) > 0:
        raise UsageError("Mitsuba export: per-channel extinction or albedo is not supported")
    n = np.array(medium.shape, dtype=np.float64)
    world_from_index = np.asarray(medium.world_from_index, dtype=np.float64)
    # unit cube [0, 1]^3 -> index box [-0.5, n - 0.5]^3 -> world; Mitsuba's cube is [-1, 1]^3
    unit_to_index = np.diag([*n, 1.0])
    unit_to_index[:3, 3] = -0.5
    cube_to_unit = np.diag([0.5, 0.5, 0.5, 1.0])
    cube_to_unit[:3, 3] = 0.5
    grid_to_world = world_from_index @ unit_to_index
    data = np.ascontiguousarray(np.transpose(medium.density, (2, 1, 0))[..., None] * scale[0], dtype=np.float32)
    phase = _phase(medium)
    forward = -camera.rotation[:, 2]
    up = camera.rotation[:, 1]
    fov = math.degrees(2.0 * math.atan(0.5 * camera.horizontal_aperture / camera.focal_length))
    out = {
        "type": "scene",
        # Russian roulette off: with albedo 1, its 0.95 survival cap makes deep paths heavy-tailed (weights
        # 1/0.95^n), so finite-sample means in thick clouds come out low; paths end by escaping instead.
        "integrator": {"type": "volpath", "max_depth": max_depth, "rr_depth": 1 << 30},
        "sensor": {
            "type": "perspective", "fov": fov, "fov_axis": "x",
            "near_clip": float(camera.near), "far_clip": float(camera.far),
            "to_world": mi.ScalarTransform4f().look_at(origin=[0.0, 0.0, 0.0], target=forward.tolist(),
                                                       up=up.tolist()),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": int(spp)},
        },
        "medium_box": {
            "type": "cube", "bsdf": {"type": "null"},
            "to_world": _transform(mi, _relative(grid_to_world @ cube_to_unit, camera.position)),
            "interior": {
                "type": "heterogeneous", "albedo": float(albedo[0]), "phase": phase, "scale": 1.0,
                "sigma_t": {"type": "gridvolume", "grid": mi.VolumeGrid(data), "filter_type": "trilinear",
                            "wrap_mode": "clamp",
                            "to_world": _transform(mi, _relative(grid_to_world, camera.position))},
            },
        },
    }
    if scene.sun is not None:
        out["sun"] = {"type": "directional", "direction": (-np.asarray(scene.sun.direction)).tolist(),
                      "irradiance": {"type": "rgb", "value": np.asarray(scene.sun.irradiance).tolist()}}
    return out


def _relative(matrix: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """``matrix`` with the camera moved to the origin (Mitsuba renders in float32, like warpsky's kernels)."""
    out = np.array(matrix, dtype=np.float64)
    out[:3, 3] -= np.asarray(origin, dtype=np.float64)
    return out


def _phase(medium) -> dict:
    if medium.species is not None:
        # tabphase's orientation convention is not verified against warpsky's tables yet
        raise UsageError(f"Mitsuba export: species phase tables ({medium.species}) are not exported yet")
    if medium.phase.kind == PhaseKind.HG:
        return {"type": "hg", "g": float(medium.phase.g)}
    if medium.phase.kind == PhaseKind.RAYLEIGH:
        return {"type": "rayleigh"}
    return {"type": "isotropic"}


def render(scene, width: int, height: int, *, spp: int, runs: int = 16, seed: int = 0) -> tuple[np.ndarray, ...]:
    """(mean image (H, W, 3), variance of the mean, seconds) from ``runs`` independent Mitsuba renders."""
    mi = import_mitsuba()
    per_run = max(1, spp // runs)
    loaded = mi.load_dict(scene_dict(scene, width, height, per_run))
    mi.render(loaded, seed=seed + 10_000)  # JIT warm-up, not timed
    started = time.perf_counter()
    images = np.stack([np.asarray(mi.render(loaded, seed=seed + i), dtype=np.float64) for i in range(runs)])
    seconds = time.perf_counter() - started
    return images.mean(axis=0), images.var(axis=0, ddof=1) / runs, seconds
