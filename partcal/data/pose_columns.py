"""What a pose measured beyond one point: the columns of further targets and of the tool's orientation.

A measurement row may carry further targets on the tool, each as wide columns with the target's
name after ``@`` (``x_meas@B, y_meas@B, z_meas@B``, optionally ``x_nom@B, ...``; the unsuffixed
columns are the primary target, named :data:`PRIMARY`), and the tool's orientation, ``rx_meas,
ry_meas, rz_meas`` and ``rx_nom, ry_nom, rz_nom``: intrinsic XYZ angles in degrees (``R = Rx Ry Rz``,
:func:`~partcal.robot.rotations.matrices_from_xyz_deg`). Here are the header rules for them and
the checks of their values; :mod:`partcal.data.measurements` reads and writes the file.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import DataError
from .formats import TARGET_COLUMN, TARGET_NAME, MeasurementFormat

PRIMARY = "A"
ORIENTATION_MEASURED = ("rx_meas", "ry_meas", "rz_meas")
ORIENTATION_NOMINAL = ("rx_nom", "ry_nom", "rz_nom")
ORIENTATION_RANGES = ((-180.0, 180.0), (-90.0, 90.0), (-180.0, 180.0))
_ORIENTATION_TARGET = re.compile(r"^r[xyz]_(?:meas|nom)@")


def suffixed(kind: str, target: str) -> list[str]:
    """A target's columns of one kind (``"meas"`` or ``"nom"``).

    >>> suffixed("meas", "B")
    ['x_meas@B', 'y_meas@B', 'z_meas@B']
    """
    return [f"{axis}_{kind}@{target}" for axis in "xyz"]


def orientation_problem(angles_deg: NDArray[np.float64]) -> tuple[int, int, str] | None:
    """The first angle out of its range, as ``(row, column, expected)``, or None.

    ``rx`` and ``rz`` lie in [-180, 180] degrees, ``ry`` in [-90, 90] (the
    principal range of intrinsic XYZ angles).
    """
    for k, (low, high) in enumerate(ORIENTATION_RANGES):
        bad = np.flatnonzero(~((angles_deg[:, k] >= low) & (angles_deg[:, k] <= high)))
        if bad.size:
            return int(bad[0]), k, f"[{low:g}, {high:g}] degrees (intrinsic XYZ angles)"
    return None


def target_columns(where: str, seen: dict[str, int], fmt: MeasurementFormat) -> dict[str, dict]:
    """Extra targets in header order: name -> ``{"meas": positions, "nom": positions or None}``.

    ``seen`` maps contract column names to their positions in the file.
    Refuses a bad or reserved target name, a target on an orientation column,
    a missing coordinate, nominal columns without measured ones, and nominal
    columns for some extra targets only (mixed target sets).
    """
    found: dict[str, set] = {}
    for col in seen:
        if _ORIENTATION_TARGET.match(col):
            raise DataError(f"{where}: column {fmt.file_column(col)!r}: the orientation is one per pose (the "
                            f"tool's): give {', '.join(ORIENTATION_MEASURED)} without a target name")
        m = TARGET_COLUMN.match(col)
        if m is None:
            continue
        target = m.group(2)
        if not TARGET_NAME.match(target) or target == PRIMARY:
            why = (f"{PRIMARY!r} names the unsuffixed columns (the primary target)" if target == PRIMARY
                   else "a target name is letters, digits and '_' (as in x_meas@B)")
            raise DataError(f"{where}: column {fmt.file_column(col)!r}: {why}")
        found.setdefault(target, set()).add(col)
    out: dict[str, dict] = {}
    for target, have in found.items():
        for kind in ("meas", "nom"):
            group = suffixed(kind, target)
            if (kind == "meas" or have & set(group)) and not set(group) <= have:
                missing = next(c for c in group if c not in seen)
                raise DataError(f"{where}: column {fmt.file_column(missing)!r} is missing (target {target} needs "
                                f"all of {', '.join(group)}{' when it has nominal columns' if kind == 'nom' else ''})")
        nominal = suffixed("nom", target)
        out[target] = {"meas": [seen[c] for c in suffixed("meas", target)],
                       "nom": [seen[c] for c in nominal] if set(nominal) <= have else None}
    with_nominal = [t for t, c in out.items() if c["nom"]]
    if with_nominal and len(with_nominal) < len(out):
        bare = next(t for t, c in out.items() if not c["nom"])
        raise DataError(f"{where}: column {fmt.file_column(f'x_nom@{bare}')!r} is missing: target "
                        f"{with_nominal[0]} has nominal columns, so every extra target needs them (or none does)")
    return out


def orientation_columns(where: str, seen: dict[str, int], fmt: MeasurementFormat, *, has_robot: bool) -> dict:
    """The measured and nominal orientation columns (``rot_meas``, ``rot_nom``: positions or None).

    Each triple is all or none; nominal ones need measured ones; measured
    ones need nominal ones unless a robot gives them (as for positions).
    """
    out = {}
    for key, group in (("rot_meas", ORIENTATION_MEASURED), ("rot_nom", ORIENTATION_NOMINAL)):
        present = [c for c in group if c in seen]
        if 0 < len(present) < 3:
            missing = next(c for c in group if c not in seen)
            raise DataError(f"{where}: column {fmt.file_column(missing)!r} is missing (give all of "
                            f"{', '.join(fmt.file_column(c) for c in group)} or none)")
        out[key] = [seen[c] for c in group] if present else None
    if out["rot_nom"] and not out["rot_meas"]:
        raise DataError(f"{where}: column {fmt.file_column('rx_meas')!r} is missing: the nominal orientation "
                        f"columns need the measured ones ({', '.join(ORIENTATION_MEASURED)})")
    if out["rot_meas"] and not out["rot_nom"] and not has_robot:
        raise DataError(f"{where}: columns {', '.join(ORIENTATION_NOMINAL)} are missing; give them, or a robot "
                        "model to compute the nominal orientation by forward kinematics")
    return out


def check_angles(path: Path, header: list[str], data: list, names: list[str], cols: list[int],
                 values: NDArray[np.float64]) -> None:
    """Refuse an orientation angle out of its range, naming the file, line, column and cell.

    ``names`` are the contract names of ``values``' columns (degrees), ``cols``
    their positions in the file, ``data`` the file's ``(line, cells)`` rows.
    """
    for contract in (ORIENTATION_MEASURED, ORIENTATION_NOMINAL):
        if contract[0] not in names:
            continue
        ks = [names.index(c) for c in contract]
        bad = orientation_problem(values[:, ks])
        if bad is not None:
            row, k, expected = bad
            number, cells = data[row]
            raise DataError(f"{path}:{number}: column {header[cols[ks[k]]]}: expected an angle in {expected}, "
                            f"got {cells[cols[ks[k]]].strip()!r}")


def checked_targets(measured: dict, nominal: dict, n: int) -> tuple[dict, dict]:
    """Extra targets of a record: valid names other than the primary's, (n, 3) positions, nominal for all or
    none. Returns clean copies of ``measured`` and ``nominal``."""
    out = []
    for attr, given in (("extra_measured_mm", measured), ("extra_nominal_mm", nominal)):
        checked = {}
        for name, arr in dict(given).items():
            if not isinstance(name, str) or not TARGET_NAME.match(name) or name == PRIMARY:
                raise DataError(f"Expected target names of letters, digits and '_' other than {PRIMARY!r} "
                                f"(the primary target) in {attr}, got {name!r}.")
            checked[name] = check_array(arr, f"{attr}[{name!r}]", columns=3)
            if checked[name].shape[0] != n:
                raise DataError(f"{attr}[{name!r}] has {checked[name].shape[0]} rows but q_deg has {n}")
        out.append(checked)
    if out[1] and set(out[1]) != set(out[0]):
        raise DataError(f"extra_nominal_mm must name the targets of extra_measured_mm ({sorted(out[0])}) or none; "
                        f"got {sorted(out[1])}")
    return out[0], out[1]


def checked_orientation(measured, nominal, n: int) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """Measured and nominal orientation of a record: both or neither, (n, 3) degrees within their ranges."""
    given = [a is not None for a in (measured, nominal)]
    if any(given) and not all(given):
        raise DataError("Expected measured_orientation_deg and nominal_orientation_deg both or neither, got "
                        f"only {'measured' if given[0] else 'nominal'}_orientation_deg.")
    if not any(given):
        return None, None
    out = []
    for attr, value in (("measured_orientation_deg", measured), ("nominal_orientation_deg", nominal)):
        arr = check_array(value, attr, columns=3)
        if arr.shape[0] != n:
            raise DataError(f"{attr} has {arr.shape[0]} rows but q_deg has {n}")
        bad = orientation_problem(arr)
        if bad is not None:
            row, k, expected = bad
            raise DataError(f"Expected {attr} within {expected}, got {arr[row, k]!r} in row {row} column {k}.")
        out.append(arr)
    return out[0], out[1]
