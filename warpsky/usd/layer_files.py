"""Open a stage's layers before USD composes them, so that a broken file is reported by its own parser.

``Usd.Stage.Open`` reports a syntax error in the root layer as "Failed to open layer", wrapped in C++ function
names and source locations, and composes the stage without a broken sublayer or reference, printing only a
warning. :func:`open_layers` instead opens the root layer and, depth first, every layer it reaches through
sublayers, references and payloads with ``Sdf.Layer.FindOrOpen``. The first layer that cannot be read raises a
:class:`~warpsky.core.errors.SceneError` carrying the parser's own ``file:line:column: message`` on one line, followed
by the chain of layers that led to it. The layers stay open for as long as the caller holds the returned list, so the
stage opened next finds them in USD's layer registry instead of parsing them again.

A missing sublayer is reported by name here; a missing reference or payload is reported by
:func:`composition_problem` once the stage is open, because only the arcs USD actually composes count
(a reference inside an unselected variant may point nowhere).
"""

from __future__ import annotations

import re
from pathlib import Path

from warpsky.core.errors import SceneError
from warpsky.usd.generated_data import missing_file_hint

#: The prefix USD puts before every message of a ``Tf.ErrorException``: where in USD's C++ sources it was raised.
_TF_PREFIX = re.compile(r"\s*Error in '[^']*' at line \d+ in file [^\n]*? : '")
_CPP_SYMBOL = re.compile(r"pxrInternal_\w+::")
_ASSET = re.compile(r"@([^@]+)@")
_LONGEST_MESSAGE = 240  # characters; the parser quotes the rest of the offending line, which can be long


def tf_message(error: Exception) -> str:
    """The messages of a USD ``Tf.ErrorException`` on one line, without USD's C++ function names and locations."""
    text = str(error)
    parts = _TF_PREFIX.split(text)
    messages = [part.strip().removesuffix("'").strip() for part in (parts[1:] if len(parts) > 1 else parts)]
    message = "; ".join(dict.fromkeys(" ".join(m.split()) for m in messages if m.strip()))
    message = _CPP_SYMBOL.sub("", message)
    message = re.sub(r"^<([^<>]+)> is not a valid", r"\1 is not a valid", message)  # USD brackets the path
    if len(message) > _LONGEST_MESSAGE:
        message = message[: _LONGEST_MESSAGE - 1].rstrip() + "…"
    return message


def _unreadable(path: str, error: Exception | None) -> str:
    """Why ``path`` could not be read, naming it once."""
    message = tf_message(error) if error is not None else ""
    if not message:
        return f"{path} is not a USD file (USD can read .usda text, .usdc crate and .usdz packages)"
    return message if Path(path).name in message else f"{path}: {message}"


def open_layers(path: Path) -> list:
    """Open the layer at ``path`` and every layer it reaches (sublayers, references, payloads); returns them, the
    root first. Raises :class:`SceneError` naming the first unreadable layer and the layers that led to it."""
    layers: list = []
    _visit(str(path), [], layers, set())
    return layers


def _visit(identifier: str, chain: list[str], layers: list, seen: set[str]) -> None:
    """Open ``identifier`` (reached through ``chain``, innermost link first) and the layers it names, depth first."""
    from pxr import Ar, Sdf, Tf

    if identifier in seen:
        return
    seen.add(identifier)
    try:
        layer, error = Sdf.Layer.FindOrOpen(identifier), None
    except Tf.ErrorException as exc:
        layer, error = None, exc
    if layer is None:
        if error is None and chain and not Ar.GetResolver().Resolve(identifier):
            return  # a missing reference or payload: composition_problem names it if USD composes it
        raise SceneError(_unreadable(identifier, error) + "".join(chain))
    layers.append(layer)
    name = layer.realPath or identifier
    sublayers = {layer.ComputeAbsolutePath(p) for p in layer.subLayerPaths}
    for sublayer in sorted(sublayers):
        if not Ar.GetResolver().Resolve(sublayer):
            raise SceneError(f"sublayer {sublayer} does not exist (named by {name})" + "".join(chain))
    for asset in layer.GetCompositionAssetDependencies():
        if not asset or asset.startswith("`"):  # expression-valued paths resolve only during composition
            continue
        target = layer.ComputeAbsolutePath(asset)
        link = f" (sublayer of {name})" if target in sublayers else f" (referenced by {name})"
        _visit(target, [link, *chain], layers, seen)


def composition_problem(stage) -> str | None:
    """The first error USD met while composing ``stage`` that loses a layer (a reference or payload whose file is
    missing or unreadable), as one line; None when there is none."""
    from pxr import Pcp

    lost = {Pcp.ErrorType_InvalidAssetPath, Pcp.ErrorType_InvalidSublayerPath}
    for error in stage.GetCompositionErrors():
        if error.errorType in lost:
            message = " ".join(str(error).split()).removesuffix("; skipping.")
            asset = _ASSET.search(message)  # USD names the missing file between @s, resolved to an absolute path
            hint = missing_file_hint(asset.group(1)) if asset else ""
            return message.removesuffix(".") + hint if hint else message
    return None
