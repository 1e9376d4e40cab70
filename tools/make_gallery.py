"""Render the hero frame of every shipped stage and of the simulated storm; write docs/gallery.md with them.

Each shot is one ``warpsky render`` command (the default technique unless the stage needs another, said in the
shot's note), run as a subprocess as a user would run it. The EXR goes to ``out/gallery/``, its PNG preview (the
default OpenColorIO view, exposure from the frame's luminance) to ``docs/gallery/``; under each picture the page
gives the exact command, the technique, the render's own time and error estimate from the EXR header
(``warpsky/renderSeconds``, ``warpsky/errorEstimate``: the hybrid and path tracer's estimated relative RMS error;
deterministic techniques have none), and the wall time of the whole command (stage load, first compiles and table
builds included unless cached). Those are this run's own figures; under the demo's picture the page also quotes the
demo's times from docs/timings.json, the figures the README and ``make help`` quote (tools/measure_timings.py).

Run:  make gallery   (builds the sample data the stages read, then this)
      python tools/make_gallery.py [--only cumulus,storm] [--out docs] [--renders out/gallery]
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


@dataclass(frozen=True)
class Shot:
    """One stage's hero frame: ``args`` follow ``warpsky render STAGE OUT``; ``note`` says what it shows and why a
    technique other than the default was chosen."""

    name: str
    stage: str
    frame: int
    args: tuple[str, ...]
    note: str


#: The simulated storm's stage (``make simulate-storm`` writes it; ``make gallery`` runs that first).
SIMULATED = "out/simulate/storm.usda"

SHOTS = (
    Shot("cumulus", "cumulus.usda", 1, (), "The demo (`make demo`): a detailed cumulus congestus, the sun 35° up to "
         "the left, its shadow on the ground. Default technique (hybrid)."),
    Shot("cumulus_wind", "cumulus_wind.usda", 24, ("--res", "384"), "The demo cloud drifting in the wind with "
         "advected detail (`make cumulus-wind`, frame 24 of 48)."),
    Shot("storm_simulated", SIMULATED, 40, ("--res", "384", "--time-budget", "60", "--exposure", "0.5"),
         "The storm grown by the cloud solver (`make simulate-storm`), frame 40 (33 minutes) from its rainbow "
         "shot: the rain shaft under the base with the primary bow, the tower rising into the ice anvil overhead. "
         "Default technique under a 60 s budget: a storm frame's multiple scattering costs minutes on a CPU, so "
         "its estimate is above 5 %. Exposure 0.5 (a white surface facing the sun at 1.4): the frame's own "
         "exposure lifts the shaded anvil and base to pale grey."),
    Shot("storm_simulated_side", SIMULATED, 40, ("--res", "384", "--time-budget", "60", "--exposure", "0.5",
                                                 "--camera", "/World/StormCam"),
         "The same frame from 30 km south (`/World/StormCam`, which follows the storm): the base, the tower and "
         "the anvil spreading downwind at the tropopause. Default technique under a 60 s budget, exposure 0.5."),
    Shot("storm", "storm.usda", 40, ("--res", "384", "--technique", "slicing"), "The procedural cumulonimbus "
         "time-lapse (`make storm-procedural`), RainbowCam frame 40. Slicing, as `make storm-procedural` renders "
         "it: hybrid takes minutes per frame on a CPU here, and slicing is darker than the path tracer in clouds "
         "this thick."),
    Shot("storm_anvil", "storm.usda", 46, ("--res", "384", "--technique", "slicing", "--camera", "/World/AnvilCam"),
         "The same storm from the AnvilCam, frame 46: the ice anvil spreading downwind. Slicing, as above."),
    Shot("stratocumulus", "stratocumulus.usda", 1, ("--res", "384"), "A stratocumulus deck over water, sand and "
         "snow with the ground-cloud radiosity of Bouthors et al. 2006 (`make stratocumulus`)."),
    Shot("stratocumulus_anim", "stratocumulus_anim.usda", 24, ("--res", "384"), "The deck's advected sequence "
         "(Neyret's textures), frame 24 of 48 (`make stratocumulus-anim`)."),
    Shot("sunrise", "sunrise.usda", 6, ("--res", "384"), "Sunrise over the demo cloud, frame 6 of 24: the sun just "
         "above the horizon, reddened by the air."),
    Shot("valley_fog", "valley_fog.usda", 1, ("--res", "384"), "Morning fog in a valley (Biri et al. 2002's "
         "analytic fog over a terrain mesh, `make valley-fog`)."),
    Shot("sunbeams", "sunbeams.usda", 1, ("--res", "384"), "Sunbeams through a height-field cloud deck lighting the "
         "haze over hills and a lake (Max 1986, `make sunbeams`)."),
    Shot("sundogs", "sundogs.usda", 1, ("--res", "768x512", "--technique", "single_scatter"), "Oriented ice: "
         "parhelia, the 22° halo, tangent and circumzenithal arcs (`make sundogs`). Single scattering: the sheet "
         "is thin and the halos are sunlight scattered once."),
)


def command(shot: Shot, exr: Path) -> list[str]:
    """The ``warpsky render`` command line of ``shot`` writing ``exr`` (with ``####`` for the frame)."""
    stage = shot.stage if "/" in shot.stage else f"usd_scenes/{shot.stage}"
    return ["warpsky", "render", stage, str(exr), "--frames", str(shot.frame), "--png",
            "--overwrite", *shot.args]


def frame_path(pattern: Path, frame: int) -> Path:
    return pattern.with_name(pattern.name.replace("####", f"{frame:04d}"))


def render(shot: Shot, out_dir: Path) -> dict:
    """Render ``shot`` into ``out_dir``; the figures the page shows."""
    from warpsky.output.exr import read_exr

    pattern = out_dir / shot.name / f"{shot.name}.####.exr"
    argv = command(shot, pattern.relative_to(ROOT) if pattern.is_relative_to(ROOT) else pattern)
    executable = str(Path(sys.executable).with_name("warpsky"))
    start = time.perf_counter()
    done = subprocess.run([executable, *argv[1:]], cwd=ROOT)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"make_gallery: {shot.name}: warpsky render exited {done.returncode}")
    exr = frame_path(pattern, shot.frame)
    header = read_exr(str(exr)).header
    return {"name": shot.name, "command": shlex.join(argv), "exr": exr, "png": exr.with_suffix(".png"),
            "technique": header.get("warpsky/technique", "?"), "seconds": header.get("warpsky/renderSeconds"),
            "error": header.get("warpsky/errorEstimate"), "spp": header.get("warpsky/spp"), "wall": wall,
            "note": shot.note}


