"""The table of measurement kinds, in one place: the built-in kinds and any added with
:func:`add_measurement_kind`; the kinds present in a set of rows (:func:`built_kinds`)."""

from __future__ import annotations

from ..errors import DataError
from .distances import DistanceKind
from .fixed_points import FixedPointKind
from .measurement import END_KIND, MeasurementKind, Rows
from .plane_contacts import PlaneKind
from .tracker_points import PointKind

MEASUREMENT_KINDS: dict[str, type[MeasurementKind]] = {k.name: k for k in (PointKind, PlaneKind, FixedPointKind,
                                                                          DistanceKind)}
"""The table of measurement kinds: the CSV's ``kind`` value -> its class; the built-in ones, then those added with
:func:`add_measurement_kind`."""


def add_measurement_kind(kind: type[MeasurementKind]) -> type[MeasurementKind]:
    """Register ``kind`` under its ``name`` (usable as a class decorator); a name taken is refused."""
    if not kind.name or kind.name == END_KIND or kind.name in MEASUREMENT_KINDS:
        raise ValueError(f"a measurement kind needs a name of its own; {kind.name!r} is empty or taken")
    MEASUREMENT_KINDS[kind.name] = kind
    return kind


def kind_names() -> tuple[str, ...]:
    """Every name a ``kind`` column may hold: the table's, and :data:`END_KIND`."""
    return (*MEASUREMENT_KINDS, END_KIND)


def built_kinds(rows: Rows, features: dict) -> list[MeasurementKind]:
    """The kinds present in ``rows``, in the table's order; a row of a kind the table does not list is refused."""
    known = set(kind_names())
    for i, k in enumerate(rows.kind):
        if k not in known:
            raise DataError(f"{rows.where(i)}: column 'kind': {k!r} is not a measurement kind; expected one of "
                            f"{', '.join(sorted(known))}")
    kinds = [k for k in (cls.build(rows, features) for cls in MEASUREMENT_KINDS.values()) if k is not None]
    if not kinds:
        raise DataError(f"{rows.source}: no row measures anything (every row is a {END_KIND!r} row)")
    return kinds
