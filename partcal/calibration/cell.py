"""The cell's description as the measurement types read it: what every section of the cell YAML shares (entry
names, the forms of an entry, ties between entries, vectors). Each type reads its own section
(:meth:`MeasurementType.read_section <partcal.calibration.measurement.MeasurementType.read_section>`): the planes
(:mod:`.plane_contacts`) and the points (:mod:`.fixed_points`)."""

from __future__ import annotations

import difflib
import re

import numpy as np

from .._yamlio import Section

FEATURE_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
"""An entry's name: letters, digits, ``_ . -``."""


def entry_form(sec: Section, forms: tuple) -> tuple[str, ...]:
    """The form whose keys ``sec`` uses (``()``: none); a key outside it is refused as unknown before a key of
    the form is missed, so that a typo is named (``offset`` for ``offset_mm``) and two forms do not mix."""
    form = next((keys for keys in forms if any(sec.has(k) for k in keys)), ())
    known = sorted(form or {k for keys in forms for k in keys})
    for key in sec.data:
        if key not in form:
            close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else "" if form else f" (known: {', '.join(known)})"
            of = f" beside {form[0]!r} (that form has {', '.join(form)}; one form per feature)" if form else ""
            sec.fail(sec.path(str(key)), f"unknown key{of}{hint}")
    return form


def named_entry(parent: Section, name) -> Section:
    """The section of a feature, its name checked (letters, digits, ``_ . -``)."""
    if not isinstance(name, str) or not FEATURE_NAME.match(name):
        parent.fail(parent.path(str(name)), f"a feature's name is letters, digits, '_', '.' or '-'; got {name!r}")
    return parent.section(name)


def check_ties(section: Section, cell: dict, key: str) -> None:
    """Refuse a ``key`` (``parallel_to``, ``distance_to``) naming itself, no feature of ``section``, or closing
    a cycle."""
    for name, spec in cell.items():
        other = spec.get(key)
        if other is None:
            continue
        where = f"{section.path(name)}.{key}"
        if other == name:
            section.fail(where, f"must name another feature than {name!r} itself")
        if other not in cell:
            section.fail(where, f"must name a feature of {section.where} ({', '.join(cell)}); got {other!r}")
        seen, at = [name], other
        while at is not None:
            if at in seen:
                section.fail(where, f"closes a cycle: {' -> '.join([*seen, at])}")
            seen.append(at)
            at = cell[at].get(key)


def unit_vector(sec: Section, key: str) -> list[float]:
    """A 3-vector of ``sec`` (finite, not zero) made unit length."""
    v = np.asarray(sec.get(key, "list", check=vector3_problem), dtype=float)
    norm = float(np.linalg.norm(v))
    if not norm > 1e-12:
        sec.fail(sec.path(key), f"must be a direction (a non-zero vector); got {v.tolist()}")
    return (v / norm).tolist()


def vector3_problem(value) -> str | None:
    """A ``check`` for :meth:`Section.get`: three finite numbers."""
    ok = len(value) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                                 for v in value)
    return None if ok else "a list of three finite numbers"


def finite_problem(value: float) -> str | None:
    return None if np.isfinite(value) else "a finite number"


def positive_problem(value: float) -> str | None:
    return None if np.isfinite(value) and value > 0 else "a finite number > 0"
