"""The table of measurement types, in one place: the built-in types and any added with
:func:`add_measurement_type`; the types present in a set of rows (:func:`built_types`)."""

from __future__ import annotations

from ..errors import DataError
from .camera import CameraPoints
from .distances import Distances
from .fixed_points import FixedPoints
from .measurement import END_TYPE, MeasurementType, MeasurementRows
from .plane_contacts import PlaneContacts
from .tracker_points import TrackerPoints

MEASUREMENT_TYPES: dict[str, type[MeasurementType]] = {k.name: k for k in (TrackerPoints, PlaneContacts, FixedPoints,
                                                                          Distances, CameraPoints)}
"""The table of measurement types: the CSV's ``measurement`` value -> its class; the built-in ones, then those added with
:func:`add_measurement_type`."""


def add_measurement_type(measurement: type[MeasurementType]) -> type[MeasurementType]:
    """Register ``measurement_type`` under its ``name`` (usable as a class decorator); a name taken is refused."""
    if not measurement.name or measurement.name == END_TYPE or measurement.name in MEASUREMENT_TYPES:
        raise ValueError(f"a measurement type needs a name of its own; {measurement.name!r} is empty or taken")
    MEASUREMENT_TYPES[measurement.name] = measurement
    return measurement


def measurement_names() -> tuple[str, ...]:
    """Every name a ``measurement`` column may hold: the table's, and :data:`END_TYPE`."""
    return (*MEASUREMENT_TYPES, END_TYPE)


def built_types(rows: MeasurementRows, cell: dict) -> list[MeasurementType]:
    """The types present in ``rows``, in the table's order; a row of a type the table does not list is refused."""
    known = set(measurement_names())
    for i, k in enumerate(rows.types):
        if k not in known:
            raise DataError(f"{rows.where(i)}: column 'measurement': {k!r} is not a measurement type; expected one of "
                            f"{', '.join(sorted(known))}")
    measurements = [k for k in (cls.build(rows, cell) for cls in MEASUREMENT_TYPES.values()) if k is not None]
    if not measurements:
        raise DataError(f"{rows.source}: no row measures anything (every row is a {END_TYPE!r} row)")
    return measurements
