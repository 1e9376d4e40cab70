"""What a ``warpsky render`` process holds before its frame allocates anything: the interpreter with its libraries and
the opened stage (:data:`~warpsky.core.resources.PROCESS_BYTES`), and what reading the stage's data left
(:func:`stage_memory`). The plan puts both in front of the passes' estimates (:func:`held_memory`), so that
``warpsky info`` prints what the process will need at its peak, and the guards leave them out of what the frame must
still find free (:meth:`~warpsky.core.resources.MemoryEstimate.frame_host`).

Reading a NanoVDB field peaks well above what it keeps: Warp's copy of the grid and its list of active voxels are
freed once the dense grid is filled, and the frame's buffers then reuse that memory. The process's peak is the
larger of the read's peak and what it keeps plus the frame's parts (:func:`with_stage_read`).

Measured as the resident-size growth over ``StageReader.scene_at`` of every shipped stage (96x64 and 384x256 read
the same, 2-core x86_64 CPU, Warp 1.19): 6 MiB for the sundogs' two small ``.npy`` fields, 9 MiB for the
stratocumulus' maps, 24 MiB for the 131,072-triangle terrain of the sunbeams and the valley fog; the demo cumulus'
NanoVDB field of 194x130x194 voxels peaked at 146 MiB over the process and the storm's four of 920,160 voxels in
all at 33 MiB, and neither frame's render grew the process by more than its estimated parts less the read's
temporaries (the cumulus' 384x256 render by 15 MiB).
"""

from __future__ import annotations

from pathlib import Path

from warpsky.core.resources import PROCESS_BYTES, MemoryEstimate
from warpsky.model.scene import Scene

#: Bytes any stage's read holds: the scene's prims read into Python, the camera, lights and small maps (6 MiB on
#: the sundogs, whose two fields hold 0.3 MiB).
STAGE_READ_BYTES = 6 * 2**20
#: Bytes per voxel a field keeps once read: its dense float32 grid.
FIELD_BYTES = 4
#: Bytes per voxel of a NanoVDB or OpenVDB field's read at its peak: the dense grid, Warp's copy of the NanoVDB
#: grid and its active-voxel list (int32 x 3): (146 - 6) MiB for the demo cumulus' 4.89 million voxels (28.6 B),
#: (33 - 6) MiB for the storm's 0.92 million (29.3 B).
FIELD_READ_PEAK_BYTES = 29
#: Bytes per triangle of a mesh read from USD: float64 points and normals, int32 indices and USD's own arrays
#: ((24 - 6) MiB for the 131,072-triangle terrain, 144 B).
MESH_READ_BYTES = 144


def field_read_peak(medium) -> int:
    """Bytes reading ``medium``'s field takes at its peak (:data:`FIELD_READ_PEAK_BYTES` per voxel from a VDB
    file, :data:`FIELD_BYTES` from a ``.npy`` one)."""
    npy = Path(medium.source).suffix.lower() == ".npy"
    return (FIELD_BYTES if npy else FIELD_READ_PEAK_BYTES) * int(medium.density.size)


def stage_memory(scene: Scene) -> int:
    """Bytes reading the stage's data for ``scene`` leaves held: its fields' dense grids and its meshes, on top of
    :data:`STAGE_READ_BYTES`."""
    fields = sum(FIELD_BYTES * int(m.density.size) for m in scene.media)
    meshes = sum(MESH_READ_BYTES * len(m.triangles) for m in scene.meshes)
    return STAGE_READ_BYTES + fields + meshes


def stage_read_peak(scene: Scene) -> int:
    """Bytes reading the stage's data for ``scene`` takes at its peak (:func:`stage_memory` with the fields'
    read temporaries)."""
    extra = sum(field_read_peak(m) - FIELD_BYTES * int(m.density.size) for m in scene.media)
    return stage_memory(scene) + extra


def held_memory(scene: Scene) -> MemoryEstimate:
    """The ``process`` and ``stage data`` parts of a frame's estimate, held before the frame."""
    return (MemoryEstimate()
            .add("process", host=PROCESS_BYTES, held=True)
            .add("stage data", host=stage_memory(scene), held=True))


def with_stage_read(estimate: MemoryEstimate, scene: Scene, device: str) -> MemoryEstimate:
    """``estimate`` (:func:`held_memory` and the frame's parts) with a ``stage read`` part where the read's peak
    exceeds what it keeps plus the frame's parts: the read's temporaries that the frame's buffers do not reuse."""
    beyond = stage_read_peak(scene) - stage_memory(scene) - estimate.frame_host(device)
    if beyond > 0:
        estimate.add("stage read", host=beyond, held=True)
    return estimate
