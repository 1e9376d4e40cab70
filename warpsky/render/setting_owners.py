"""A ``--set`` name given to the wrong technique or pass, told where it belongs.

:func:`~warpsky.core.settings.parse_settings` knows one settings class: it can say a name is unknown to hybrid, not
that the name is slicing's or the stratiform pass's. :func:`check_owners` runs before it, over every registered
technique and pass, and raises a one-line :class:`~warpsky.core.errors.UsageError` naming the owner and the
``--technique`` / ``--set`` that reach it.
"""

from __future__ import annotations

from warpsky.core.errors import UsageError
from warpsky.core.settings import field_kinds
from warpsky.render.registry import technique_class, technique_names


def _owners(key: str, value, technique: str, passes: dict) -> list[str]:
    """Where the setting ``key`` lives other than where it was given: 'the NAME pass (use --set P.key=V)' and
    'the NAME technique (use --technique NAME --set key=V)'."""
    found = [f"the {cls.name} pass (use --set {prefix}{key}={value})" for prefix, cls in passes.items()
             if key in field_kinds(cls.Settings)]
    for name in technique_names():
        if key in field_kinds(technique_class(name).Settings):
            use = f"--set {key}={value}" if name == technique else f"--technique {name} --set {key}={value}"
            found.append(f"the {name} technique (use {use})")
    return found


def check_owners(technique: str, own: dict, by_prefix: dict[str, dict], passes: dict) -> None:
    """Raise a UsageError for the first name of ``own`` (the technique's ``--set`` names) or ``by_prefix``
    (``{prefix: a pass's names}``) that its target does not declare but another registered technique or pass of
    ``passes`` (``{prefix: pass class}``) does; names nobody declares are left to ``parse_settings``."""
    targets = [("", technique_class(technique).Settings, own)]
    targets += [(prefix, cls.Settings, by_prefix.get(prefix, {})) for prefix, cls in passes.items()]
    for prefix, settings, values in targets:
        known = field_kinds(settings)
        for key, value in values.items():
            if key in known:
                continue
            owners = _owners(key, value, technique, passes)
            if owners:
                raise UsageError(f"setting {prefix}{key} is not a setting of {settings.owner}; it belongs to "
                                 + " or ".join(owners))
