"""The README's USD snippets are valid USD: each ```usda block parses as a layer, and its render settings read."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def usda_blocks() -> list[str]:
    return re.findall(r"```usda\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_usda_snippets_parse_and_their_vars_read():
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
