"""Kinds of measurement: one identification over whatever a cell measured.

A laser tracker gives 3-D points of the tool in its own frame. Most cells own other instruments: a
touch probe and a flat plate (the tip's distance to a plane is zero), a reference sphere or a nest
reached from many orientations (the tip is at one point each time), a ballbar or draw-wire (the
distance between two tips, or between the tip and a pivot). Each is a **measurement kind**: one
class that reads its rows, declares its own unknowns (a plane's normal and offset, a point's
position), and gives its residuals and their derivatives from the chain's positions (and, where it
needs it, the tool's orientation). :data:`MEASUREMENT_KINDS` lists them; :func:`add_measurement_kind`
adds one.

:func:`identify_measures` stacks the residuals of every kind present, each divided by its kind's
stated noise (and multiplied by :data:`REFERENCE_NOISE_MM`, so that they read as millimetres of a
tracker), and fits the robot's parameters and the kinds' unknowns together with the rank rule and
Levenberg-Marquardt of :func:`~partcal.calibration.identification.identify`. The result is the same
:class:`~partcal.calibration.parameters.Identification`, the kinds' unknowns listed after the robot's.

What the data cannot identify is judged on consistent data: the Jacobian at the nominal robot with
the kinds' unknowns started from the nominal robot's own positions at the measured poses, so noise
or a misfit cannot make a null direction look merely weak. A uniform scale of the robot is such a
direction whenever nothing measures a length (planes and points whose positions are all unknown):
it is named (:data:`SCALE`), and the rank rule holds one length nominal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

REFERENCE_NOISE_MM = 0.02
"""Residuals are weighted by this over their kind's noise: a tracker point of 0.02 mm per axis weighs one."""

NEAR_MM = 20.0
"""A row whose target the nominal robot puts farther than this from what the row says (a touch from its plane,
a visit from its point's other visits) is refused as bad input: a robot's geometric errors are millimetres, so
the row names the wrong feature. (A distance is refused only by a factor, :data:`~partcal.calibration.tracker_points.UNIT_FACTOR`:
an unknown tool changes short distances by more than this.)"""

SCALE = "scale"
"""The name under which a uniform scale of the robot is reported when nothing in the data measures a length."""


