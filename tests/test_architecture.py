"""The hallway that runs a frame, checked: no import cycle, imports running down the layers ``docs/architecture.md``
draws, files and functions that stay small, no technique or pass named outside its folder and the registry, and a
new technique and a new pass that plug in through their own modules and one registry line each.

Every import statement counts, those inside functions included (read from the syntax trees, nothing imported).
"""

from __future__ import annotations

import ast
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import StageSpec, run_cli, write_stage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
from import_graph import LAYERS, imports, layer_of, modules  # noqa: E402

#: Longest file [lines] and function [lines]; a longer function must be a kernel that is one loop carrying state
#: and say so in its docstring.
MAX_FILE_LINES = 500
MAX_FUNCTION_LINES = 80
ONE_LOOP = "one loop carrying state"


def test_no_import_cycle():
    found = modules()
    edges = imports(found)
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        stack.append(module)
        for target in sorted(edges[module]):
            if state.get(target) == 1:
                return stack[stack.index(target):] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        stack.pop()
        state[module] = 2
        return None

    for module in sorted(found):
        if module not in state:
            cycle = visit(module)
            assert cycle is None, "import cycle: " + " -> ".join(cycle)
    print(f"\n{len(found)} modules, {sum(len(t) for t in edges.values())} imports, no cycle")


def test_imports_run_down_the_layers():
    edges = imports(modules())
    upward = [f"{a} ({LAYERS[layer_of(a)][0]}) -> {b} ({LAYERS[layer_of(b)][0]})"
              for a in sorted(edges) for b in sorted(edges[a]) if layer_of(b) > layer_of(a)]
    assert not upward, "imports running up the layers:\n" + "\n".join(upward)


def test_every_folder_is_a_layer_and_no_two_files_of_a_layer_share_a_name():
    """A module's layer is its top folder's (no module-by-module exceptions), and within a layer a file's name says
    which file it is: no two ``kernels.py`` or ``technique.py`` to tell apart by their folder."""
    names: dict[tuple[int, str], list[str]] = {}
    for module, path in modules().items():
        rank = layer_of(module)  # raises for a folder in no layer
        if path.name != "__init__.py":
            names.setdefault((rank, path.name), []).append(module)
    shared = {name: found for (_, name), found in names.items() if len(found) > 1}
    assert not shared, shared


def test_files_and_functions_stay_small():
    long_files, long_functions = [], []
    for module, path in sorted(modules().items()):
        text = path.read_text()
        if len(text.splitlines()) > MAX_FILE_LINES:
            long_files.append(f"{module}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES and ONE_LOOP not in (ast.get_docstring(node) or ""):
                    long_functions.append(f"{module}.{node.name}: {length} lines")
    assert not long_files, long_files
    assert not long_functions, long_functions


def _string_constants(path: Path) -> set[str]:
    """The string constants of a module that are not docstrings."""
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)) and node.body
                  and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings}


#: The modules that run a frame around the techniques and passes: they must not name any of them.
HALLWAY = ("warpsky.render", "warpsky.batch", "warpsky.cli", "warpsky.api", "warpsky.passes.composite",
           "warpsky.passes.frame", "warpsky.passes.render_pass")


def test_no_technique_or_pass_is_named_outside_its_folder_and_the_registry():
    """No module but a technique's own (and the registry, and the evaluation code that compares techniques by name
    as a user would) names a technique; the modules that run a frame name no pass either: they read names and
    capabilities from the registered classes."""
    from warpsky.render.registry import pass_classes, technique_classes

    techniques = {cls.name for cls in technique_classes()}
    passes = {cls.name for cls in pass_classes()}
    named = []
    for module, path in sorted(modules().items()):
        if module in ("warpsky.render.registry",) or module.startswith(("warpsky.techniques", "evaluation")):
            continue
        hallway = module in HALLWAY or module.startswith(tuple(prefix + "." for prefix in HALLWAY))
        for name in sorted(_string_constants(path) & (techniques | (passes if hallway else set()))):
            named.append(f"{module} names {name!r}")
    assert not named, named


PLUGIN = '''
"""A technique and a pass that live outside warpsky, plugged in by one registry line each."""

from dataclasses import dataclass

import numpy as np

from warpsky.core.image import ImageLayer
from warpsky.passes.render_pass import Pass
from warpsky.core.resources import MemoryEstimate
from warpsky.core.settings import Settings, documented, setting
from warpsky.techniques.technique import Technique


@documented
@dataclass(frozen=True)
class GlowSettings(Settings):
    """Settings of the glow technique."""

    owner = "glow"
    level: float = setting(0.25, range="> 0", help="radiance of every pixel")


class Glow(Technique):
    """Every pixel glows at ``level`` through half transmittance, 1 km away."""

    name = "glow"
    Settings = GlowSettings
    aovs = {"glow": "RGB"}
    settings_notes = "A technique made for the plug-in test."

    def memory_estimate(self, scene, width, height):
        return MemoryEstimate().add("glow", host=width * height * 28)

    def render(self, scene, width, height):
        level = self.settings_for(scene).level
        radiance = np.full((height, width, 3), level, np.float32)
        return ImageLayer(radiance, np.full((height, width, 3), 0.5, np.float32),
                          np.full((height, width), 1000.0, np.float32), aovs={"glow": radiance},
                          warnings=["glow: made up"])


@documented
@dataclass(frozen=True)
class VeilSettings(Settings):
    """Settings of the veil pass."""

    owner = "veil"
    prefix = "veil."
    opacity: float = setting(0.2, range="[0, 1]", help="share of the light behind the veil it stops")


class VeilPass(Pass):
    """A grey veil 1 m in front of the camera."""

    name = "veil"
    Settings = VeilSettings

    @classmethod
    def runs(cls, scene, technique):
        return True

    @classmethod
    def describe(cls, scene, technique, settings):
        return {"veil": f"opacity {settings.opacity:g}"}

    def render(self, frame):
        shape = (frame.height, frame.width)
        opacity = self.settings.opacity
        return [ImageLayer(np.full((*shape, 3), opacity, np.float32), np.full((*shape, 3), 1.0 - opacity, np.float32),
                           np.full(shape, 1.0, np.float32))]
'''


