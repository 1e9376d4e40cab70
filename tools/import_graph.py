"""warpsky's import graph, read from the syntax trees of its modules (every import statement, those inside
functions included; nothing is imported), and the layers it must respect: ``tests/test_architecture.py`` checks
them and ``tools/make_architecture_diagram.py`` draws them."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "warpsky"

#: The layers, bottom first: each is one or two folders of the package (the application also holds the package's
#: top-level modules), and a module imports only from its own layer or those below (docs/architecture.md).
LAYERS = (
    ("core", ("core",)),
    ("model", ("model",)),
    ("output", ("output",)),
    ("surfaces", ("surfaces",)),
    ("optics", ("optics",)),
    ("media", ("media",)),
    ("usd", ("usd",)),
    ("light", ("light",)),
    ("passes and techniques", ("passes", "techniques")),
    ("render", ("render",)),
    ("batch", ("batch",)),
    ("simulate", ("simulate",)),
    ("cli and api", ("cli", "", "api", "__main__")),
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
    """The rank in :data:`LAYERS` of ``module``'s top-level folder (``""`` for the package itself)."""
    parts = module.split(".")
    top = parts[1] if len(parts) > 1 else ""
    for rank, (_, folders) in enumerate(LAYERS):
        if top in folders:
            return rank
    raise KeyError(f"{module}: the folder {top!r} is in no layer of LAYERS")
