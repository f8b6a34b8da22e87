"""Typed reads of JSON objects (model files) that fail naming the file and the field path.

A :class:`FieldReader` wraps one JSON object: ``get`` checks a field's type,
``rule`` applies a parameter's declared :class:`~partcal._validation.Rule`
(the same rule the estimator and the run-config reader apply), ``array``
checks nested lists for element type, shape and finiteness, and ``sub``
descends into a field, so a message reads ``model.json: field
'regions[2].coef': expected shape (4, 3); got shape (3, 3)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validation import Rule, one_of
from .errors import ModelFileError


def is_int(value) -> bool:
    """An int that is not a bool (JSON's integers)."""
    return isinstance(value, int) and not isinstance(value, bool)


class FieldReader:
    """Typed access to one JSON object, failing with the file and the field path."""

    def __init__(self, doc: Any, source: str, where: str):
        self.doc, self.source, self.where = doc, source, where
        if not isinstance(doc, dict):
            self.fail("", f"expected an object; got {type(doc).__name__}")

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def fail(self, key: str, message: str):
        raise ModelFileError(f"{self.source}: field {self.path(key) or 'top level'!r}: {message}")

    def get(self, key: str, kind):
        if key not in self.doc:
            self.fail(key, "missing")
        value = self.doc[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
        if float in kinds and is_int(value):
            ok, value = True, float(value)
        if not ok:
            names = " or ".join("null" if k is type(None) else k.__name__ for k in kinds)
            self.fail(key, f"expected {names}; got {type(value).__name__} {value!r}"[:200])
        return value

    def choice(self, key: str, allowed: tuple[str, ...]) -> str:
        return self.rule(key, one_of(*allowed))

    def rule(self, key: str, rule: Rule) -> Any:
        """The field ``key``, checked by a declared parameter :class:`~partcal._validation.Rule`."""
        if key not in self.doc:
            self.fail(key, "missing")
        value = self.doc[key]
        if rule.type == "float" and is_int(value):
            value = float(value)
        if rule.problem(value) is not None:
            self.fail(key, f"expected {rule.expected}; got {value!r}"[:200])
        return value

    def requirements(self, requirements, params: dict) -> None:
        """Fail at the first declared :class:`~partcal._validation.Requirement` that ``params`` break."""
        for req in requirements:
            if req.problem(params):
                self.fail(req.param, f"expected {req.expected}; got {params[req.param]!r}")

    def integer(self, key: str, low: int, high: int | None = None) -> int:
        value = self.get(key, int)
        if value < low or (high is not None and value > high):
            self.fail(key, f"expected an integer in [{low}, {high if high is not None else 'inf'}]; got {value}")
        return value

    def number(self, key: str, low: float | None = None, high: float | None = None) -> float:
        value = self.get(key, float)
        if not np.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
            self.fail(key, f"expected a finite number in [{low}, {high}]; got {value!r}")
        return value

    def sub(self, key: str, value: Any = None) -> "FieldReader":
        doc = self.get(key, dict) if value is None else value
        return FieldReader(doc, self.source, self.path(key) if value is None else key)

    def array(self, key: str, shape: tuple, kind=float) -> np.ndarray:
        """A nested list of ``kind`` (float: numbers, not strings or booleans; int; bool) of ``shape``.

        ``None`` in ``shape`` accepts any size on that axis.
        """
        value = self.get(key, list)
        check = {float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
                 int: is_int, bool: lambda v: isinstance(v, bool)}[kind]

        def walk(v, depth):
            if depth == len(shape):
                if not check(v):
                    self.fail(key, f"expected {kind.__name__} values; found {type(v).__name__} {v!r}"[:200])
                return
            if not isinstance(v, list):
                self.fail(key, f"expected nested lists of shape {shape}; found {type(v).__name__}")
            for item in v:
                walk(item, depth + 1)

        walk(value, 0)
        try:
            arr = np.array(value, dtype=kind if kind is not int else np.intp)
        except (TypeError, ValueError):
            self.fail(key, f"expected a regular array of shape {shape}")
        if arr.ndim != len(shape) or any(w is not None and w != a for w, a in zip(shape, arr.shape)):
            want = tuple("n" if w is None else w for w in shape)
            self.fail(key, f"expected shape {want}; got shape {arr.shape}")
        if kind is float and not np.all(np.isfinite(arr)):
            self.fail(key, "holds a non-finite value (NaN or infinity)")
        return arr
