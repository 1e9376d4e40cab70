"""The documents' USD snippets are valid USD: each ```usda block of the README and the user guide parses as a
layer, and its render settings read."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]


def usda_blocks() -> list[str]:
    return [block for path in DOCUMENTS for block in re.findall(r"```usda\n(.*?)```", path.read_text(), flags=re.S)]


def test_usda_snippets_parse_and_their_vars_read():
    from pxr import Sdf, Usd, UsdRender

    blocks = usda_blocks()
    assert blocks
    for block in blocks:
        layer = Sdf.Layer.CreateAnonymous(".usda")
        assert layer.ImportFromString("#usda 1.0\n" + block), block[:200]
        stage = Usd.Stage.Open(layer)
        for prim in stage.Traverse():
            if prim.IsA(UsdRender.Var):
                var = UsdRender.Var(prim)
                assert var.GetSourceNameAttr().Get() and var.GetDataTypeAttr().Get(), prim.GetPath()
