"""Types of measurement: one identification over whatever a cell measured.

A laser tracker gives 3-D points of the tool in its own frame. Most cells own other instruments: a
touch probe and a flat plate (the tip's distance to a plane is zero), a reference sphere or a nest
reached from many orientations (the tip is at one point each time), a ballbar or draw-wire (the
distance between two tips, or between the tip and a pivot). Each is a **measurement type**: one
class that reads its rows, declares its own unknowns (a plane's normal and offset, a point's
position), and gives its residuals and their derivatives from the chain's positions (and, where it
needs it, the tool's orientation). :data:`MEASUREMENT_TYPES` lists them; :func:`add_measurement_type`
adds one.

:func:`identify_measurements` stacks the residuals of every type present, each divided by its type's
stated noise (and multiplied by :data:`REFERENCE_NOISE_MM`, so that they read as millimetres of a
tracker), and fits the robot's parameters and the types' unknowns together with the rank rule and
Levenberg-Marquardt of :func:`~partcal.calibration.identification.identify`. The result is the same
:class:`~partcal.calibration.parameters.Identification`, the types' unknowns listed after the robot's.

What the data cannot identify is judged on consistent data: the Jacobian at the nominal robot with
the types' unknowns started from the nominal robot's own positions at the measured poses, so noise
or a misfit cannot make a null direction look merely weak. A uniform scale of the robot is such a
direction whenever nothing measures a length (planes and points whose positions are all unknown):
it is named (:data:`SCALE`), and the rank rule holds one length nominal.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

REFERENCE_NOISE_MM = 0.02
"""Residuals are weighted by this over their type's noise: a tracker point of 0.02 mm per axis weighs one."""

NEAR_MM = 20.0
"""A row whose target the nominal robot puts farther than this from what the row says (a touch from its plane,
a visit from its point's other visits) is refused as bad input: a robot's geometric errors are millimetres, so
the row names the wrong feature. (A distance is refused only by a factor, :data:`~partcal.calibration.tracker_points.UNIT_FACTOR`:
an unknown tool changes short distances by more than this.)"""

SCALE = "scale"
"""The name under which a uniform scale of the robot is reported when nothing in the data measures a length."""


