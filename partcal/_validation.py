"""Boundary checks: turn user input into clean arrays, or raise with what was expected.

Every public entry point validates here once; the numerical core trusts its
inputs. Messages follow one format, naming the parameter, what was expected
and what was got. Parameters are checked by declared :class:`Rule` objects
(one rule, one wording, wherever the parameter is read), and model files by a
:class:`FieldReader`, whose messages name the file and the field path
(``model.json: field 'regions[2].coef': expected shape (4, 3); got shape (3, 3)``).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from .errors import DataError, ModelFileError, PartcalError

MAX_PAYLOAD_KG = 1e5        # a payload at the tool point, kg: data columns, model parameters, predictions


@contextmanager
def numbers_checked() -> Iterator[None]:
    """A block whose numbers partcal checks itself, never warned about: numpy's floating-point errors and
    Python's ``RuntimeWarning`` silenced (the command line runs each command in one); other warnings are
    restored on leaving it."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def check_array(
    value: Any, name: str, *, ndim: int = 2, columns: int | None = None, min_rows: int = 0
) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 array of the expected shape.

    Parameters
    ----------
    value : array-like
        The input.
    name : str
        How to call it in error messages (``"X"``, ``"q_deg"``).
    ndim : int
        Required number of dimensions.
    columns : int, optional
        Required size of the last axis.
    min_rows : int
        Minimum size of the first axis.

    Examples
    --------
    >>> check_array([[1, 2, 3]], "positions", columns=3).shape
    (1, 3)
    >>> check_array([[1, 2]], "positions", columns=3)
    Traceback (most recent call last):
    ...
    partcal.errors.DataError: Expected positions with shape (n, 3), got array with shape (1, 2).
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"Expected {name} as a numeric array, got {type(value).__name__}: {exc}") from None
    want = "(n, {})".format(columns if columns is not None else "m") if ndim == 2 else f"{ndim}-D"
    if arr.ndim != ndim or (columns is not None and arr.shape[-1] != columns):
        raise DataError(f"Expected {name} with shape {want}, got array with shape {arr.shape}.")
    if arr.shape[0] < min_rows:
        raise DataError(f"Expected {name} with at least {min_rows} rows, got {arr.shape[0]}.")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise DataError(f"{name} holds a non-finite value ({arr[tuple(bad)]}) at index {tuple(int(i) for i in bad)}.")
    return arr


def check_std(value: Any, n: int, where: str = "") -> NDArray[np.float64]:
    """``value`` as ``n`` rows of three standard deviations (mm), each finite and > 0: a weighted fit's
    ``std_mm``; else one :class:`DataError` naming the first bad row (``where``: the data's source, if any).

    >>> check_std([[0.02, 0.02, 0.03]], 1).shape
    (1, 3)
    """
    std = check_array(value, "std_mm", columns=3)
    bad = np.flatnonzero(~(std > 0).all(axis=1))
    if std.shape[0] != n or bad.size:
        got = f"{std[bad[0]].tolist()} at row {bad[0] + 1}" if bad.size else f"{std.shape[0]} rows"
        raise DataError(f"{where + ': ' if where else ''}Expected std_mm as {n} rows of 3 positive standard "
                        f"deviations (mm), got {got}")
    return std


def param_error(owner: str, name: str, expected: str, got: Any) -> PartcalError:
    """The one message format for a bad parameter.

    >>> str(param_error("ErrorModel", "degree", "an int in [1, 8]", 0))
    "The 'degree' parameter of ErrorModel must be an int in [1, 8]. Got 0 instead."
    """
    return PartcalError(f"The {name!r} parameter of {owner} must be {expected}. Got {got!r} instead.")


def check_int(owner: str, name: str, value: Any, low: int, high: int | None = None) -> int:
    """Return ``value`` if it is an int in ``[low, high]``, else raise :func:`param_error`."""
    return int(integer(low, high).check(owner, name, value))


def check_real(
    owner: str, name: str, value: Any, low: float | None = None, high: float | None = None,
    *, low_open: bool = False,
) -> float:
    """Return ``value`` as float if it is a finite real within the bounds, else raise."""
    return float(real(low, high, default=None, low_open=low_open).check(owner, name, value))


def check_choice(owner: str, name: str, value: Any, choices: tuple) -> Any:
    """Return ``value`` if it is one of ``choices``, else raise :func:`param_error`."""
    return one_of(*choices).check(owner, name, value)


