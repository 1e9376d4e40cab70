"""Every shipped stage loads from a fresh checkout after ``make data``, and before it a missing data file's error
names the command that makes it.

The table of generated files (:data:`warpsky.usd.generated_data.GENERATED`) covers every file a stage in
``usd_scenes/`` references under ``data/``, and its commands are the ones ``make data`` runs.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path, PurePosixPath

import pytest
from conftest import run_cli

from warpsky.usd.generated_data import GENERATED, generating_command, missing_file_hint

ROOT = Path(__file__).resolve().parent.parent
STAGES = sorted((ROOT / "usd_scenes").glob("*.usda"))


def _makefile() -> str:
    return (ROOT / "Makefile").read_text().replace("\\\n", " ")  # continuation lines joined


def _checkout(tmp_path: Path, *scripts: str) -> Path:
    """A copy of the shipped stages and the named tools/ scripts (all of them: none named) in ``tmp_path``."""
    shutil.copytree(ROOT / "usd_scenes", tmp_path / "usd_scenes")
    (tmp_path / "tools").mkdir()
    for script in scripts or [p.name for p in (ROOT / "tools").glob("*.py")]:
        shutil.copy(ROOT / "tools" / script, tmp_path / "tools")
    return tmp_path


def test_every_data_file_a_shipped_stage_references_has_its_command():
    referenced = {match for stage in STAGES for match in re.findall(r"@\.\./(data/[^@]+)@", stage.read_text())}
    assert referenced
    for path in sorted(referenced):
        assert any(PurePosixPath(path).match(pattern) for pattern, _, _ in GENERATED), path
        assert generating_command(ROOT / path) is not None, path


def test_make_data_runs_every_command_of_the_table():
    text = _makefile()
    prerequisites = re.search(r"^DATA\s*=(.*)$", text, re.M).group(1).split()
    assert re.search(r"^data:\s*\$\(DATA\)", text, re.M)
    for _, script, command in GENERATED:
        assert (ROOT / script).is_file(), script
        assert command.startswith("python ")
        recipe = "$(PY) " + command.removeprefix("python ")
        rule = re.search(rf"^(\S+):[^\n]*\n(?:\t[^\n]*\n)*?\t{re.escape(recipe)}$", text, re.M)
        assert rule is not None, f"no rule runs {recipe}"
        assert rule.group(1) in prerequisites, rule.group(1)


@pytest.mark.parametrize("stage, script, culprit", [
    ("storm.usda", "make_storm.py", "'../data/storm/cloud.0001.nvdb' not found"),
    ("stratocumulus.usda", "make_stratocumulus.py", "'../data/stratocumulus/ground_albedo.npy' not found"),
    ("sunbeams.usda", "make_terrain.py", "terrain.usda"),
])
def test_a_missing_data_file_names_the_command_that_makes_it(tmp_path, capsys, monkeypatch, stage, script,
                                                             culprit):
    checkout = _checkout(tmp_path / "clone", script)
    command = next(c for _, s, c in GENERATED if s == f"tools/{script}")
    monkeypatch.chdir(checkout)
    code, out, err = run_cli(["info", f"usd_scenes/{stage}"], capsys)
    assert code == 2 and out == ""
    line = err.strip().splitlines()[-1]  # USD prints its own warning first for a missing reference
    assert culprit in line and line.endswith(f"; run `make data` (or `{command}`) to generate it"), line
    monkeypatch.chdir(tmp_path)  # elsewhere: the message says where to run it
    code, _, err = run_cli(["info", checkout / "usd_scenes" / stage], capsys)
    assert code == 2 and f"(or `{command}`) in {checkout} to generate it" in err.strip().splitlines()[-1]


def test_no_command_is_named_for_a_file_outside_a_checkout(tmp_path):
    assert missing_file_hint(tmp_path / "data" / "storm" / "cloud.0001.nvdb") == ""  # no tools/make_storm.py there
    assert missing_file_hint(ROOT / "data" / "elsewhere.nvdb") == ""
    assert "make_storm.py" in missing_file_hint(ROOT / "data" / "storm" / "cloud.0007.nvdb")


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_every_shipped_stage_loads_after_make_data(tmp_path, capsys):
    """A copy of the checkout's stages, tools and Makefile without data/: ``make data`` (the venv taken as
    installed) prints a line per step, then ``warpsky info`` reads every stage; the stages it regenerates are
    unchanged."""
    checkout = _checkout(tmp_path)
    shutil.copy(ROOT / "Makefile", checkout)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # tools/make_cumulus.py imports the evaluation package
    done = subprocess.run(["make", "-C", str(checkout), "data", f"PY={sys.executable}", "STAMP="], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    steps = [line for line in done.stdout.splitlines() if line.startswith("make data: ")]
    assert len(steps) == len(GENERATED) + 1, done.stdout
    for stage in STAGES:
        assert (checkout / "usd_scenes" / stage.name).read_text() == stage.read_text(), stage.name
        code, out, err = run_cli(["info", checkout / "usd_scenes" / stage.name], capsys)
        assert code == 0, f"{stage.name}: {err}"
        assert "not found" not in err, err