@dataclass(frozen=True, eq=False)
class Rows:
    """Every row of an identification's data, all kinds together, as the study layer hands them over.

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    kind : tuple of str
        Each row's kind (a name of :data:`MEASUREMENT_KINDS`, or ``pose``: an end other rows refer to).
    ids : tuple of str
        Each row's name (the ``id`` column, or its 1-based data-row number).
    lines : tuple of int
        The line of each row in its file (for messages).
    source : str
        The file (or files) the rows came from.
    numbers : dict of str to ndarray (n,)
        Numeric columns (NaN where a row has none): ``x_meas``, ``distance_mm``, ``flush``, ...
    texts : dict of str to tuple of str
        Text columns ("" where empty): ``feature``, ``to``, ...
    payload_kg : ndarray, shape (n,), optional
    sources : tuple of str, optional
        Each row's file, when the rows come from several (``source`` names them all).
    """

    q_deg: NDArray[np.float64]
    kind: tuple[str, ...]
    ids: tuple[str, ...]
    lines: tuple[int, ...]
    source: str
    numbers: dict = field(default_factory=dict)
    texts: dict = field(default_factory=dict)
    payload_kg: NDArray[np.float64] | None = None
    sources: tuple[str, ...] | None = None

    def __len__(self) -> int:
        return self.q_deg.shape[0]

    def of(self, kind: str) -> NDArray[np.intp]:
        """The indices of the rows of ``kind``."""
        return np.flatnonzero(np.asarray(self.kind, dtype=object) == kind)

    def where(self, row: int) -> str:
        """``FILE:LINE`` of row ``row``, for messages."""
        return f"{self.source if self.sources is None else self.sources[row]}:{self.lines[row]}"

    def number(self, column: str, rows: NDArray[np.intp]) -> NDArray[np.float64]:
        """Column ``column`` at ``rows``, every value present and finite, else one :class:`DataError`."""
        values = self.numbers.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.kind[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = np.asarray(values, dtype=float)[rows]
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            raise DataError(f"{self.where(rows[bad[0]])}: column {column!r}: a {self.kind[rows[bad[0]]]} row needs a "
                            f"number here, got none")
        return out

    def text(self, column: str, rows: NDArray[np.intp]) -> list[str]:
        """Column ``column`` at ``rows``, every value given, else one :class:`DataError`."""
        values = self.texts.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.kind[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = [values[i] for i in rows]
        for i, v in zip(rows, out):
            if not v:
                raise DataError(f"{self.where(i)}: column {column!r}: a {self.kind[i]} row needs a name here, got "
                                "none")
        return out

    def take(self, rows) -> "Rows":
        """The rows ``rows`` (indices) as rows of their own; ``ids`` kept, so references resolve while both
        ends are among them."""
        rows = np.asarray(rows, dtype=np.intp)
        return Rows(self.q_deg[rows], tuple(self.kind[i] for i in rows), tuple(self.ids[i] for i in rows),
                    tuple(self.lines[i] for i in rows), self.source,
                    {k: np.asarray(v)[rows] for k, v in self.numbers.items()},
                    {k: tuple(v[i] for i in rows) for k, v in self.texts.items()},
                    None if self.payload_kg is None else self.payload_kg[rows],
                    None if self.sources is None else tuple(self.sources[i] for i in rows))


@dataclass(frozen=True, eq=False)
class Residuals:
    """A kind's residuals (mm, before weighting) and what they depend on.

    Attributes
    ----------
    values : ndarray, shape (m,)
    rows_a : ndarray of int, shape (m,)
        The row whose target each residual reads (an index into the identification's rows); -1: none.
    grad_a : ndarray, shape (m, 3)
        ``d value / d position`` of that row's target.
    rows_b, grad_b : the same for a second row (distances), or None.
    turn_grad : ndarray, shape (m, 3), optional
        ``d value / d turn`` of row ``rows_a``'s tool (a small rotation vector in the base frame, radians).
    scaled : ndarray of bool, shape (m,), optional
        The residuals that are lengths (they scale with the cell; None: all). An angle is not.
    turning : ndarray of bool, shape (m,), optional
        The residuals that come as x, y, z triples of a vector that turns with the cell (a point's miss, an
        orientation's; None: none). A distance to a plane or between two points does not turn.
    du : ndarray, shape (m, k)
        ``d value / d`` the kind's unknowns (:meth:`MeasurementKind.unknowns`, in their order).
    tool_grad : ndarray, shape (m, 3), optional
        ``d value / d`` the robot's tool offset (flange frame, mm) beyond what reaches it through row ``rows_a``'s
        target: a point fixed on the flange (a further target, a camera) at ``tool_mm``'s distance from the tool
        point (:attr:`MeasurementKind.tool_mm`).
    """

    values: NDArray[np.float64]
    rows_a: NDArray[np.intp]
    grad_a: NDArray[np.float64]
    du: NDArray[np.float64]
    rows_b: NDArray[np.intp] | None = None
    grad_b: NDArray[np.float64] | None = None
    turn_grad: NDArray[np.float64] | None = None
    scaled: NDArray[np.bool_] | None = None
    turning: NDArray[np.bool_] | None = None
    tool_grad: NDArray[np.float64] | None = None


class MeasurementKind:
    """What every measurement kind answers. A kind is built from all rows and reads those of its own ``name``.

    Class attributes: ``name`` (the CSV's ``kind`` value), ``reads`` (the columns its rows read beside the
    joints), ``needs_orientation`` (whether its residuals read the tool's orientation; an instance may say
    so for its rows alone), ``fixes_frame`` (whether its rows fix the base frame: points measured in it; an
    instance may say so for its rows alone), ``default_noise_mm`` (its stated noise when the cell states none),
    ``summary`` (one line for the report: what one row says).
    """

    name: ClassVar[str] = ""
    reads: ClassVar[tuple[str, ...]] = ()
    needs_orientation: ClassVar[bool] = False
    fixes_frame: ClassVar[bool] = False
    default_noise_mm: ClassVar[float] = 0.01
    summary: ClassVar[str] = ""

    def __init__(self, rows: Rows, index: NDArray[np.intp], features: dict, noise_mm: float):
        self.rows, self.index, self.features, self.noise_mm = rows, index, features, float(noise_mm)
        self.noise_stated = False
        self.tool_mm = np.zeros(3)      # the model's tool offset (flange frame, mm), set before each residuals()

    @classmethod
    def build(cls, rows: Rows, features: dict) -> "MeasurementKind | None":
        """The kind over ``rows`` (None when no row is of it), its rows checked; ``features`` as
        :func:`partcal.data.observations.read_features` gives them."""
        index = rows.of(cls.name)
        if index.size == 0:
            return None
        stated = (features.get("noise_mm") or {}).get(cls.name)
        kind = cls(rows, index, features, cls.default_noise_mm if stated is None else stated)
        kind.noise_stated = stated is not None
        return kind

    def relative_weights(self, residuals: Residuals) -> NDArray[np.float64]:
        """Each residual's weight among the kind's own (the rows' stated standard deviations; default all one):
        the kind's noise sets their level against other kinds."""
        return np.ones(residuals.values.size)

    def stated_spread(self) -> float | None:
        """The standard deviation the rows state of themselves (in the kind's unit; None: the kind's noise if
        the cell states it, else nothing stated)."""
        return self.noise_mm if self.noise_stated else None

    def follows_tool(self, name: str) -> bool:
        """Whether the unknown ``name`` is a parameter of the tool, held where the tool is (``tool: false``)."""
        return False

    def unknowns(self, positions: NDArray[np.float64], rotations: NDArray[np.float64]
                 ) -> tuple[list[tuple[str, str]], NDArray[np.float64]]:
        """The kind's own unknowns ``(name, unit)`` and where their fit starts, from the targets' ``positions``
        (n, 3) mm and tool ``rotations`` (n, 3, 3) of every row at the nominal robot (consistent data). Two
        kinds declaring an unknown of one name share it (a pivot that is also a fixed point). Rows the nominal
        robot puts far from what they say (:data:`NEAR_MM`: a touch near no plane; a distance in metres) are
        refused here."""
        return [], np.zeros(0)

    def residuals(self, positions: NDArray[np.float64], rotations: NDArray[np.float64] | None,
                  u: NDArray[np.float64]) -> Residuals:
        """The residuals at the targets' ``positions`` (n, 3) and ``rotations`` of every row, and the
        unknowns ``u``."""
        raise NotImplementedError

    def scaled_lengths(self, start: NDArray[np.float64]) -> NDArray[np.float64]:
        """How the kind's unknowns (at ``start``, in :meth:`unknowns`' order) change per unit of a uniform scale
        of the whole cell that leaves its rows' residuals as they are: a length by its own value (the default);
        the entries of unknowns that are not lengths are not read."""
        return start

    def moved(self, u: NDArray[np.float64], omega: NDArray[np.float64], shift: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        """How the kind's unknowns ``u`` change, to first order, when the whole cell turns by the small rotation
        vector ``omega`` (radians) about the base frame's origin and shifts by ``shift`` (mm): a point turns and
        shifts with it, a plane's normal turns and its offset shifts. Default: unknowns that do not move."""
        return np.zeros_like(u)

    def notes(self) -> list[str]:
        """What this kind can never identify, in words (for the run and the report)."""
        return []

    def describe(self) -> str:
        """One line: the rows and what they touch."""
        return f"{self.index.size} {self.name} rows"


END_KIND = "pose"
"""A row of joints alone: an end other rows' distances refer to; it has no residual of its own."""


@dataclass(frozen=True, eq=False)
class Measured:
    """What :meth:`KinematicModel.fit <partcal.models.kinematic.KinematicModel.fit>` identifies from instead
    of position errors: rows of any kinds and the cell's features."""

    rows: Rows
    features: dict = field(default_factory=dict)


# ---------------------------------------------------------------------- what several kinds share
def unit_rows(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Three residuals per row: their rows' repeat pattern and the unit gradients."""
    return np.repeat(np.arange(n), 3), np.tile(np.eye(3), (n, 1))


def worst_of(values: NDArray[np.float64], beyond: NDArray[np.bool_]) -> tuple[int, int] | None:
    """The index of the largest of ``values`` where ``beyond`` holds, and how many hold (what a refusal names:
    the worst row and the count); None where none does."""
    far = np.flatnonzero(beyond)
    return (int(far[np.argmax(values[far])]), int(far.size)) if far.size else None


def largest_turn_deg(rotations: NDArray[np.float64]) -> float:
    """The largest angle (degrees) between the first of ``rotations`` (n, 3, 3) and the others."""
    cos = (np.einsum("ij,nij->n", rotations[0], rotations[1:]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max(initial=0.0))


def counted(features, names) -> str:
    """``top 300, step 300, side 200``: each name and how many rows name it."""
    features = list(features)
    return ", ".join(f"{name} {features.count(name)}" for name in names)


def points_moved(u: NDArray[np.float64], omega, shift) -> NDArray[np.float64]:
    """How points (x, y, z after x, y, z) move with a small turn ``omega`` and a shift of the cell."""
    return (np.cross(omega, u.reshape(-1, 3)) + shift).ravel()


def point_unknowns(name: str) -> list[tuple[str, str]]:
    return [(f"point {name}.{c}", "mm") for c in "xyz"]