@dataclass(frozen=True, eq=False)
class MeasurementRows:
    """Rows of measurements of any types, as a file gives them and the identification reads them.

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    types : tuple of str
        Each row's measurement type (a name of the table of types, or ``pose``: an end other rows refer to).
    ids : tuple of str
        Each row's name (the ``id`` column, or its 1-based data-row number).
    lines : tuple of int
        The line of each row in its file, as an editor shows it (for messages).
    source : str
        The file (or files) the rows came from.
    numbers : dict of str to ndarray (n,)
        Numeric columns (NaN where a row has none): ``x_meas``, ``distance_mm``, ``flush``, ..., in the
        contract's units.
    texts : dict of str to tuple of str
        Text columns ("" where empty): ``feature``, ``to``, ...
    payload_kg : ndarray, shape (n,), optional
    sources : tuple of str, optional
        Each row's file, when the rows come from several (``source`` names them all).
    name : str
        The data set's name (a file's stem by default).
    """

    q_deg: NDArray[np.float64]
    types: tuple[str, ...]
    ids: tuple[str, ...]
    lines: tuple[int, ...]
    source: str
    numbers: dict = field(default_factory=dict)
    texts: dict = field(default_factory=dict)
    payload_kg: NDArray[np.float64] | None = None
    sources: tuple[str, ...] | None = None
    name: str = "measurements"

    def __post_init__(self):
        q = np.asarray(self.q_deg, dtype=float)
        n = q.shape[0] if q.ndim == 2 else -1
        if n < 1 or not np.isfinite(q).all():
            raise DataError(f"Expected q_deg with shape (n, N), n >= 1, finite degrees, got shape {q.shape}")
        for what, values in (("types", self.types), ("ids", self.ids), ("lines", self.lines),
                             *self.texts.items()):
            if len(values) != n:
                raise DataError(f"Expected {what} with {n} entries (one per row of q_deg), got {len(values)}")
        numbers = {k: np.asarray(v, dtype=float) for k, v in self.numbers.items()}
        bad = next((k for k, v in numbers.items() if v.shape != (n,)), None)
        if bad is not None:
            raise DataError(f"Expected numbers[{bad!r}] with shape ({n},), got {numbers[bad].shape}")
        object.__setattr__(self, "q_deg", q)
        object.__setattr__(self, "numbers", numbers)
        object.__setattr__(self, "texts", {k: tuple(v) for k, v in self.texts.items()})
        for attr in ("types", "ids", "lines"):
            object.__setattr__(self, attr, tuple(getattr(self, attr)))

    def __len__(self) -> int:
        return self.q_deg.shape[0]

    def of(self, name: str) -> NDArray[np.intp]:
        """The indices of the rows of measurement type ``name``."""
        return np.flatnonzero(np.asarray(self.types, dtype=object) == name)

    def where(self, row: int) -> str:
        """``FILE:LINE`` of row ``row``, for messages."""
        return f"{self.source if self.sources is None else self.sources[row]}:{self.lines[row]}"

    def number(self, column: str, rows: NDArray[np.intp]) -> NDArray[np.float64]:
        """Column ``column`` at ``rows``, every value present and finite, else one :class:`DataError`."""
        values = self.numbers.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.types[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = np.asarray(values, dtype=float)[rows]
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            raise DataError(f"{self.where(rows[bad[0]])}: column {column!r}: a {self.types[rows[bad[0]]]} row needs "
                            f"a number here, got none")
        return out

    def text(self, column: str, rows: NDArray[np.intp]) -> list[str]:
        """Column ``column`` at ``rows``, every value given, else one :class:`DataError`."""
        values = self.texts.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.types[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = [values[i] for i in rows]
        for i, v in zip(rows, out):
            if not v:
                raise DataError(f"{self.where(i)}: column {column!r}: a {self.types[i]} row needs a name here, got "
                                "none")
        return out

    def take(self, rows) -> "MeasurementRows":
        """The rows ``rows`` (indices) as rows of their own; ``ids`` kept, so references resolve while both
        ends are among them."""
        rows = np.asarray(rows, dtype=np.intp)
        return dataclasses.replace(
            self, q_deg=self.q_deg[rows], types=tuple(self.types[i] for i in rows),
            ids=tuple(self.ids[i] for i in rows), lines=tuple(self.lines[i] for i in rows),
            numbers={k: np.asarray(v)[rows] for k, v in self.numbers.items()},
            texts={k: tuple(v[i] for i in rows) for k, v in self.texts.items()},
            payload_kg=None if self.payload_kg is None else self.payload_kg[rows],
            sources=None if self.sources is None else tuple(self.sources[i] for i in rows))


@dataclass(frozen=True, eq=False)
class Residuals:
    """A type's residuals (mm, before weighting) and what they depend on.

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
        ``d value / d`` the type's unknowns (:meth:`MeasurementType.unknowns`, in their order).
    tool_grad : ndarray, shape (m, 3), optional
        ``d value / d`` the robot's tool offset (flange frame, mm) beyond what reaches it through row ``rows_a``'s
        target: a point fixed on the flange (a further target, a camera) at ``tool_mm``'s distance from the tool
        point (:attr:`MeasurementType.tool_mm`).
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


@dataclass(frozen=True)
class Column:
    """A column the rows of a measurement type read (beside the joints).

    Attributes
    ----------
    unit : str
        Its unit: ``mm`` (a format's ``length_unit: m`` converts it), ``deg``, any other name, or ``""`` (a plain
        number, or a name).
    text : bool
        It holds names (a feature's, another row's id), not numbers.
    required : bool
        Every row of the type gives it (the reader refuses an empty cell, naming file, line and column).
    check : callable, optional
        ``check(value) -> str | None``: what a number must be (None: it is), for the reader's refusal.
    refers : str, optional
        The column names another row's ``id`` or an entry of this section of the cell (a distance's ``to``).
    """

    unit: str = ""
    text: bool = False
    required: bool = False
    check: Callable[[float], str | None] | None = None
    refers: str | None = None


class MeasurementType:
    """What every measurement type answers. A type is built from all rows and reads those of its own ``name``.

    What the road asks of a type is declared on its class, so that a new type is one file:

    - ``name``: its rows' value in the measurements file's ``measurement`` column;
    - ``columns``: the columns its rows read, each a :class:`Column` (unit, text, required, a value check; the
      reader of measurements files takes them from here), and ``unit``: the unit of its residuals and noise;
    - ``needs_orientation`` (its residuals read the tool's orientation) and ``fixes_frame`` (its rows fix the
      base frame: points measured in it); an instance may say either for its rows alone;
    - ``default_noise`` (its noise, in ``unit``, when the cell states none) and ``summary`` (one line for the
      report: what one row says);
    - ``cell_section`` and ``feature_column``: its section of the cell's description (``planes``, ``points``) and
      the column that names an entry of it; :meth:`read_section` reads the section, :meth:`given_section` says
      what a simulated cell knows of it; ``extra_sections``: further sections it reads (a camera's ``boards``,
      :meth:`read_extra_section`, :meth:`given_extra_section`);
    - optional hooks: ``simulate(truth, spec, rng, noise)`` (rows of a virtual robot: ``partcal simulate``) and
      ``candidates(robot, cell, count, rng)`` (rows to choose from: ``partcal plan --measurement``; with a keyword
      ``poses=``, at the cell's own poses: ``plan --candidates``), and
      ``plans_by = "image"`` when the plan chooses whole groups of rows (a camera's images), not rows;
    - :meth:`fit_notes`: what the fit's residuals say of some of its rows (a camera's image paired with the wrong
      joints), notes of the run.
    """

    name: ClassVar[str] = ""
    columns: ClassVar[dict[str, Column]] = {}
    reads: ClassVar[tuple[str, ...]] = ()
    needs_orientation: ClassVar[bool] = False
    fixes_frame: ClassVar[bool] = False
    unit: ClassVar[str] = "mm"
    default_noise: ClassVar[float] = 0.01
    summary: ClassVar[str] = ""
    cell_section: ClassVar[str | None] = None
    feature_column: ClassVar[str | None] = None
    extra_sections: ClassVar[tuple[str, ...]] = ()
    simulate: ClassVar[Callable | None] = None
    candidates: ClassVar[Callable | None] = None
    plans_by: ClassVar[str | None] = None

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if "columns" in cls.__dict__ and "reads" not in cls.__dict__:
            cls.reads = tuple(cls.columns)
        elif "reads" in cls.__dict__ and "columns" not in cls.__dict__:     # a type that names its columns alone
            cls.columns = {c: Column() for c in cls.reads}

    @classmethod
    def read_section(cls, sec) -> dict:
        """Its section of the cell's description (a :class:`partcal._yamlio.Section`), read and checked: by
        default each entry a name with nothing known of it (``NAME: {}``)."""
        out = {}
        for name in list(sec.data):
            entry = sec.section(name)
            entry.done()
            out[str(name)] = {}
        return out

    @classmethod
    def given_section(cls, true: dict, rng) -> dict:
        """What a simulated cell knows of the true entries ``true`` of its section (the cell YAML that
        ``partcal simulate`` writes): by default nothing (each unknown)."""
        return {name: {} for name in true}

    @classmethod
    def read_extra_section(cls, name: str, sec) -> dict:
        """A further section ``name`` of the cell (one of ``extra_sections``: a camera's boards beside its
        cameras), read as :meth:`read_section` reads the type's own."""
        return cls.read_section(sec)

    @classmethod
    def given_extra_section(cls, name: str, true: dict, rng) -> dict:
        """What a simulated cell knows of the true entries of its further section ``name``."""
        return cls.given_section(true, rng)

    @classmethod
    def files(cls, cell: dict, names, values) -> dict[str, str]:
        """The files the type writes beside an identified model (file name -> text), from the cell and the
        identified table's ``names`` and ``values`` (a camera's ``camera_info`` YAML). Default: none."""
        return {}

    def __init__(self, rows: MeasurementRows, index: NDArray[np.intp], cell: dict, noise: float):
        self.rows, self.index, self.cell, self.noise = rows, index, cell, float(noise)
        self.noise_stated = False
        self.suspicions: list[str] = []     # what :meth:`unknowns` found doubtful at the nominal robot (a known length)
        self.tool_mm = np.zeros(3)      # the model's tool offset (flange frame, mm), set before each residuals()

    @classmethod
    def build(cls, rows: MeasurementRows, cell: dict) -> "MeasurementType | None":
        """The type over ``rows`` (None when no row is of it), its rows checked; ``cell`` as
        :func:`partcal.data.measurement_rows.read_cell` gives them."""
        index = rows.of(cls.name)
        if index.size == 0:
            return None
        stated = (cell.get("noise") or {}).get(cls.name)
        measurement = cls(rows, index, cell, cls.default_noise if stated is None else stated)
        measurement.noise_stated = stated is not None
        return measurement

    def relative_weights(self, residuals: Residuals) -> NDArray[np.float64]:
        """Each residual's weight among the type's own (the rows' stated standard deviations; default all one):
        the type's noise sets their level against other types."""
        return np.ones(residuals.values.size)

    def stated_spread(self) -> float | None:
        """The standard deviation the rows state of themselves (in the type's unit; None: the type's noise if
        the cell states it, else nothing stated)."""
        return self.noise if self.noise_stated else None

    def follows_tool(self, name: str) -> bool:
        """Whether the unknown ``name`` is a parameter of the tool, held where the tool is (``tool: false``)."""
        return False

    def stands_for(self, names: list[str]) -> set[str]:
        """The robot's parameters (of ``names``, the table's) that this type's own unknowns stand for: what its rows
        cannot tell from them (a camera's pose in the cell and the base frame). Held nominal when every type
        present says so, so that the type's unknowns carry them (the rank rule would otherwise pick either).
        Default: none."""
        return set()

    def unknowns(self, positions: NDArray[np.float64], rotations: NDArray[np.float64]
                 ) -> tuple[list[tuple[str, str]], NDArray[np.float64]]:
        """The type's own unknowns ``(name, unit)`` and where their fit starts, from the targets' ``positions``
        (n, 3) mm and tool ``rotations`` (n, 3, 3) of every row at the nominal robot (consistent data). Two
        types declaring an unknown of one name share it (a pivot that is also a fixed point). Rows the nominal
        robot puts far from what they say (:data:`NEAR_MM`: a touch near no plane; a distance in metres) are
        refused here."""
        return [], np.zeros(0)

    def residuals(self, positions: NDArray[np.float64], rotations: NDArray[np.float64] | None,
                  u: NDArray[np.float64]) -> Residuals:
        """The residuals at the targets' ``positions`` (n, 3) and ``rotations`` of every row, and the
        unknowns ``u``."""
        raise NotImplementedError

    def scaled_lengths(self, start: NDArray[np.float64]) -> NDArray[np.float64]:
        """How the type's unknowns (at ``start``, in :meth:`unknowns`' order) change per unit of a uniform scale
        of the whole cell that leaves its rows' residuals as they are: a length by its own value (the default);
        the entries of unknowns that are not lengths are not read."""
        return start

    def moved(self, u: NDArray[np.float64], omega: NDArray[np.float64], shift: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        """How the type's unknowns ``u`` change, to first order, when the whole cell turns by the small rotation
        vector ``omega`` (radians) about the base frame's origin and shifts by ``shift`` (mm): a point turns and
        shifts with it, a plane's normal turns and its offset shifts. Default: unknowns that do not move."""
        return np.zeros_like(u)

    def notes(self) -> list[str]:
        """What this type can never identify, in words (for the run and the report)."""
        return []

    def fit_notes(self, residuals: Residuals) -> list[str]:
        """What the fit's ``residuals`` of this type say of some of its rows, in words (a camera's image whose pixels
        disagree with its pose's prediction): notes of the run, the fit then not called calibrated. Default: none."""
        return []

    def describe(self) -> str:
        """One line: the rows and what they touch."""
        return f"{self.index.size} {self.name} rows"


END_TYPE = "pose"
"""A row of joints alone: an end other rows' distances refer to; it has no residual of its own."""


# ---------------------------------------------------------------------- what several types share
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


def counted(cell, names) -> str:
    """``top 300, step 300, side 200``: each name and how many rows name it."""
    cell = list(cell)
    return ", ".join(f"{name} {cell.count(name)}" for name in names)


def points_moved(u: NDArray[np.float64], omega, shift) -> NDArray[np.float64]:
    """How points (x, y, z after x, y, z) move with a small turn ``omega`` and a shift of the cell."""
    return (np.cross(omega, u.reshape(-1, 3)) + shift).ravel()


def point_unknowns(name: str) -> list[tuple[str, str]]:
    return [(f"point {name}.{c}", "mm") for c in "xyz"]


