"""Typed settings, declared once per field, for every technique and pass.

A settings class is a frozen dataclass deriving from :class:`Settings` whose fields are made by :func:`setting`::

    @documented
    @dataclass(frozen=True)
    class FogSettings(Settings):
        owner = "fog"
        prefix = "fog."
        nodes: int = setting(4, range="1..64", help="Gauss-Legendre nodes per piece")

That one declaration drives everything else: ``--set fog.nodes=8`` parsing (:func:`parse_settings`, by the field's
type: whole numbers for ``int``, 0/1/true/false for ``bool``, a value or a member's name for an Enum, ``auto`` for
None), validation (the ``range`` text is parsed into a check, see :func:`range_check`; cross-field rules go in
:meth:`Settings.check`), the error messages (they name the setting and say what it accepts), ``warpsky render
--help`` and the docstring table (:func:`settings_table`), ``warpsky info`` (:func:`settings_line`) and the settings
hash (:func:`settings_dict`). ``--set`` names reach a pass's settings by their ``prefix`` (:func:`split_by_prefix`).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import re
import textwrap
import types
import typing
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from warpsky.core.errors import UsageError, did_you_mean


def setting(default, *, unit: str = "--", range: str = "", help: str, auto: str | None = None):  # noqa: A002
    """A settings dataclass field carrying its own documentation.

    Args:
        default: The default value (None: ``auto``, worked out per scene by the owner's ``resolved_settings``).
        unit: Unit of the value (``m``, ``1/sr``, ``texel``), ``--`` for pure numbers.
        range: Accepted values as they read after "must be a whole number": ``>= 1``, ``> 0``, ``0..4`` (whole
            numbers, both ends included), ``[0, 1)``; checked on construction (:func:`range_check`). Any other text
            documents a rule that :meth:`Settings.check` enforces.
        help: What the setting does.
        auto: What ``auto`` (None) means, for settings that have it.
    """
    return field(default=default, metadata={"unit": unit, "range": range, "help": help, "auto": auto})


class Settings:
    """Base of every settings dataclass (frozen, fields made by :func:`setting`).

    ``owner`` names the technique or pass the settings belong to; ``prefix`` is what a ``--set`` name carries to
    reach them (``stratiform.`` for the stratiform pass, empty for the technique). Construction converts every value
    to its declared type (so ``spp=64.0`` and ``low_albedo=1`` given in Python hold an int and a bool, like values
    parsed from ``--set``), checks each declared range and then :meth:`check`; a bad value is a one-line
    :class:`~warpsky.core.errors.UsageError` naming the setting.
    """

    owner: ClassVar[str]
    prefix: ClassVar[str] = ""

    def __post_init__(self):
        self.normalise()
        for name, kind in field_kinds(type(self)).items():
            value = getattr(self, name)
            if value is not None and not kind.accepts(value):
                raise UsageError(f"setting {self.prefix}{name} must be {kind.expected()}, got {_text(value)}")
        self.check()

    def normalise(self) -> None:
        """Convert every field to its declared type; a value that has none is a UsageError naming the setting."""
        for name, kind in field_kinds(type(self)).items():
            value = getattr(self, name)
            try:
                converted = kind.convert(value)
            except (TypeError, ValueError):
                raise UsageError(f"setting {self.prefix}{name} must be {kind.expected()}, got {value}") from None
            if converted is not value:
                object.__setattr__(self, name, converted)

    def check(self) -> None:
        """Rules between fields, beyond each field's own range (none by default)."""


#: ``>= 1``, ``> 0``, ``<= 8``, ``< 1``.
_BOUND = re.compile(r"^(>=|>|<=|<)\s*(-?[0-9.eE+-]+)$")
#: ``0..4``: whole numbers, both ends included.
_SPAN = re.compile(r"^(-?\d+)\.\.(-?\d+)$")
#: ``[0, 1)``, ``(0, 1]``: an interval with open or closed ends.
_INTERVAL = re.compile(r"^([\[(])\s*(-?[0-9.eE+-]+)\s*,\s*(-?[0-9.eE+-]+)\s*([\])])$")


@functools.cache
def range_check(text: str):
    """A function ``value -> bool`` for a :func:`setting` ``range`` text, or None when the text is not one of the
    checked forms (``>= a``, ``> a``, ``<= a``, ``< a``, ``a..b``, ``[a, b)`` and the other three intervals)."""
    text = text.strip()
    if match := _BOUND.match(text):
        op, bound = match.group(1), float(match.group(2))
        return {">=": lambda v: v >= bound, ">": lambda v: v > bound, "<=": lambda v: v <= bound,
                "<": lambda v: v < bound}[op]
    if match := _SPAN.match(text):
        low, high = int(match.group(1)), int(match.group(2))
        return lambda v: low <= v <= high
    if match := _INTERVAL.match(text):
        left, low, high, right = match.group(1), float(match.group(2)), float(match.group(3)), match.group(4)
        return lambda v: (v >= low if left == "[" else v > low) and (v <= high if right == "]" else v < high)
    return None


@dataclass(frozen=True)
class FieldKind:
    """The declared type of one settings field: ``base`` is int, float, bool, an Enum class or a Literal's values,
    ``optional`` whether None (``auto``) is allowed, ``range`` and ``unit`` as given to :func:`setting`."""

    base: object
    optional: bool
    range: str = ""
    unit: str = "--"

    def convert(self, value):
        """``value`` as the declared type; ValueError when it cannot be."""
        if value is None:
            if self.optional:
                return None
            raise ValueError(value)
        if isinstance(self.base, tuple):  # Literal
            if value in self.base:
                return self.base[self.base.index(value)]
            raise ValueError(value)
        if isinstance(self.base, type) and issubclass(self.base, enum.Enum):
            return self.base(value)
        if not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(value)
        if self.base is bool:
            if value in (0, 1):
                return bool(value)
            raise ValueError(value)
        if self.base is int:
            if math.isfinite(value) and float(value).is_integer():
                return value if type(value) is int else int(value)
            raise ValueError(value)
        return value if type(value) is float else float(value)

    def accepts(self, value) -> bool:
        """Whether a converted, non-None ``value`` lies in the declared range (numbers are finite)."""
        if self.base not in (int, float):
            return True
        check = range_check(self.range)
        return math.isfinite(value) and (check is None or bool(check(value)))

    def expected(self) -> str:
        """What a valid value is, for error messages: ``a whole number >= 1``, ``a number > 0 [m] or auto``,
        ``0 or 1``, ``0, 24 or 25``."""
        if self.base is bool:
            return "0, 1 or auto" if self.optional else "0 or 1"
        if isinstance(self.base, tuple) or (isinstance(self.base, type) and issubclass(self.base, enum.Enum)):
            values = [str(v.value if isinstance(v, enum.Enum) else v) for v in self.choices()]
            text = ", ".join(values[:-1]) + " or " + values[-1] if len(values) > 1 else values[0]
            if isinstance(self.base, type):
                text += " (" + ", ".join(member.name.lower() for member in self.base) + ")"
            return text + (" or auto" if self.optional else "")
        rng = self.range
        if rng and (rng[0].isdigit() or rng[0] in "[(-"):
            rng = "in " + rng
        noun = "a whole number" if self.base is int else "a number"
        unit = f" [{self.unit}]" if self.unit not in ("", "--") else ""
        return f"{noun} {rng}".strip() + unit + (" or auto" if self.optional else "")

    def choices(self) -> tuple:
        return tuple(self.base) if isinstance(self.base, (tuple, enum.EnumMeta)) else ()


@functools.cache
def field_kinds(cls) -> dict[str, FieldKind]:
    """Every field of the settings dataclass ``cls`` with its declared type."""
    hints = typing.get_type_hints(cls)
    kinds = {}
    for f in dataclasses.fields(cls):
        hint, optional = hints[f.name], False
        if typing.get_origin(hint) in (typing.Union, types.UnionType):
            rest = [a for a in typing.get_args(hint) if a is not type(None)]
            optional = len(rest) < len(typing.get_args(hint))
            if len(rest) != 1:
                raise TypeError(f"{cls.__name__}.{f.name}: one type (optionally | None) per setting, got {hint}")
            hint = rest[0]
        if typing.get_origin(hint) is typing.Literal:
            hint = typing.get_args(hint)
        elif hint not in (int, float, bool) and not (isinstance(hint, type) and issubclass(hint, enum.Enum)):
            raise TypeError(f"{cls.__name__}.{f.name}: settings are int, float, bool, an Enum or a Literal, got {hint}")
        kinds[f.name] = FieldKind(hint, optional, f.metadata.get("range", ""), f.metadata.get("unit", "--"))
    return kinds


_AUTO = ("", "auto", "none")
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")
_DEFAULT = object()


def _number(text: str):
    try:
        return int(text)
    except ValueError:
        return float(text)


def parse_value(cls, name: str, text):
    """``--set`` text for the field ``name`` of ``cls`` converted by its declared type; ``_DEFAULT`` for ``auto``
    on a setting without an automatic value (the default is kept). Range checks are the dataclass's. Values that
    are not text (given in Python) pass through to the dataclass, which converts them."""
    if not isinstance(text, str):
        return text
    kind = field_kinds(cls)[name]
    word = text.strip().lower()
    if word in _AUTO:
        return None if kind.optional else _DEFAULT
    if kind.base is bool and word in _TRUE + _FALSE:
        return word in _TRUE
    for choice in kind.choices():
        if isinstance(choice, enum.Enum) and word == choice.name.lower():
            return choice
        if isinstance(choice, str) and word == choice.lower():
            return choice
    try:
        return _number(word)
    except ValueError:
        pass
    if kind.base is bool:
        raise UsageError(f"setting {cls.prefix}{name} must be 0 or 1 (or true/false), got {text!r}")
    if kind.choices():
        raise UsageError(f"setting {cls.prefix}{name} must be {kind.expected()}, got {text!r}")
    noun = "a whole number" if kind.base is int else "a number"
    raise UsageError(f"setting {cls.prefix}{name}: expected {noun}, got {text!r}")


def parse_settings(cls, values: dict | None):
    """Build the settings dataclass ``cls`` from ``{name: text or value}`` (names without ``cls.prefix``),
    converting text by each field's declared type (:func:`parse_value`)."""
    kinds = field_kinds(cls)
    kwargs = {}
    for key, text in (values or {}).items():
        if key not in kinds:
            known = ", ".join(cls.prefix + name for name in kinds)
            guess = did_you_mean(cls.prefix + key, [cls.prefix + name for name in kinds])
            raise UsageError(f"unknown setting {cls.prefix}{key} for {cls.owner}; {guess}known: {known}")
        value = parse_value(cls, key, text)
        if value is not _DEFAULT:
            kwargs[key] = value
    return cls(**kwargs)


#: Prefixes a pass's settings had before it was renamed: the old name is refused with the new one.
RENAMED_PREFIXES = {"heightfield.": "deck."}


def split_by_prefix(values: dict, prefixes) -> tuple[dict, dict[str, dict]]:
    """``--set`` values split into (the technique's, {prefix: that pass's, names without the prefix}) for the
    passes' ``prefixes`` (``stratiform.``, ``fog.``); names with no known prefix are the technique's."""
    own: dict = {}
    by_prefix: dict[str, dict] = {prefix: {} for prefix in prefixes}
    for key, value in (values or {}).items():
        old = next((p for p in RENAMED_PREFIXES if key.startswith(p)), None)
        if old is not None:
            new = RENAMED_PREFIXES[old] + key[len(old):]
            raise UsageError(f"setting {key}: the {old[:-1]} pass is now called {RENAMED_PREFIXES[old][:-1]}; "
                             f"use {new}")
        prefix = next((p for p in prefixes if key.startswith(p)), None)
        if prefix is None:
            own[key] = value
        else:
            by_prefix[prefix][key[len(prefix):]] = value
    return own, by_prefix


def _text(value) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, enum.Enum):
        return str(value.value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def settings_dict(settings) -> dict:
    """``settings`` as plain JSON values by field name (Enum members as their values), for hashes and headers."""
    return {k: (v.value if isinstance(v, enum.Enum) else v) for k, v in dataclasses.asdict(settings).items()}


def settings_line(settings) -> str:
    """``prefix.name=value, ...`` of every field, ``auto`` for None: one line of ``warpsky info``."""
    return ", ".join(f"{settings.prefix}{k}={'auto' if v is None else _info_text(v)}"
                     for k, v in dataclasses.asdict(settings).items())


def _info_text(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return _text(value)


def settings_rows(cls) -> list[tuple[str, str, str, str]]:
    """(name with prefix, default with unit, range, meaning) per field of the settings dataclass ``cls``."""
    rows = []
    for f in dataclasses.fields(cls):
        meta, kind = f.metadata, field_kinds(cls)[f.name]
        unit = "" if meta.get("unit", "--") == "--" else " " + meta["unit"]
        default = "auto" if f.default is None else _text(f.default) + unit
        meaning = meta.get("help", "")
        if kind.choices() and isinstance(kind.base, enum.EnumMeta):
            meaning += "; by name: " + ", ".join(f"{m.name.lower()} = {m.value}" for m in kind.base)
        if meta.get("auto"):
            meaning += f"; auto: {meta['auto']}"
        rng = meta.get("range", "") or (" | ".join(_text(c) for c in kind.choices()) if kind.choices() else "")
        if kind.base is bool and not rng:
            rng = "0 | 1"
        rows.append((cls.prefix + f.name, default, rng, meaning))
    return rows


def settings_table(cls, indent: int = 2, width: int = 118) -> str:
    """The settings of ``cls`` as a plain-text table: name, default [unit], range, meaning (wrapped)."""
    rows = settings_rows(cls)
    widths = [max(len(row[i]) for row in rows + [("name", "default", "range", "")]) for i in range(3)]
    lead = " " * indent
    prefix_width = indent + sum(widths) + 3
    lines = [lead + "  ".join(h.ljust(w) for h, w in zip(("name", "default", "range"), widths, strict=True))
             + "  meaning"]
    for row in rows:
        head = lead + "  ".join(cell.ljust(w) for cell, w in zip(row[:3], widths, strict=True)) + "  "
        wrapped = textwrap.wrap(row[3], max(30, width - prefix_width - 3)) or [""]
        lines.append(head + wrapped[0])
        lines += [" " * (prefix_width + 3) + more for more in wrapped[1:]]
    return "\n".join(line.rstrip() for line in lines)


def documented(cls):
    """Class decorator for settings dataclasses: append the settings table made from the field metadata to the
    class docstring, so ``help()`` and the docs show one table, the one ``--help`` shows."""
    cls.__doc__ = (cls.__doc__ or "").rstrip() + "\n\n    Settings:\n\n" + settings_table(cls, indent=4) + "\n"
    return cls
