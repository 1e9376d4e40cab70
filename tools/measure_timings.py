"""Measure how long the make targets take into docs/timings.json, and quote its figures in the documents.

docs/timings.json is the one source of every time the README, ``make help``, docs/gallery.md and
docs/validation/timings.md quote. Each entry has a name, its seconds, what was measured, the shell command that
measures it (run from the repository root), the machine and the date; an entry that still carries ``seeded`` was
copied from the documents and awaits a measurement by this tool. A measurement runs the entry's command once and
records its wall time, or, for an entry with ``exr``, that file's ``warpsky/renderSeconds`` once the command has
run; for a pytest run also the number of tests. Entries with the same command are measured from one run.

A document quotes a figure in one of two forms, which ``--apply`` rewrites from the file and ``--check`` (and
tests/test_timings_file.py) compares with it:

- Markdown: ``<!-- timing:NAME -->`` right before the figure, e.g. ``<!-- timing:demo -->1 min 16 s``;
  ``<!-- timing:NAME.tests -->`` quotes the number of tests.
- Makefile: a variable ``TIMING_NAME = figure`` (upper case, ``.`` as ``_``) that a help line uses as
  ``$(TIMING_NAME)``.

Figures are formatted one way: ``8.4 s`` under 10 s, ``76 s`` under 2 minutes, ``4 min 25 s``, ``1 h 5 min``;
``about 3 min`` for a seeded approximate figure. The README and the help lines quote no other time outside code.

Measure on an idle machine: the long entries delete their earlier outputs and run make targets for minutes.

Run:  python tools/measure_timings.py                                 # the entries, their figures and commands
      python tools/measure_timings.py --only demo,demo_render --apply   # measure, write the file, rewrite the docs
      python tools/measure_timings.py --all --apply                   # every entry (the listing's total)
      python tools/measure_timings.py --check                         # exit 1 where a document disagrees
"""

from __future__ import annotations

import argparse
import collections
import datetime
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TIMINGS = ROOT / "docs" / "timings.json"
DOCUMENTS = ("README.md", "docs/gallery.md", "docs/validation/timings.md")  # with markers; README also scanned
MAKEFILE = "Makefile"

FIGURE = r"(?:about )?\d+(?:\.\d+)? (?:h|min|s)(?: \d+ (?:min|s))?|\d+"
MARKER = re.compile(rf"<!-- timing:([\w.]+) -->({FIGURE})")
VARIABLE = re.compile(r"^(TIMING_\w+)([ \t]*=[ \t]*)(.*)$", re.M)
USE = re.compile(r"\$\(TIMING_\w+\)")
DURATION = re.compile(r"\b\d+(?:\.\d+)?(?:\s?[–-]\s?\d+)?\s?(?:s|secs?|seconds?|mins?|minutes?|h|hours?)\b")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def load(path: Path = TIMINGS) -> dict:
    return json.loads(Path(path).read_text())


def save(timings: dict, path: Path = TIMINGS) -> None:
    Path(path).write_text(json.dumps(timings, indent=2, ensure_ascii=False) + "\n")


def duration(seconds: float, approximate: bool = False) -> str:
    """``seconds`` as the documents quote it (see the module's docstring)."""
    if approximate:
        if seconds < 60:
            return f"about {round(seconds)} s"
        minutes = round(seconds / 60)
        hours, minutes = divmod(minutes, 60)
        return f"about {minutes} min" if not hours else f"about {hours} h {minutes} min"
    if seconds < 9.95:
        return f"{seconds:.1f} s"
    whole = round(seconds)
    if whole < 120:
        return f"{whole} s"
    if whole < 3600:
        minutes, rest = divmod(whole, 60)
        return f"{minutes} min {rest} s" if rest else f"{minutes} min"
    hours, minutes = divmod(round(whole / 60), 60)
    return f"{hours} h {minutes} min" if minutes else f"{hours} h"


def figures(timings: dict) -> dict[str, str]:
    """Every quotable figure of ``timings``: ``NAME`` -> its time, ``NAME.tests`` -> its number of tests."""
    out = {}
    for entry in timings["entries"]:
        out[entry["name"]] = duration(entry["seconds"], entry.get("approximate", False))
        if "tests" in entry:
            out[f"{entry['name']}.tests"] = str(entry["tests"])
    return out


def quote(name: str, timings: dict) -> str:
    """The Markdown that quotes figure ``name``: its marker and its figure."""
    return f"<!-- timing:{name} -->{figures(timings)[name]}"


