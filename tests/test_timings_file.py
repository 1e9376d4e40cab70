"""docs/timings.json is the one source of the times the documents quote: the README, ``make help``, the gallery and
docs/validation/timings.md quote exactly its figures, formatted as tools/measure_timings.py formats them, and the
README and the help lines quote no other time; the tool rewrites stale figures and measures an entry's command."""

from __future__ import annotations

import datetime
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))

import measure_timings as timings_tool  # noqa: E402  (tools/ is not a package)


def _quickstart() -> str:
    readme = (ROOT / "README.md").read_text()
    start = readme.index("## Quickstart")
    return readme[start: readme.index("\n## ", start + 1)]


def test_every_entry_says_what_was_measured_how_where_and_when():
    entries = timings_tool.load()["entries"]
    names = [entry["name"] for entry in entries]
    assert len(names) == len(set(names))
    for entry in entries:
        assert re.fullmatch(r"[a-z][a-z0-9_]*", entry["name"]), entry["name"]
        assert isinstance(entry["seconds"], (int, float)) and entry["seconds"] > 0, entry["name"]
        for key in ("measured", "command", "machine"):
            assert isinstance(entry.get(key), str) and entry[key].strip(), (entry["name"], key)
        datetime.date.fromisoformat(entry["date"])
    variables = [timings_tool.variable(name) for name in timings_tool.figures(timings_tool.load())]
    assert len(variables) == len(set(variables)), "two figures would share a Makefile variable"


def test_the_documents_quote_the_files_figures():
    assert timings_tool.check() == []


def test_the_quickstart_and_the_gallery_quote_the_demo_from_the_file():
    timings = timings_tool.load()
    quickstart = _quickstart()
    for name in ("demo", "demo_render", "demo_cold", "test", "test.tests", "test_fast", "storm"):
        assert timings_tool.quote(name, timings) in quickstart, name
    gallery = (ROOT / "docs" / "gallery.md").read_text()
    demo = gallery[gallery.index("## cumulus\n"): gallery.index("\n## ", gallery.index("## cumulus\n") + 1)]
    assert timings_tool.quote("demo", timings) in demo and timings_tool.quote("demo_render", timings) in demo
    from make_gallery import demo_line

    assert demo_line() in gallery, "docs/gallery.md is what tools/make_gallery.py writes (--page-only)"


def test_make_help_prints_the_files_figures():
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    makefile = (ROOT / "Makefile").read_text()
    by_variable = {timings_tool.variable(name): figure
                   for name, figure in timings_tool.figures(timings_tool.load()).items()}
    written = timings_tool.help_lines(makefile)
    printed = subprocess.run(["make", "-s", "-C", str(ROOT), "help"], capture_output=True, text=True,
                             check=True).stdout.splitlines()
    assert len(written) == len(printed)
    quoted = set()
    for source, shown in zip(written, printed, strict=True):
        pattern = ""
        for piece in re.split(r"(\$\([\w]+\))", source):
            name = piece[2:-1] if piece.startswith("$(") else None
            if name in by_variable:
                quoted.add(name)
            pattern += re.escape(by_variable[name]) if name in by_variable else ".*?" if name else re.escape(piece)
        assert re.fullmatch(pattern, shown), (source, shown)
    for name in ("demo", "demo_cold", "data", "test", "test_fast", "storm", "valley_fog", "sunbeams", "gallery"):
        assert timings_tool.variable(name) in quoted, name


def _copy_of_the_documents(tmp_path: Path) -> Path:
    for document in (*timings_tool.DOCUMENTS, timings_tool.MAKEFILE, "docs/timings.json"):
        (tmp_path / document).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / document, tmp_path / document)
    return tmp_path


def test_a_stale_figure_is_found_and_apply_rewrites_it(tmp_path):
    root = _copy_of_the_documents(tmp_path)
    timings = timings_tool.load(root / "docs" / "timings.json")
    demo = timings_tool.quote("demo", timings)
    readme = root / "README.md"
    readme.write_text(readme.read_text().replace(demo, "<!-- timing:demo -->50 s", 1)
                      + "\nThe storm takes about 12 minutes.\n")
    makefile = root / "Makefile"
    makefile.write_text(re.sub(r"^TIMING_TEST( *)= .*$", r"TIMING_TEST\1= 8 min", makefile.read_text(), flags=re.M))
    problems = timings_tool.check(root)
    assert any("README.md: demo: quotes '50 s'" in p for p in problems), problems
    assert any("'12 minutes' is not a marked figure" in p for p in problems), problems
    assert any("Makefile: TIMING_TEST: quotes '8 min'" in p for p in problems), problems
    timings["entries"][0]["seconds"] = 81.4
    (root / "docs" / "timings.json").write_text(json.dumps(timings))
    timings_tool.apply(root)
    assert "<!-- timing:demo -->81 s" in readme.read_text()
    assert [p for p in timings_tool.check(root) if "12 minutes" not in p] == []


def test_figures_are_formatted_one_way():
    duration = timings_tool.duration
    assert [duration(s) for s in (0.43, 9.94, 9.96, 76, 119.4, 265, 612, 600, 3900)] == [
        "0.4 s", "9.9 s", "10 s", "76 s", "119 s", "4 min 25 s", "10 min 12 s", "10 min", "1 h 5 min"]
    assert [duration(s, approximate=True) for s in (10, 180, 420, 4200)] == [
        "about 10 s", "about 3 min", "about 7 min", "about 1 h 10 min"]
    for text in ("0.4 s", "76 s", "4 min 25 s", "1 h 5 min", "about 3 min", "899"):
        assert re.fullmatch(timings_tool.FIGURE, text), text


def test_measuring_runs_the_command_and_records_it(tmp_path):
    path = tmp_path / "timings.json"
    path.write_text(json.dumps({"entries": [
        {"name": "quick", "seconds": 5.0, "approximate": True, "measured": "a shell command", "tests": 1,
         "command": "echo '3 passed, 2 skipped, 9 deselected in 0.01s'", "machine": "?", "date": "2000-01-01",
         "seeded": "by hand"}]}))
    timings_tool.measure(["quick"], path, root=tmp_path)
    entry = json.loads(path.read_text())["entries"][0]
    assert "seeded" not in entry and "approximate" not in entry
    assert 0 <= entry["seconds"] < 5 and entry["tests"] == 5
    assert entry["date"] == datetime.date.today().isoformat() and "CPU" in entry["machine"]
    path.write_text(path.read_text().replace("echo ", "false && echo "))
    with pytest.raises(SystemExit):
        timings_tool.measure(["quick"], path, root=tmp_path)