# ---------------------------------------------------------------------- declared parameter rules
@dataclass(frozen=True)
class Rule:
    """What one parameter accepts, declared once and applied wherever the parameter is read.

    An estimator declares a ``Rule`` per parameter (``_parameter_rules``); the
    estimator's own check, the run-config reader and the model-file reader all
    ask the same rule, so a rule and its wording (:attr:`expected`) exist once.
    Build rules with :func:`one_of`, :func:`integer`, :func:`real` and :func:`boolean`.

    Examples
    --------
    >>> integer(1, 8).expected, integer(1, 8).problem(9), integer(1, 8).problem(3)
    ('an int in [1, 8]', 'an int in [1, 8]', None)
    >>> one_of("rbf", "matern").expected
    "one of 'rbf', 'matern'"
    """

    type: str                           # "int", "float", "str", "bool": the value's type in YAML and JSON
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    none: bool = False                  # None is accepted too
    low_open: bool = False

    @property
    def expected(self) -> str:
        """What the rule accepts, in words (the one wording of every message about it)."""
        if self.choices:
            text = "one of " + ", ".join(repr(c) for c in self.choices)
        elif self.type == "bool":
            text = "a bool"
        elif self.type == "str":
            text = "a text"
        else:
            what = "an int" if self.type == "int" else "a real number"
            if self.low is not None and self.high is None and self.type == "int":
                text = f"{what} >= {self.low}"
            else:
                lo = "-inf" if self.low is None else self.low
                hi = "inf" if self.high is None else self.high
                text = f"{what} in {'(' if self.low_open else '['}{lo}, {hi}]"
        return text + (" or None" if self.none else "")

    def problem(self, value: Any) -> str | None:
        """None if ``value`` is accepted, else :attr:`expected`."""
        if value is None:
            return None if self.none else self.expected
        if self.choices:
            same_type = isinstance(value, str) == (self.type == "str") and not isinstance(value, (bool, np.bool_))
            return None if same_type and value in self.choices else self.expected
        if self.type == "bool":
            return None if isinstance(value, (bool, np.bool_)) else self.expected
        if self.type == "str":
            return None if isinstance(value, str) else self.expected
        kinds = Integral if self.type == "int" else Real
        if not isinstance(value, kinds) or isinstance(value, (bool, np.bool_)):
            return self.expected
        if not isinstance(value, Integral) and not math.isfinite(value):      # (a huge int is finite)
            return self.expected
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return self.expected
        if self.high is not None and value > self.high:
            return self.expected
        return None

    def check(self, owner: str, name: str, value: Any) -> Any:
        """Return ``value`` if accepted, else raise :func:`param_error` naming ``owner`` and ``name``."""
        if self.problem(value) is not None:
            raise param_error(owner, name, self.expected, value)
        return value


def one_of(*choices, default: Any = None, none: bool = False) -> Rule:
    """A rule for one of ``choices`` (texts or numbers); the first is the default unless given."""
    kind = "str" if isinstance(choices[0], str) else "float"
    return Rule(kind, choices[0] if default is None else default, choices=tuple(choices), none=none)


def integer(low: int, high: int | None = None, *, default: Any = None, none: bool = False) -> Rule:
    """A rule for an int in ``[low, high]`` (``high`` None: no upper bound)."""
    return Rule("int", low if default is None and not none else default, low, high, none=none)


def real(low: float | None = None, high: float | None = None, *, default: float | None, low_open: bool = False,
         none: bool = False) -> Rule:
    """A rule for a finite real number in ``[low, high]`` (``(low, high]`` with ``low_open``; None too with ``none``)."""
    return Rule("float", default, low, high, low_open=low_open, none=none)


def boolean(default: bool) -> Rule:
    """A rule for true or false."""
    return Rule("bool", default)


@dataclass(frozen=True)
class Requirement:
    """A rule that ties parameters together: ``param`` must be ``expected`` whenever ``holds(params)`` is false.

    >>> fourier = Requirement("cross_terms", "false for the fourier basis",
    ...                       lambda p: not p["cross_terms"] or p["basis"] == "polynomial")
    >>> fourier.problem({"cross_terms": True, "basis": "fourier"})
    'false for the fourier basis'
    """

    param: str
    expected: str
    holds: Callable[[dict], bool]

    def problem(self, params: dict) -> str | None:
        return None if self.holds(params) else self.expected


def check_params(owner: str, rules: dict[str, Rule], requirements: tuple[Requirement, ...], params: dict) -> None:
    """Check ``params`` against declared rules and requirements; raise :func:`param_error` on the first problem."""
    for name, rule in rules.items():
        rule.check(owner, name, params[name])
    for req in requirements:
        if req.problem(params):
            raise param_error(owner, req.param, req.expected, params[req.param])


_SAFE_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def safe_name(value: str) -> str | None:
    """A ``check`` for names that become file or folder names: ``None`` if safe, else what is expected.

    >>> safe_name("paper_sk120"), safe_name("../etc") is not None, safe_name("a/b") is not None
    (None, True, True)
    """
    if _SAFE_NAME.match(value) and ".." not in value and not value.startswith(".") and len(value) <= 100:
        return None
    return ("a name of at most 100 letters, digits, '_', '.' and '-' (it names files and folders: no '/', "
            "no '..', no leading '.')")


# ---------------------------------------------------------------------- model-file fields
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
        return f"{self.where}.{key}" if self.where and key else self.where or key

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


def seed_from(random_state) -> int:
    """One integer seed from None (numpy's global generator), an int, a RandomState or a Generator."""
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(2**32))
    if isinstance(random_state, Integral):
        return int(random_state)
    if random_state is None:
        return int(np.random.randint(2**32))
    if isinstance(random_state, np.random.RandomState):
        return int(random_state.randint(2**32))
    raise ValueError(f"random_state must be None, an int, a RandomState or a Generator; got {random_state!r}")