def variable(name: str) -> str:
    """The Makefile variable that holds figure ``name``."""
    return "TIMING_" + name.upper().replace(".", "_")


def rewrite_markdown(text: str, quoted: dict[str, str]) -> tuple[str, list[str]]:
    """``text`` with every marked figure replaced by the file's; what differed (or is unknown), one line each."""
    differences = []

    def replace(match: re.Match) -> str:
        name, old = match.groups()
        if name not in quoted:
            differences.append(f"{name}: no such figure in the timings file")
            return match.group(0)
        if old != quoted[name]:
            differences.append(f"{name}: quotes {old!r}, the timings file {quoted[name]!r}")
        return f"<!-- timing:{name} -->{quoted[name]}"

    return MARKER.sub(replace, text), differences


def rewrite_makefile(text: str, quoted: dict[str, str]) -> tuple[str, list[str]]:
    """``text`` with every ``TIMING_`` variable set to the file's figure; what differed, one line each."""
    by_variable = {variable(name): figure for name, figure in quoted.items()}
    differences = []

    def replace(match: re.Match) -> str:
        name, equals, old = match.groups()
        if name not in by_variable:
            differences.append(f"{name}: no such figure in the timings file")
            return match.group(0)
        if old.strip() != by_variable[name]:
            differences.append(f"{name}: quotes {old.strip()!r}, the timings file {by_variable[name]!r}")
        return f"{name}{equals}{by_variable[name]}"

    return VARIABLE.sub(replace, text), differences


def unmarked(text: str) -> list[str]:
    """The times in Markdown ``text`` that are not marked figures (code blocks, code spans and comments aside)."""
    text = FENCE.sub("", text)
    text = MARKER.sub("", text)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    text = re.sub(r"`[^`\n]*`", "", text)
    return DURATION.findall(text)


def help_lines(makefile: str) -> list[str]:
    """The text of every ``@echo`` line of the Makefile's ``help`` rule, as written (variables not expanded)."""
    recipe = re.search(r"^help:[^\n]*\n((?:\t[^\n]*\n)+)", makefile, re.M)
    return [m.group(1) for m in re.finditer(r'^\t@echo "(.*)"$', recipe.group(1), re.M)] if recipe else []


def check(root: Path = ROOT, timings: dict | None = None) -> list[str]:
    """Where the documents quote a figure other than the timings file's, or a time that is not one of its figures."""
    timings = load(root / "docs" / "timings.json") if timings is None else timings
    quoted = figures(timings)
    problems = []
    for document in DOCUMENTS:
        text = (root / document).read_text()
        problems += [f"{document}: {line}" for line in rewrite_markdown(text, quoted)[1]]
        if not MARKER.search(text):
            problems.append(f"{document}: quotes no figure of the timings file")
    problems += [f"README.md: {t!r} is not a marked figure" for t in unmarked((root / "README.md").read_text())]
    makefile = (root / MAKEFILE).read_text()
    problems += [f"{MAKEFILE}: {line}" for line in rewrite_makefile(makefile, quoted)[1]]
    defined = {m.group(1) for m in VARIABLE.finditer(makefile)}
    for line in help_lines(makefile):
        problems += [f"{MAKEFILE}: help line quotes {t!r}, not a $(TIMING_...) figure: {line.strip()}"
                     for t in DURATION.findall(USE.sub("", line))]
        problems += [f"{MAKEFILE}: help line uses {use}, which is not set" for use in USE.findall(line)
                     if use[2:-1] not in defined]
    return problems


def apply(root: Path = ROOT, timings: dict | None = None) -> list[str]:
    """Rewrite every document's figures from the timings file; the figures that changed."""
    timings = load(root / "docs" / "timings.json") if timings is None else timings
    quoted = figures(timings)
    changed = []
    for document, rewrite in [*((d, rewrite_markdown) for d in DOCUMENTS), (MAKEFILE, rewrite_makefile)]:
        path = root / document
        text, differences = rewrite(path.read_text(), quoted)
        if text != path.read_text():
            path.write_text(text)
        changed += [f"{document}: {line}" for line in differences]
    return changed


def machine_words() -> str:
    """This machine in words, with its load when the measurement starts."""
    gpu = "without a GPU"
    if shutil.which("nvidia-smi"):
        listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True).stdout.strip()
        gpu = f"with {listed.splitlines()[0].split(' (')[0]}" if listed else gpu
    load_average = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{os.cpu_count()}-core {platform.machine()} {platform.system()} CPU {gpu}, "
            f"load average {load_average:.1f} at the start")


