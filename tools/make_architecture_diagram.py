"""Draw docs/architecture.png from the code: how one frame flows through warpsky (the registered passes in their
order), and the import layers with the number of imports between them, read from the modules' syntax trees.

    python tools/make_architecture_diagram.py [--out docs/architecture.png]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
sys.path.insert(0, str(ROOT))

from import_graph import LAYERS, imports, layer_of, modules  # noqa: E402

BLUE, INK, SAND, BROWN = "#eef4fb", "#14324d", "#fbf3e8", "#5a3a12"


def flow_boxes() -> list[tuple[str, str]]:
    """(title, text) of each step of a frame, left to right; the passes as the registry orders them."""
    from warpsky.render.registry import pass_classes, technique_names

    passes = []
    for cls in pass_classes():
        note = " (the technique)" if cls.runs_technique else (" (wraps the rest)" if cls.wraps else "")
        passes.append(cls.name + note)
    return [
        ("stage", "USD stage\n.usda .nvdb .vdb .npy"),
        ("scene", "usd/stage.py: StageReader\nmodel/: Scene, SI, Y up"),
        ("plan", "render/plan.py + render/registry.py\nRenderPlan: technique, passes,\nsettings, features, costs"),
        ("light", "light/: sun above the air +\ntransmittance, dome, sky light,\nskylight (FrameLight)"),
        ("passes", "passes/frame.py, in order:\n" + "\n".join(passes)),
        ("technique", "techniques/<name>:\n" + "\n".join(technique_names())),
        ("composite", "passes/composite.py\nlayers front to back"),
        ("output", "output/: EXR (atomic),\nPNG, products"),
    ]


def layer_imports() -> tuple[list[int], Counter]:
    """(modules per layer, imports between layers keyed (from layer, to layer))."""
    found = modules()
    counts = [0] * len(LAYERS)
    for module in found:
        counts[layer_of(module)] += 1
    between: Counter = Counter()
    for source, targets in imports(found).items():
        for target in targets:
            a, b = layer_of(source), layer_of(target)
            if a != b:
                between[a, b] += 1
    return counts, between


def draw_flow(ax, boxes) -> None:
    from matplotlib.patches import FancyBboxPatch

    ax.set_xlim(-0.6, len(boxes) - 0.4)
    ax.set_ylim(-0.85, 1.35)
    ax.axis("off")
    ax.set_title("one frame: data flows left to right", fontsize=11, color=INK, loc="left")
    w, h = 0.9, 1.3
    for x, (title, text) in enumerate(boxes):
        ax.add_patch(FancyBboxPatch((x - w / 2, 0.5 - h / 2), w, h, boxstyle="round,pad=0.02", fc=BLUE, ec=INK))
        ax.text(x, 1.03, title, ha="center", va="center", fontsize=10.5, weight="bold", color=INK)
        ax.text(x, 0.45, text, ha="center", va="center", fontsize=7.2, color="#222222")
        if x:
            ax.annotate("", xy=(x - w / 2, 0.5), xytext=(x - 1 + w / 2, 0.5),
                        arrowprops={"arrowstyle": "->", "color": INK, "lw": 1.2})
    ax.add_patch(FancyBboxPatch((-0.45, -0.8), len(boxes) - 0.1, 0.35, boxstyle="round,pad=0.02", fc=SAND,
                                ec=BROWN))
    ax.text((len(boxes) - 1) / 2, -0.62, "cli/main.py → batch/ (frame lists, resume, Dask) → render/frame.py: read the "
            "stage, plan, run the passes per light, composite, write; a failed frame never costs finished ones",
            ha="center", va="center", fontsize=8.5, color=BROWN)


def draw_layers(ax, counts, between) -> None:
    from matplotlib.patches import FancyBboxPatch

    n = len(LAYERS)
    ax.set_xlim(0.0, 10.0)
    ax.set_ylim(-0.6, n - 0.3)
    ax.axis("off")
    ax.set_title("imports run down: a module imports its own layer and those below (tests/test_architecture.py)",
                 fontsize=11, color=INK, loc="left")
    for rank, (name, prefixes) in enumerate(LAYERS):
        y = rank
        ax.add_patch(FancyBboxPatch((0.2, y - 0.36), 6.3, 0.72, boxstyle="round,pad=0.02", fc=BLUE, ec=INK))
        shown = ", ".join(f"{p}/" if p and p != "api" and p != "__main__" else (p + ".py" if p else "__init__.py")
                          for p in prefixes)
        if len(shown) > 92:
            shown = shown[:89] + "..."
        ax.text(0.35, y + 0.12, f"{name}  ({counts[rank]} modules)", fontsize=9, weight="bold", color=INK,
                va="center")
        ax.text(0.35, y - 0.16, shown, fontsize=6.6, color="#222222", va="center")
        down = sum(c for (a, b), c in between.items() if a == rank and b < rank)
        if down:
            ax.text(6.7, y, f"{down} imports into the layers below", fontsize=7.5, color=INK, va="center")
    up = sum(c for (a, b), c in between.items() if b > a)
    ax.text(6.7, -0.45, f"imports up the layers: {up}", fontsize=8.5, color=BROWN, weight="bold", va="center")


def draw(out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    counts, between = layer_imports()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(16, 9), dpi=100, gridspec_kw={"height_ratios": [0.8, 1.5]})
    draw_flow(top, flow_boxes())
    draw_layers(bottom, counts, between)
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
