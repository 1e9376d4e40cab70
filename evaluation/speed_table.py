"""The table ``warpsky bench speed`` prints: its columns, one row's cells and the note under it."""

from __future__ import annotations

from pathlib import Path

from warpsky.core.device import is_cpu

#: Columns of :func:`format_table`, in order.
COLUMNS = ("device", "threads", "stage", "technique", "size", "cold ms", "cold kernels", "warm ms", "fps",
           "CPU/wall", "kernel ms", "copy ms", "peak MiB", "Mpaths/s", "steps/path", "events/path", "settings")
LEFT_ALIGNED = ("device", "stage", "technique", "cold kernels", "settings")
#: What the columns measure (under the table and in the JSON).
NOTE = ("cold: plan + first frame of a fresh process (kernels compiled or loaded from Warp's cache, as 'cold kernels' "
        "says); warm: median frame after it; CPU/wall: process CPU time over wall time of the warm frames (the "
        "cores kept busy; a GPU row counts the host thread); kernel/copy ms: CUDA events of one more frame (n/a on "
        "the CPU); peak MiB: CUDA mempool high-water mark on GPUs, process peak RSS on the CPU; Mpaths/s: the Monte "
        "Carlo part only (hybrid: frame time less single scattering and denoising); steps/path: tentative "
        "collisions and majorant-segment crossings per path (shadow rays towards the sun in brackets); events/path: "
        "scattering events per path (the rest of the steps are null collisions and crossings).")


def _cell(value, fmt: str, missing: str) -> str:
    return missing if value is None else format(value, fmt)


def table_cells(row: dict) -> list[str]:
    """``row`` as the text of :data:`COLUMNS`."""
    threads = "-" if row.get("threads") is None else str(row["threads"])
    settings = " ".join(f"{k}={v}" for k, v in row.get("settings", {}).items()) or "defaults"
    head = [row["device"], threads, Path(row["stage"]).stem, row["technique"], f"{row['width']}x{row['height']}"]
    if "error" in row:
        return head + ["failed"] + [""] * (len(COLUMNS) - len(head) - 2) + [row["error"]]
    gpu_missing = "n/a" if is_cpu(row["device"]) else "-"
    paths = row.get("paths_per_s")
    return head + [
        f"{row['cold_ms']:.0f}", row["cold_kernels"], f"{row['warm_ms']:.1f}", f"{row['fps']:.2f}",
        _cell(row.get("cores_busy"), ".2f", "-"),
        _cell(row.get("kernel_ms"), ".2f", gpu_missing), _cell(row.get("copy_ms"), ".2f", gpu_missing),
        _cell(row.get("peak_mib"), ".0f", "-"), "-" if paths is None else f"{paths / 1e6:.2f}",
        _steps_cell(row.get("per_path")), _cell((row.get("per_path") or {}).get("events"), ".1f", "-"), settings,
    ]


def _steps_cell(per_path: dict | None) -> str:
    if not per_path:
        return "-"
    return f"{per_path['steps']:.0f} ({per_path['shadow_steps']:.0f})"


def format_table(rows: list[dict]) -> str:
    """The rows as a fixed-width table under :data:`COLUMNS`, with a footer saying what the columns measure."""
    cells = [list(COLUMNS)] + [table_cells(row) for row in rows]
    widths = [max(len(line[i]) for line in cells) for i in range(len(COLUMNS))]
    left = {COLUMNS.index(name) for name in LEFT_ALIGNED}
    lines = ["  ".join(text.ljust(widths[i]) if i in left else text.rjust(widths[i])
                       for i, text in enumerate(line)).rstrip() for line in cells]
    return "\n".join([*lines, NOTE])
