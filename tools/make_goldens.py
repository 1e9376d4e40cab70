"""Golden images: the shipped stages rendered small by every technique, kept under tests/golden/ as .npz.

``tests/test_golden.py`` renders the same cases and compares them with these files (1e-6 relative), so a refactor
that is meant to leave every image unchanged proves it. The inputs are written here at low resolution from the
same generators the stages use (demo cumulus, storm frame 40, stratocumulus, sunrise frame 12), so a golden does
not depend on ``data/``. Regenerate only when a change is meant to alter pixels, and say why in the commit:

    python tools/make_goldens.py            # writes tests/golden/<stage>-<technique>.npz
    python tools/make_goldens.py --check    # renders and prints the largest relative difference, writes nothing
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "golden"
sys.path.insert(0, str(ROOT / "tools"))

#: Image width of every golden [px]; the height follows the stage camera's aspect ratio.
WIDTH = 32
#: Path tracer settings of the goldens: few samples, fixed seed (the image is noisy but exactly reproducible).
PATH_TRACER = ("spp=4", "seed=3")
#: Hybrid settings of the goldens: 4 multiple-scattering paths, no denoiser (Open Image Denoise's output depends on
#: the processor's instruction set, the Warp kernels' does not).
HYBRID = ("spp=4", "seed=3", "target_error=0", "denoise=0")


@dataclass(frozen=True)
class Case:
    stage: str  # name of the stage (cumulus, storm, stratocumulus, sunrise)
    technique: str
    time: float
    settings: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return f"{self.stage}-{self.technique}"


def _cases() -> list[Case]:
    cases = []
    for stage, time in (("cumulus", 1), ("storm", 40), ("stratocumulus", 1), ("sunrise", 12)):
        for technique in ("single_scatter", "slicing", "path_tracer", "hybrid"):
            if stage == "stratocumulus" and technique in ("path_tracer", "hybrid"):
                continue  # the path tracer does not render stratiform layers; hybrid's media part is single_scatter
            settings = {"path_tracer": PATH_TRACER, "hybrid": HYBRID}.get(technique, ())
            cases.append(Case(stage, technique, time, settings))
    return cases


CASES = _cases()
#: Species tables the cases need (built once into the optics cache).
SPECIES = ("cloud", "rain", "snow", "ice")


def _relocated(src: Path, dest: Path, data: Path) -> Path:
    """Copy of the shipped stage ``src`` whose ``../data/`` asset paths point into ``data``."""
    dest.write_text(src.read_text().replace("@../data/", f"@{data.as_posix()}/"))
    return dest


def write_inputs(folder: Path) -> dict[str, Path]:
    """Low-resolution fields and stage copies for every golden stage, under ``folder``; {stage name: stage path}."""
    import make_cumulus
    import make_storm
    import make_stratocumulus

    from warpsky.media.stratiform.thickness import procedural_thickness

    data = folder / "data"
    make_cumulus.write_all(data, 20, 7)
    strato = data / "stratocumulus"
    strato.mkdir(parents=True, exist_ok=True)
    np.save(strato / "thickness.npy", procedural_thickness(48, cover=0.75, max_thickness=450.0, seed=8))
    np.save(strato / "ground_albedo.npy", make_stratocumulus.ground_albedo(48))
    storm = data / "storm"
    make_storm.write_frames(storm, 48, res=12, only=[40])
    return {
        "cumulus": _relocated(ROOT / "usd_scenes" / "cumulus.usda", folder / "cumulus.usda", data),
        "sunrise": _relocated(ROOT / "usd_scenes" / "sunrise.usda", folder / "sunrise.usda", data),
        "stratocumulus": _relocated(ROOT / "usd_scenes" / "stratocumulus.usda", folder / "stratocumulus.usda", data),
        "storm": make_storm.write_stage(folder / "storm.usda", storm, 48),
    }


def render_case(case: Case, stages: dict[str, Path], folder: Path) -> dict[str, np.ndarray]:
    """Render ``case`` through the command line (32-bit float EXR, CPU) and read it back."""
    from warpsky.cli.main import main
    from warpsky.output.exr import read_exr

    out = folder / "out" / f"{case.name}.####.exr"
    args = ["render", str(stages[case.stage]), str(out), "--frames", f"{case.time:g}", "--res", str(WIDTH),
            "--technique", case.technique, "--device", "cpu", "--float", "--overwrite"]
    for setting in case.settings:
        args += ["--set", setting]
    if main(args) != 0:
        raise RuntimeError(f"warpsky render failed for golden {case.name}")
    image = read_exr(folder / "out" / f"{case.name}.{int(case.time):04d}.exr")
    return {"rgba": image.rgba(), "transmittance": image.transmittance(), "depth": image.depth()}


def largest_difference(actual: dict[str, np.ndarray], golden: dict[str, np.ndarray]) -> float:
    """Largest |actual - golden| over every channel, relative to the golden's largest magnitude in that output."""
    worst = 0.0
    for key, expected in golden.items():
        scale = max(float(np.abs(expected).max()), 1e-30)
        worst = max(worst, float(np.abs(actual[key].astype(np.float64) - expected).max()) / scale)
    return worst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="compare with the stored goldens, write nothing")
    parser.add_argument("--only", default=None, help="comma-separated case names (e.g. cumulus-slicing)")
    args = parser.parse_args(argv)
    cases = [c for c in CASES if args.only is None or c.name in args.only.split(",")]
    from warpsky.core.device import init_warp

    init_warp()
    GOLDEN.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        stages = write_inputs(folder)
        for case in cases:
            arrays = render_case(case, stages, folder)
            path = GOLDEN / f"{case.name}.npz"
            if args.check:
                stored = dict(np.load(path))
                print(f"{case.name:<30} largest relative difference {largest_difference(arrays, stored):.3g}")
            else:
                np.savez_compressed(path, **arrays)
                print(f"wrote {path.relative_to(ROOT)} {arrays['rgba'].shape[1]}x{arrays['rgba'].shape[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