def run(command: str, root: Path = ROOT) -> tuple[float, str]:
    """Run ``command`` with bash in ``root``, echoing its output; its wall time and its last lines of output."""
    print(f"measure_timings: {command}", flush=True)
    start = time.perf_counter()
    process = subprocess.Popen(command, shell=True, executable="/bin/bash", cwd=root, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, errors="replace")
    tail = collections.deque(maxlen=40)
    for line in process.stdout:
        sys.stdout.write(line)
        tail.append(line)
    code = process.wait()
    seconds = time.perf_counter() - start
    if code != 0:
        hint = (" (the tests fail where the documents quote other figures than the file: measure with --apply)"
                if "test" in command else "")
        raise SystemExit(f"measure_timings: {command!r} exited {code}; nothing recorded for it{hint}")
    return seconds, "".join(tail)


def test_count(output: str) -> int | None:
    """The number of tests pytest's summary line in ``output`` counts (passed, failed, skipped, xfailed, xpassed)."""
    summary = [line for line in output.splitlines() if re.search(r"\d+ (passed|failed)", line)]
    if not summary:
        return None
    counts = re.findall(r"(\d+) (passed|failed|skipped|xfailed|xpassed)", summary[-1])
    return sum(int(n) for n, _ in counts)


def render_seconds(exr: Path) -> float:
    from warpsky.output.exr import read_exr

    return float(read_exr(str(exr)).header["warpsky/renderSeconds"])


def measure(names: list[str], path: Path = TIMINGS, root: Path = ROOT, apply_each: bool = False) -> None:
    """Measure the entries ``names`` and write each into ``path`` as soon as it is measured; with ``apply_each``
    also rewrite the documents' figures then, so that a later entry running the tests finds them in agreement."""
    timings = load(path)
    entries = {entry["name"]: entry for entry in timings["entries"]}
    unknown = sorted(set(names) - set(entries))
    if unknown:
        raise SystemExit(f"measure_timings: no entry {', '.join(unknown)}; the entries: {', '.join(entries)}")
    runs: dict[str, tuple[float, str, str]] = {}  # command -> wall seconds, output, machine
    for name in names:
        entry = entries[name]
        if entry["command"] not in runs:
            machine = machine_words()
            runs[entry["command"]] = (*run(entry["command"], root), machine)
        seconds, output, machine = runs[entry["command"]]
        if "exr" in entry:
            seconds = render_seconds(root / entry["exr"])
        for key in ("approximate", "seeded", "tests"):
            entry.pop(key, None)
        tests = test_count(output)
        entry.update(seconds=round(seconds, 2), machine=machine, date=datetime.date.today().isoformat())
        if tests is not None:
            entry["tests"] = tests
        save(timings, path)
        print(f"measure_timings: {name} = {duration(entry['seconds'])}", flush=True)
        if apply_each:
            for line in apply(root, timings):
                print(f"measure_timings: {line}", flush=True)


def listing(timings: dict) -> str:
    quoted = figures(timings)
    lines = []
    for entry in timings["entries"]:
        state = "seeded, awaits measurement" if "seeded" in entry else "measured"
        lines.append(f"{entry['name']:<12} {quoted[entry['name']]:<14} {entry['date']}  {state}\n"
                     f"{'':<12} {entry['command']}")
    distinct = {entry["command"]: entry["seconds"] for entry in timings["entries"] if "exr" not in entry}
    lines.append(f"{'all':<12} {duration(sum(distinct.values()), approximate=True)}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--only", default=None, help="comma-separated entry names to measure")
    which.add_argument("--all", action="store_true", help="measure every entry")
    parser.add_argument("--apply", action="store_true", help="rewrite the documents' figures from the file")
    parser.add_argument("--check", action="store_true", help="exit 1 where a document quotes another figure")
    parser.add_argument("--file", type=Path, default=TIMINGS, help="the timings file (default docs/timings.json)")
    args = parser.parse_args(argv)
    if args.only or args.all:
        names = [e["name"] for e in load(args.file)["entries"]] if args.all else args.only.split(",")
        measure(names, args.file, apply_each=args.apply)
    if args.apply:
        for line in apply(ROOT, load(args.file)):
            print(f"measure_timings: {line}")
    if args.check:
        problems = check(ROOT, load(args.file))
        print("\n".join(problems) or "measure_timings: every document quotes the timings file")
        return 1 if problems else 0
    if not (args.only or args.all or args.apply):
        print(listing(load(args.file)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
