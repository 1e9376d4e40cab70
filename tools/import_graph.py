"""warpsky's import graph, read from the syntax trees of its modules (every import statement, those inside
functions included; nothing is imported), and the layers it must respect: ``tests/test_architecture.py`` checks
them and ``tools/make_architecture_diagram.py`` draws them."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "warpsky"

#: The layers, bottom first: a module imports only from its own layer or those below (docs/architecture.md).
#: Longest prefix wins, so the stage readers (``scene.usd*``) sit above the media and optics whose file loaders
#: they use, while the scene's plain dataclasses sit at the bottom.
LAYERS = (
    ("core", ("warpsky.errors", "warpsky.version", "warpsky.interrupt", "warpsky.files", "warpsky.settings",
              "warpsky.device", "warpsky.device_buffers", "warpsky.kernel_variants", "warpsky.numerics",
              "warpsky.layer", "warpsky.resources")),
    ("scene", ("warpsky.scene", "warpsky.camera_rays", "warpsky.output")),
    ("optics", ("warpsky.optics",)),
    ("media", ("warpsky.media", "warpsky.surfaces")),
    ("stage", tuple(f"warpsky.scene.{name}" for name in ("usd", "usd_composition", "usd_ignored", "usd_layers",
                                                         "usd_lights", "usd_prims", "usd_render", "usd_scenery",
                                                         "usd_surfaces", "usd_volumes"))),
    ("light", ("warpsky.light",)),
    ("composite", ("warpsky.composite",)),
    ("techniques and passes", ("warpsky.techniques", "warpsky.passes")),
    ("plan", ("warpsky.registry", "warpsky.plan", "warpsky.kernel_cache")),
    ("frame, batch, cli", ("warpsky", "warpsky.render", "warpsky.api", "warpsky.batch", "warpsky.evaluation",
                           "warpsky.cli", "warpsky.cli_options", "warpsky.cli_info", "warpsky.kernel_registry",
                           "warpsky.__main__")),
)
def modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the warpsky modules its import statements (anywhere in it) name."""
    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = defaultdict(set)
    for module, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                           for a in node.names]
            else:
                continue
            for target in targets:
                resolved = resolve(target) if target.startswith("warpsky") else None
                if resolved is not None and resolved != module:
                    edges[module].add(resolved)
    return edges


def layer_of(module: str) -> int:
    best = None
    for rank, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > best[1]):
                best = (rank, len(prefix))
    if best is None:
        raise KeyError(f"{module} is in no layer of LAYERS")
    return best[0]
