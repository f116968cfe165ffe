"""Edit specs as the package takes them (TOML text, a path to a ``.toml`` file, or a dict of
the same shape) and the library's messages about them in a dict's terms: ``spec["handle"][0]``
where the command line says "line 4"."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, List, Optional, Tuple, Union

import numpy as np

from . import _rigidcells
from ._rigidcells import TurnNotHeldError

Spec = Union[str, "os.PathLike[str]", dict]


def _plain(value: Any, path: List[Any]) -> Any:
    """A dict spec's value as plain Python (numpy scalars and arrays as the numbers and lists
    they hold, paths as text); a value no spec holds (None, NaN, a masked array, an object)
    is an error naming its key path."""
    if isinstance(value, dict):
        return {str(k): _plain(v, path + [str(k)]) for k, v in value.items()}
    if isinstance(value, np.ma.MaskedArray):
        raise TypeError(f"{_key_path(path)}: a masked array; pass the values themselves")
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "fiub":
            raise TypeError(f"{_key_path(path)}: an array of {value.dtype}, not numbers")
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v, path + [k]) for k, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if value is None:
        raise ValueError(f"{_key_path(path)}: None is not a value (leave the key out)")
    if isinstance(value, float) and not np.isfinite(value):
        raise ValueError(f"{_key_path(path)}: {value} is not a finite number")
    if not isinstance(value, (str, int, float, bool)):
        raise TypeError(f"{_key_path(path)}: a {type(value).__name__} is not a number, text, list or dict")
    return value


def _key_paths(text: str) -> List[str]:
    """For each line of TOML made from a dict spec, the dict's key path of what it holds
    (``spec["handle"][0]["translate"]``), or "" for a blank line."""
    paths: List[str] = []
    counts: dict = {}
    table: List[Any] = []
    for line in text.splitlines():
        t = line.strip()
        if t.startswith("[["):
            names = t.strip("[]").split(".")
            counts[tuple(names)] = counts.get(tuple(names), -1) + 1
            table = names[:-1] + [names[-1], counts[tuple(names)]]
        elif t.startswith("["):
            names = t.strip("[]").split(".")
            table = []
            for k, name in enumerate(names):
                table.append(name)
                if tuple(names[: k + 1]) in counts:
                    table.append(counts[tuple(names[: k + 1])])
        elif "=" in t:
            paths.append(_key_path(table + [t.split("=", 1)[0].strip().strip('"')]))
            continue
        else:
            paths.append("")
            continue
        paths.append(_key_path(table))
    return paths


def _key_path(parts: List[Any]) -> str:
    """``["handle", 0, "box"]`` as ``spec["handle"][0]["box"]``."""
    return "spec" + "".join(f"[{p}]" if isinstance(p, int) else f'["{p}"]' for p in parts)


def _spec(spec: Spec) -> Tuple[str, str, Optional[List[str]]]:
    """The spec's TOML text, the folder its relative file names are resolved against, and for
    a dict the key path of each line of that text."""
    if isinstance(spec, dict):
        text = _rigidcells.toml_from_json(json.dumps(_plain(spec, [])))
        return text, os.getcwd(), _key_paths(text)
    if isinstance(spec, os.PathLike) or (
        isinstance(spec, str) and "\n" not in spec and spec.strip().endswith(".toml")
    ):
        path = Path(spec)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError as e:
            raise OSError(f"{path}: {e.strerror}") from e
        return text, str(path.parent.resolve()), None
    if isinstance(spec, str):
        return spec, os.getcwd(), None
    raise TypeError("spec must be TOML text, a path to a .toml file, or a dict")


def _said(
    parts: Any, paths: Optional[List[str]], option: Any = None, entry: Any = None
) -> str:
    """A message of the library, given as its parts, as text. The parts: the package's words;
    the spec's lines as numbers; the options it names as ``(keyword, value or None, how the
    package says both)``; the spec entries it names as dicts of ``entry`` (the kind:
    ``handle``), ``index`` (from 0), ``line`` and ``said``; asides as nested lists of parts.
    Each line and entry is said as a dict spec's key path, or as ``line N`` and ``handle #2
    (line 17)`` for a spec written as TOML; each entry as ``entry(kind, index)`` says it where
    given; each option as ``option(keyword, value)`` says it where given (default: the
    package's way). Where ``option`` gives None the face lacks that option: it is said in the
    package's words, and an aside naming it is left unsaid. A message that is already text is
    kept."""
    if isinstance(parts, str):
        return parts

    def path(line: int) -> Optional[str]:
        if paths is not None and 0 < line <= len(paths) and paths[line - 1]:
            return paths[line - 1]
        return None

    def one(p: Any) -> str:
        if isinstance(p, str):
            return p
        if isinstance(p, list):
            # An aside: said only where every option it names, its own asides' among them,
            # is one the face has (as the library's `Said::options`).
            if option is not None and any(option(k, v) is None for k, v, _ in _options(p)):
                return ""
            return "".join(one(q) for q in p)
        if isinstance(p, tuple):
            keyword, value, said = p
            if option is None:
                return said
            mine = option(keyword, value)
            return said if mine is None else mine
        if isinstance(p, dict):
            if entry is not None:
                return entry(p["entry"], p["index"])
            return path(p["line"]) or p["said"]
        return path(p) or f"line {p}"

    return "".join(one(p) for p in parts)


def _options(parts: List[Any]) -> List[Any]:
    """The options (``(keyword, value, said)``) that ``parts`` name, its asides' among them."""
    out: List[Any] = []
    for p in parts:
        if isinstance(p, tuple):
            out.append(p)
        elif isinstance(p, list):
            out.extend(_options(p))
    return out


def _lines_said(messages: List[Any], paths: Optional[List[str]]) -> List[str]:
    """Messages of the library (as parts, see ``_said``) as text, a dict spec's lines named by
    their key paths."""
    return [_said(m, paths) for m in messages]


def _in_dict_terms(error: ValueError, paths: Optional[List[str]]) -> ValueError:
    """A spec error of a dict spec: its line said as the dict's key path (the TOML it became,
    and the parser's picture of it, are the package's, not the user's)."""
    if paths is None:
        return error
    line, message = getattr(error, "spec_line", None), getattr(error, "spec_message", None)
    if isinstance(line, int) and message is not None:
        path = paths[line - 1] if 0 < line <= len(paths) and paths[line - 1] else "spec"
        raised = type(error)(f"{path}: {_said(message, paths)}")
    else:
        parts = getattr(error, "parts", None)
        # Only a message naming a line or an entry reads otherwise by key path.
        if not (isinstance(parts, list) and any(isinstance(p, (int, dict)) for p in parts)):
            return error
        raised = type(error)(_said(parts, paths))
    raised.__dict__.update(error.__dict__)
    return raised


def _call(paths: Optional[List[str]], f: Any, *args: Any) -> Any:
    """``f(*args)``, a dict spec's errors said by key path."""
    try:
        return f(*args)
    except TurnNotHeldError as e:
        if paths is None:
            raise
        raise _turn_said(e, _key_path(["handle", e.handle])) from None
    except ValueError as e:
        raised = _in_dict_terms(e, paths)
        if raised is e:
            raise
        raise raised from None


def _turn_said(error: TurnNotHeldError, name: str) -> TurnNotHeldError:
    """The refusal with the handle called ``name`` (``spec["handle"][0]``), its fields kept but
    ``line`` (None: a dict spec has no lines)."""
    said = TurnNotHeldError(f"{name} {error.said}")
    said.__dict__.update(error.__dict__)
    # The line is the TOML's the package wrote, not one the user did.
    said.line = None
    return said