def test_a_new_technique_and_a_new_pass_plug_in_through_the_registry(tmp_path, homogeneous_npy, capsys,
                                                                     monkeypatch):
    """Both are written outside the package; registering them is all it takes for ``--technique``, ``--set``,
    ``render --help-settings``, ``warpsky info``, the frame, the EXR's channels and metadata and the warnings."""
    from warpsky.output.exr import read_exr
    from warpsky.render import registry

    (tmp_path / "toy_plugin.py").write_text(textwrap.dedent(PLUGIN))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(registry.TECHNIQUES, "glow", "toy_plugin:Glow")
    monkeypatch.setattr(registry, "PASSES", (*registry.PASSES, "toy_plugin:VeilPass"))
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))

    with pytest.raises(SystemExit):
        run_cli(["render", "--help-settings", "all"], capsys)
    help_text = capsys.readouterr().out
    assert "glow:" in help_text and "radiance of every pixel" in help_text and "veil.opacity" in help_text
    code, out, err = run_cli(["info", stage, "--technique", "glow", "--set", "veil.opacity=0.5",
                              "--set", "level=2"], capsys)
    assert code == 0, err
    assert "technique   glow" in out and "level=2" in out and "veil.opacity=0.5" in out
    assert "passes      media -> veil -> composite" in out and "veil        opacity 0.5" in out

    out_path = tmp_path / "glow.exr"
    code, _, err = run_cli(["render", stage, out_path, "--technique", "glow", "--res", "4", "--float",
                            "--set", "veil.opacity=0.5", "--set", "level=2"], capsys)
    assert code == 0, err
    assert "glow: made up" in err
    image = read_exr(out_path)
    rgb = image.rgba()[..., :3]
    np.testing.assert_allclose(rgb, 0.5 + 0.5 * 2.0, rtol=1e-6)  # the veil in front, the glow behind it
    assert "glow.R" in image.channels and '"veil": {"opacity": 0.5}' in image.metadata["settings"]
    assert "glow: made up" in image.metadata["warnings"]


#: What the commands that render and inspect a stage must not load: the evaluation code beside the package, the
#: peers and tools only benchmarks, previews and farms use.
NOT_LOADED = ("evaluation", "mitsuba", "drjit", "dask", "distributed", "pyvista", "vtk", "matplotlib")


def _imported(args: list[str]) -> set[str]:
    """Every module ``python -X importtime -m warpsky ARGS`` imports (read from its import-time log)."""
    import subprocess

    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "warpsky", *args], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return {line.rsplit("|", 1)[1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")
            and "|" in line}


def test_render_help_and_info_load_no_evaluation_code_or_peer(tmp_path, homogeneous_npy):
    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))
    for args in (["render", "--help"], ["info", str(stage)]):
        names = _imported(args)
        assert "warpsky.cli.main" in names
        loaded = sorted(n for n in names if n.split(".")[0] in NOT_LOADED)
        assert not loaded, f"warpsky {' '.join(args)} imports {loaded}"


#: What printing help must not load: Warp (about 0.4 s), USD and OpenEXR, so that ``warpsky --help`` answers at once.
HEAVY = ("warp", "pxr", "OpenEXR")


def test_help_loads_neither_warp_nor_usd():
    for args in (["--help"], ["render", "--help"], ["info", "--help"]):
        loaded = sorted(n for n in _imported(args) if n.split(".")[0] in HEAVY)
        assert not loaded, f"warpsky {' '.join(args)} imports {loaded}"


def test_warp_is_configured_when_first_imported_after_warpsky():
    """Importing warpsky leaves Warp unimported; Warp, imported later, comes without adjoint code generation."""
    import subprocess

    code = "import sys, warpsky; print('warp' in sys.modules); import warp; print(warp.config.enable_backward)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["False", "False"]


def test_a_render_loads_only_its_own_technique(tmp_path, homogeneous_npy):
    """A frame imports its technique's modules and no other technique's (each defines its kernels on import); the
    AOVs of every technique load only for a stage whose RenderProducts ask."""
    from warpsky.render.registry import TECHNIQUES

    stage = write_stage(tmp_path / "s.usda", StageSpec(volume_file=homogeneous_npy))
    own = TECHNIQUES["single_scatter"].split(":")[0].rsplit(".", 1)[0]
    args = ["render", str(stage), str(tmp_path / "o.exr"), "--technique", "single_scatter", "--res", "4"]
    others = sorted({n.rsplit(".", 1)[0] for n in _imported(args) if n.startswith("warpsky.techniques.")
                     and n.count(".") >= 3 and not n.startswith(own)})
    assert not others, f"a single_scatter render imports {others}"
