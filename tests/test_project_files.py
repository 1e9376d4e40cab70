"""The project's own files: ``make help`` lists every target, ``make test-fast`` leaves out the slow tests,
pyproject's license is an SPDX string, and the gallery shows every shipped stage (the times the README and
``make help`` quote: test_timings_file.py)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _makefile() -> str:
    return (ROOT / "Makefile").read_text().replace("\\\n", " ")  # continuation lines joined


def test_make_help_lists_every_target():
    text = _makefile()
    phony = set(re.search(r"^\.PHONY:(.*)$", text, re.M).group(1).split())
    rules = {m.group(1) for m in re.finditer(r"^([A-Za-z][\w.-]*)\s*:(?!=)", text, re.M)}
    assert rules == phony, "every plain-named rule is .PHONY and every .PHONY target has a rule"
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    out = subprocess.run(["make", "-s", "-C", str(ROOT), "help"], capture_output=True, text=True, check=True).stdout
    listed = {line.split()[1] for line in out.splitlines() if line.startswith("make ")}
    assert listed == phony


def test_make_test_fast_leaves_out_the_slow_tests():
    recipe = re.search(r"^test-fast:.*\n\t(.*)$", _makefile(), re.M).group(1)
    assert "pytest" in recipe and re.search(r"-m ['\"]not slow['\"]", recipe)
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert any(m.startswith("slow:") for m in config["tool"]["pytest"]["ini_options"]["markers"])


def test_license_is_an_spdx_string():
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert config["project"]["license"] == "Apache-2.0"  # the table form is deprecated by setuptools
    setuptools = [r for r in config["build-system"]["requires"] if r.startswith("setuptools")]
    assert setuptools and int(re.search(r">=\s*(\d+)", setuptools[0]).group(1)) >= 77  # first with SPDX strings
    for path in config["project"].get("license-files", []):
        assert list(ROOT.glob(path)), path


def test_the_gallery_has_a_shot_of_every_shipped_stage_and_shows_each():
    """tools/make_gallery.py renders every stage in usd_scenes/ (a new stage cannot be left out of it) and the
    simulated storm's, and docs/gallery.md shows a picture and the command of every shot, with the figures its last
    render recorded."""
    import json
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    from make_gallery import SHOTS, SIMULATED, command

    shipped = {p.name for p in (ROOT / "usd_scenes").glob("*.usda")}
    assert {s.stage for s in SHOTS} == shipped | {SIMULATED}
    assert len({s.name for s in SHOTS}) == len(SHOTS)
    page = (ROOT / "docs" / "gallery.md").read_text()
    figures = json.loads((ROOT / "docs" / "gallery" / "figures.json").read_text())
    for shot in SHOTS:
        assert (ROOT / "docs" / "gallery" / f"{shot.name}.png").is_file(), shot.name
        assert f"](gallery/{shot.name}.png)" in page, shot.name
        assert figures[shot.name]["command"].split()[:3] == command(shot, Path("x"))[:3]
        assert figures[shot.name]["command"] in page
        assert f"render {float(figures[shot.name]['seconds']):.1f} s" in page
