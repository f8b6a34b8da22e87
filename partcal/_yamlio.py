"""YAML with line numbers: safe loading, duplicate keys refused, strict typed sections.

``load_yaml`` returns plain Python data plus the line of every key path, so
errors can say ``models[2].partition.max_depth (line 31): ...``. ``Section``
reads one mapping field by field and refuses what it did not read, with a
"did you mean" for near misses.
"""

from __future__ import annotations

import difflib
import logging
import re
from pathlib import Path
from typing import Any, Callable

import yaml

from .errors import ConfigError


log = logging.getLogger(__name__)

class _Loader(yaml.SafeLoader):
    """The safe loader, reading ``1e-3`` and ``-2E5`` as numbers as YAML 1.2 does (YAML 1.1, PyYAML's, wants a
    dot in the mantissa and read them as text)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def load_yaml(path: str | Path) -> tuple[Any, dict[str, int]]:
    """Load a YAML file with the safe loader; return ``(data, lines)``.

    ``lines`` maps key paths such as ``"models[0].solver"`` to 1-based lines.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        lines: dict[str, int] = {}
        data = _build(loader, node, "", lines, path) if node is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f" (line {mark.line + 1})" if mark else ""
        raise ConfigError(f"{path}{line}: not valid YAML: {exc.problem or exc.context}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    finally:
        loader.dispose()
    return data, lines


def _build(loader, node, where: str, lines: dict[str, int], path: Path):
    lines.setdefault(where, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        out = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            sub = f"{where}.{key}" if where else str(key)
            if key in out:
                raise ConfigError(f"{path}: {sub} (line {key_node.start_mark.line + 1}): duplicate key "
                                  f"(first at line {lines[sub]})")
            lines[sub] = key_node.start_mark.line + 1
            out[key] = _build(loader, value_node, sub, lines, path)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(loader, item, f"{where}[{i}]", lines, path) for i, item in enumerate(node.value)]
    return loader.construct_object(node, deep=True)


_MISSING = object()


class Section:
    """A mapping read field by field, with errors that name path and line.

    Parameters
    ----------
    data : Any
        The mapping (anything else is an error).
    where : str
        Its key path (``""`` for the top level).
    lines : dict
        From :func:`load_yaml`.
    source : str
        The file name, first in every message.
    """

    def __init__(self, data: Any, where: str, lines: dict[str, int], source: str):
        self.where, self.lines, self.source = where, lines, source
        if data is None:
            data = {}
        if not isinstance(data, dict):
            self.fail(where, f"expected a mapping, got {_kind(data)}" + ("" if where else (
                ": is it a YAML config? (a CSV or another file given where a config is expected)")))
        self.data, self._read = data, set()

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def fail(self, where: str, message: str):
        line = self.lines.get(where)
        at = f"{where or 'top level'} (line {line})" if line else (where or "top level")
        raise ConfigError(f"{self.source}: {at}: {message}")

    def has(self, key: str) -> bool:
        return key in self.data

    def renamed(self, old: str, new: str) -> None:
        """Take key ``old`` as ``new`` (a key renamed: the old name is read for one release, with a warning that
        names file, key and line); both given is refused."""
        if old not in self.data:
            return
        where, to = self.path(old), self.path(new)
        if new in self.data:
            self.fail(where, f"is the old name of {new!r}, which is given too: keep {new!r} alone")
        line = self.lines.get(where)
        log.warning("%s: %s%s: the old name of %r, read as it for this release: rename it (the old name will be "
                    "refused in the next)", self.source, where, f" (line {line})" if line else "", new)
        self.data[new] = self.data.pop(old)
        for key in [k for k in self.lines if k == where or k.startswith(where + ".")]:
            self.lines[to + key[len(where):]] = self.lines[key]

    def get(self, key: str, kind: str, default: Any = _MISSING, check: Callable[[Any], str | None] | None = None):
        """Read ``key`` as ``kind`` (``int``, ``float``, ``str``, ``bool``, ``list``, ``map``, ``any``).

        ``check`` returns an error text (what was expected) or None.
        """
        self._read.add(key)
        where = self.path(key)
        if key not in self.data:
            if default is _MISSING:
                self.fail(self.where or "top level", f"missing required key {key!r}")
            return default
        value = self.data[key]
        if not _is_kind(value, kind):
            self.fail(where, f"must be {_KIND_TEXT[kind]}; got {_show(value)}")
        if kind == "float":
            value = float(value)
        problem = check(value) if check else None
        if problem:
            self.fail(where, f"must be {problem}; got {_show(value)}")
        return value

    def rule(self, key: str, rule) -> Any:
        """Read ``key`` by a declared parameter rule (``partcal._validation.Rule``: type, check, default)."""
        if rule.none and key in self.data and self.data[key] is None:
            self._read.add(key)
            return None
        return self.get(key, rule.type, default=rule.default, check=rule.problem)

    def requirements(self, requirements, params: dict) -> None:
        """Fail at the first declared requirement (``partcal._validation.Requirement``) ``params`` break,
        naming the key if this section wrote it."""
        for req in requirements:
            if req.problem(params):
                where = self.path(req.param) if self.has(req.param) else (self.where or "top level")
                self.fail(where, f"must be {req.expected}; got {_show(params[req.param])}")

    def section(self, key: str, required: bool = False) -> "Section":
        self._read.add(key)
        if required and key not in self.data:
            self.fail(self.where or "top level", f"missing required key {key!r}")
        return Section(self.data.get(key), self.path(key), self.lines, self.source)

    def done(self) -> None:
        """Refuse every key that was not read, suggesting a close known one."""
        for key in self.data:
            if key not in self._read:
                close = difflib.get_close_matches(str(key), sorted(self._read), n=1, cutoff=0.6)
                hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(sorted(self._read))})"
                self.fail(self.path(str(key)), f"unknown key{hint}")


_KIND_TEXT = {"int": "an integer", "float": "a number", "str": "a text", "bool": "true or false",
              "list": "a list", "map": "a mapping", "any": "a value"}


def _is_kind(value: Any, kind: str) -> bool:
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "float":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == "str":
        return isinstance(value, str)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "list":
        return isinstance(value, list)
    if kind == "map":
        return isinstance(value, dict)
    return True


def _kind(value: Any) -> str:
    return {dict: "a mapping", list: "a list", str: "a text"}.get(type(value), repr(value))


def _show(value: Any, limit: int = 80) -> str:
    """A value as a message shows it: a list or mapping by what it is and what it holds (shortened)."""
    if isinstance(value, (dict, list)):
        text = repr(value)
        return f"{_kind(value)} {text if len(text) <= limit else text[:limit - 5] + ' ...' + text[-1]}"
    return repr(value)


def range_check(low: float | None = None, high: float | None = None, *, integer: bool = False):
    """A ``check`` for :meth:`Section.get`: a number in ``[low, high]`` (the wording of a declared rule)."""
    from ._validation import Rule

    return Rule("int" if integer else "float", None, low, high).problem
