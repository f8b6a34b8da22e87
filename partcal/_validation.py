"""Boundary checks: turn user input into clean arrays, or raise with what was expected.

Every public entry point validates here once; the numerical core trusts its
inputs. Messages follow one format, naming the parameter, what was expected
and what was got.
"""

from __future__ import annotations

import re
from numbers import Integral, Real
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import DataError, PartcalError


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


def param_error(owner: str, name: str, expected: str, got: Any) -> PartcalError:
    """The one message format for a bad parameter.

    >>> str(param_error("ErrorModel", "degree", "an int in [1, 8]", 0))
    "The 'degree' parameter of ErrorModel must be an int in [1, 8]. Got 0 instead."
    """
    return PartcalError(f"The {name!r} parameter of {owner} must be {expected}. Got {got!r} instead.")


def check_int(owner: str, name: str, value: Any, low: int, high: int | None = None) -> int:
    """Return ``value`` if it is an int in ``[low, high]``, else raise :func:`param_error`."""
    ok = isinstance(value, Integral) and not isinstance(value, bool)
    if not ok or value < low or (high is not None and value > high):
        rng = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise param_error(owner, name, f"an int in {rng}" if high is not None else f"an int {rng}", value)
    return int(value)


def check_real(
    owner: str, name: str, value: Any, low: float | None = None, high: float | None = None,
    *, low_open: bool = False,
) -> float:
    """Return ``value`` as float if it is a finite real within the bounds, else raise."""
    ok = isinstance(value, Real) and not isinstance(value, bool) and np.isfinite(value)
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value <= high
    if not ok:
        lo = "(" if low_open else "["
        rng = f"{lo}{low if low is not None else '-inf'}, {high if high is not None else 'inf'}]"
        raise param_error(owner, name, f"a real number in {rng}", value)
    return float(value)


def check_choice(owner: str, name: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise :func:`param_error`."""
    if not isinstance(value, str) or value not in choices:
        raise param_error(owner, name, "one of " + ", ".join(repr(c) for c in choices), value)
    return value


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
