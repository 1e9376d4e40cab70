"""Draw docs/architecture.png: how one frame flows through warpsky's packages.

    python tools/make_architecture_diagram.py [--out docs/architecture.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: (label, package, x, y) of each stage of a frame, left to right along the data flow.
BOXES = [
    ("USD stage", ".usda / .nvdb / .vdb / .npy", 0.0, 1.0),
    ("scene", "warpsky/scene\nScene: plain dataclasses, SI", 1.0, 1.0),
    ("plan", "warpsky/plan.py\nRenderPlan: technique, settings,\nfeatures, species (warpsky info)", 2.0, 1.0),
    ("media", "warpsky/media\nVoxelMedia, Air, detail,\nstratiform maps (wp.structs)", 3.0, 1.6),
    ("optics", "warpsky/optics\nphase tables, Ams_n,\nphase eval / sample / pdf", 3.0, 0.4),
    ("technique passes", "warpsky/techniques\nsingle_scatter, slicing,\npath_tracer, stratiform, sky", 4.0, 1.0),
    ("composite", "warpsky/composite.py\nLayers front to back", 5.0, 1.0),
    ("output", "warpsky/output\nEXR (atomic), PNG", 6.0, 1.0),
]
ARROWS = [(0, 1), (1, 2), (2, 3), (2, 4), (3, 5), (4, 5), (5, 6), (6, 7)]


def draw(out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    fig, ax = plt.subplots(figsize=(15, 4.6), dpi=110)
    ax.set_xlim(-0.6, 6.6)
    ax.set_ylim(-0.55, 2.35)
    ax.axis("off")
    w, h = 0.86, 0.62
    for label, text, x, y in BOXES:
        ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h, boxstyle="round,pad=0.02", fc="#eef4fb",
                                    ec="#2b5d8a", lw=1.4))
        ax.text(x, y + 0.17, label, ha="center", va="center", fontsize=11, weight="bold", color="#14324d")
        ax.text(x, y - 0.08, text, ha="center", va="center", fontsize=7.4, color="#222222")
    for a, b in ARROWS:
        xa, ya = BOXES[a][2], BOXES[a][3]
        xb, yb = BOXES[b][2], BOXES[b][3]
        ax.annotate("", xy=(xb - w / 2, yb), xytext=(xa + w / 2, ya),
                    arrowprops={"arrowstyle": "->", "color": "#2b5d8a", "lw": 1.3})
    # the drivers around one frame
    ax.add_patch(FancyBboxPatch((-0.45, -0.5), 6.9, 0.42, boxstyle="round,pad=0.02", fc="#fbf3e8", ec="#a0692b"))
    ax.text(3.0, -0.29, "warpsky/cli.py  →  warpsky/batch (frame lists, resume, Dask)  →  render.py: one plan per "
            "frame, the plan's passes, composite, write", ha="center", va="center", fontsize=9, color="#5a3a12")
    ax.text(4.0, 2.12, "a new technique: a Settings dataclass + a class with name, capabilities, resolved_settings, "
            "render(scene, w, h) → Layer,\nkernels that take the shared structs; registered in techniques/base.py",
            ha="center", va="center", fontsize=8.5, style="italic", color="#14324d")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "architecture.png")
    print(draw(parser.parse_args(argv).out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