def figures_line(record: dict) -> str:
    """One line of the page under a picture: technique, times, error estimate."""
    parts = [f"`{record['technique']}`"]
    if record.get("seconds") is not None:
        parts.append(f"render {float(record['seconds']):.1f} s")
    parts.append(f"command {record['wall']:.1f} s wall")
    if record.get("spp") is not None:
        parts.append(f"{int(record['spp'])} paths per pixel")
    if record.get("error") is not None:
        parts.append(f"estimated error {100.0 * float(record['error']):.1f} % (relative RMS)")
    else:
        parts.append("no error estimate (nothing in the frame is path-traced: the technique's passes are "
                     "deterministic)")
    return ", ".join(parts)


def demo_line() -> str:
    """Under the demo's picture: the demo's times as docs/timings.json has them, marked as tools/measure_timings.py
    quotes a figure (``--apply`` rewrites them when the file is re-measured)."""
    sys.path.insert(0, str(ROOT / "tools"))
    from measure_timings import load, quote

    timings = load()
    return (f"`make demo` renders this frame in {quote('demo_render', timings)} ({quote('demo', timings)} for the "
            "whole command) by [the measured timings](timings.json) that the README and `make help` quote; the "
            "figures above are this gallery run's own.")


def page(records: list[dict], *, machine: str) -> str:
    """docs/gallery.md for ``records`` (their PNGs already copied to ``gallery/<name>.png``)."""
    lines = ["# Gallery", "",
             "Every shipped stage's hero frame, rendered by `make gallery` (`tools/make_gallery.py`) on "
             f"{machine}. The pictures are the PNG previews warpsky writes next to each EXR (OpenColorIO's ACES 2.0 "
             "SDR view, exposure from the frame's 99.5th-percentile luminance unless the command sets one); the "
             "EXRs stay scene-linear in `out/gallery/`. Times are the EXR header's render time and the whole "
             "command's wall time (stage "
             "load and Warp's kernel cache included; the first run on a machine also compiles kernels and builds "
             "optics tables).", ""]
    for record in records:
        lines += [f"## {record['name']}", "", f"![{record['name']}](gallery/{record['name']}.png)", "",
                  record["note"], "", "```sh", record["command"], "```", "", figures_line(record), ""]
        if record["name"] == "cumulus":
            lines += [demo_line(), ""]
    return "\n".join(lines)


def machine_words() -> str:
    import os
    import platform

    return f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPU cores, Warp on the CPU"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default=None, help="comma-separated shot names (default: all); the others keep "
                        "the figures of their last render (gallery/figures.json)")
    parser.add_argument("--page-only", action="store_true", help="write gallery.md from gallery/figures.json "
                        "without rendering")
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="where gallery.md and gallery/ go")
    parser.add_argument("--renders", type=Path, default=ROOT / "out" / "gallery", help="where the EXRs go")
    args = parser.parse_args(argv)
    names = {s.name for s in SHOTS}
    chosen = set() if args.page_only else names if args.only is None else set(args.only.split(","))
    unknown = sorted(chosen - names)
    if unknown:
        parser.error(f"--only: unknown shot {', '.join(unknown)}; expected some of {', '.join(sorted(names))}")
    gallery = args.out / "gallery"
    figures = gallery / "figures.json"
    kept = json.loads(figures.read_text()) if figures.exists() else {}
    for shot in SHOTS:
        if shot.name in chosen:
            print(f"make_gallery: {shot.name}", flush=True)
            record = render(shot, args.renders.resolve())
            gallery.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(record.pop("png"), gallery / f"{shot.name}.png")
            record.pop("exr")
            kept[shot.name] = record
    records = [kept[s.name] | {"note": s.note} for s in SHOTS if s.name in kept]  # notes as this file has them
    figures.write_text(json.dumps(kept, indent=1) + "\n")
    (args.out / "gallery.md").write_text(page(records, machine=machine_words()))
    print(args.out / "gallery.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
