"""Error types that carry a message meant for users.

Every error raised at the boundary (USD reading, file loading, command line) is one of these. The message names
the prim, attribute or file at fault and what was expected, so the CLI can print it as-is and exit with code 2.
"""

from __future__ import annotations


class WarpskyError(Exception):
    """Base class for errors caused by the user's input (exit code 2)."""

    exit_code = 2


class SceneError(WarpskyError):
    """A stage, prim, attribute or data file is missing or invalid."""


class UsageError(WarpskyError):
    """A command-line argument or option value is invalid."""


class ResourceError(WarpskyError):
    """The frame needs more memory or work than allowed: the message names the estimate, the limit and the option
    that changes it."""


class OutputError(WarpskyError):
    """An output or cache file cannot be written or read back."""


class UnsupportedVar(SceneError):
    """A RenderVar whose source warpsky does not write: its product is written without it."""


def did_you_mean(word: str, candidates, cutoff: float = 0.6) -> str:
    """``"did you mean X? "`` (or ``"did you mean X or Y? "``) for the ``candidates`` closest to a misspelt ``word``
    (difflib's similarity at least ``cutoff``; raise it for names that share long prefixes, as prim paths do), ""
    when none is close: the start of an error's suggestion, before the list of what is valid."""
    import difflib

    close = difflib.get_close_matches(word, [str(c) for c in candidates], n=2, cutoff=cutoff)
    return f"did you mean {' or '.join(close)}? " if close else ""
