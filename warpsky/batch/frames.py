"""Frame lists and output names, following usdrecord's rules.

Frame specs use ``UsdUtils.TimeCodeRange``'s grammar: ``1``, ``1:48``, ``1:48x2``, ``1.5:3x0.5``; a comma joins
several. Output paths mark the frame with a placeholder: a run of ``#``, optionally ``.`` and more ``#`` for
subframes; the field width is the placeholder's length and the decimals the ``#`` after the dot, zero-padded
(``####`` -> ``0012``, ``###.##`` -> ``012.50``, ``####`` at -3 -> ``-003``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from warpsky.core.errors import UsageError
from warpsky.core.files import PLACEHOLDER

GRAMMAR = "examples: 1 | 1:48 | 1:48x2 | 1.5:3x0.5 | 1,5,9:12"


def parse_frame_spec(spec: str) -> list[float]:
    """Time codes named by ``spec`` in order (duplicates kept, as written)."""
    from pxr import Tf, UsdUtils

    times: list[float] = []
    parts = [p.strip() for p in str(spec).split(",")]
    for part in parts:
        if not part:
            raise UsageError(f"--frames {spec!r}: empty frame spec ({GRAMMAR})")
        try:
            span = UsdUtils.TimeCodeRange.CreateFromFrameSpec(part)
        except Tf.ErrorException:
            raise UsageError(f"--frames {spec!r}: cannot parse {part!r} ({GRAMMAR})") from None
        values = [float(t.GetValue()) for t in span]
        if not values:
            raise UsageError(f"--frames {spec!r}: {part!r} names no frame ({GRAMMAR})")
        times.extend(values)
    return times


class FramePattern:
    """An output path, possibly with a frame placeholder."""

    def __init__(self, pattern: str):
        self.pattern = str(pattern)
        if not self.pattern.lower().endswith(".exr"):
            raise UsageError(f"output {self.pattern!r} must end in .exr")
        matches = list(PLACEHOLDER.finditer(self.pattern))
        if len(matches) > 1:
            raise UsageError(f"output {self.pattern!r} has {len(matches)} frame placeholders; use exactly one")
        self._match = matches[0] if matches else None

    @property
    def has_placeholder(self) -> bool:
        return self._match is not None

    def require_placeholder(self, frame_count: int) -> None:
        if frame_count > 1 and not self.has_placeholder:
            raise UsageError(
                f"output {self.pattern!r} has no frame placeholder (e.g. out/name.####.exr) but {frame_count} "
                "frames were requested"
            )

    def path_for(self, frame: float) -> Path:
        if self._match is None:
            return Path(self.pattern)
        text = self._match.group(0)
        decimals = len(text.split(".", 1)[1]) if "." in text else 0
        if decimals == 0 and float(frame) != int(frame):
            raise UsageError(
                f"frame {frame:g} is a subframe, but {self.pattern!r} has no decimals in its placeholder "
                "(use e.g. ####.##)"
            )
        number = f"{float(frame):0{len(text)}.{decimals}f}"
        return Path(self.pattern[: self._match.start()] + number + self.pattern[self._match.end():])


class PlainLines:
    """A progress bar's ``write``, ``update`` and ``close`` where no bar is drawn (one frame, or no terminal): each
    line printed as it comes, as tqdm's ``write`` does, without loading tqdm (and multiprocessing, 10-40 ms)."""

    @staticmethod
    def write(text: str, file=None) -> None:
        print(text, file=file if file is not None else sys.stdout)

    def update(self, count: int = 1) -> None:
        pass

    def close(self) -> None:
        pass
