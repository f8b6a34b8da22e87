"""Experiment design for kinematic identification: observability indices and D-optimal pose selection.

Which poses to measure decides how well the parameters of
:mod:`partcal.models.kinematic` can be identified. Everything here works on
the identification Jacobian ``J`` (``d positions / d parameters``, one block of
three rows per pose) at the nominal parameters:

- **indices** of the literature from the singular values ``s_1 >= ... >= s_L``
  of the scaled Jacobian: O1 = ``(s_1 ... s_L)^(1/L) / sqrt(m)`` for ``m``
  poses (Borm and Menq 1991), the condition number ``s_1 / s_L`` (Driels and
  Pathre 1990), the smallest singular value ``s_L`` (Nahvi, Hollerbach and
  Hayward 1994) and the noise amplification ``s_L^2 / s_1`` (Nahvi and
  Hollerbach 1996). Parameters have different units, so the columns are scaled
  first: a length stays in mm, an angle is counted as the arc it sweeps at the
  robot's reach (mm), so a column means "mm of tool motion per mm of
  parameter" for both (:func:`parameter_scales`).
- **predicted uncertainty** for a tracker noise ``sigma`` (mm, per
  coordinate): the parameter covariance ``sigma^2 (J^T J)^-1``, and from it
  the standard deviation of the identified robot's position anywhere.
- **D-optimal selection**: Mitchell's DETMAX exchange, which maximises
  ``det(J^T J)`` over subsets of a candidate pool; the result never has a
  smaller determinant than the start.
- **how far from the best any design can be**: the approximate (continuous)
  I-optimal design over the candidates, whose value bounds from below the
  predicted mean squared position error of every ``n``-pose design
  (:func:`i_optimal_bound`).

The Jacobian comes from :func:`model_jacobian` for a :class:`PlannedModel`
(the options of ``kind: kinematic``: base, tool, compliance, joint harmonics,
payload), the one place that says which kinematic model is planned for.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from .._validation import seed_from
from ..errors import PartcalError
from ..robot.kinematics import Robot
from .joint_errors import GRAVITY_M_S2, JointErrors, compliance_problem, harmonics_problem
from .chain import identification_jacobian
from .fit import held_still
from .identification import Extra, point_rows
from .parameters import nominal_values, parameter_names, PARAMETRIZATIONS, resolved_parametrization
from .chain import model_jacobian as kinematic_jacobian
from .stacked import StackedProblem
from .tracker_points import TrackerPoints

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- the planned model
@dataclass(frozen=True)
class PlannedModel:
    """Which kinematic model a pose set is planned for: the options of ``kind: kinematic``.

    Attributes
    ----------
    base, tool : bool
        Whether the base pose and the tool offset are identified.
    compliance : tuple of int
        1-based joints that yield under gravity (:mod:`partcal.calibration.joint_errors`).
    joint_harmonics : int or tuple of int
        Harmonics of every joint's transmission error, or one count per joint.
    payload_kg : float
        The payload the measurement carries at the tool point (kg). A plan is
        at one payload, and at one payload, zero or not, a compliance is not
        identifiable (it is the tool point's share of the sags, which the
        lumped masses' sags carry; only data at a second payload separate it):
        only the sags are planned for, whatever the payload.

    parametrization : {"auto", "dh", "complete"}
        The geometric parameters (:class:`~partcal.models.kinematic.KinematicModel`'s;
        ``auto``: ``dh`` for DH rows, ``complete`` for a URDF's chain).

    Several targets (one tool offset per target) will be one more field here.
    """

    base: bool = True
    tool: bool = True
    compliance: tuple[int, ...] = ()
    joint_harmonics: int | tuple[int, ...] = 0
    payload_kg: float = 0.0
    parametrization: str = "auto"

    def __post_init__(self):
        for name in ("compliance", "joint_harmonics"):          # lists as tuples: the model is a value
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))

    def check(self, robot: Robot) -> "PlannedModel":
        """Refuse options that do not fit ``robot`` (one line naming the option); returns self."""
        for name, problem in (("compliance", compliance_problem), ("joint_harmonics", harmonics_problem)):
            value = getattr(self, name)
            expected = problem(list(value) if isinstance(value, tuple) else value, robot.n_joints)
            if expected is not None:
                raise PartcalError(f"the planned model's {name} must be {expected} for {robot.name}; got {value!r}")
        if not (math.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise PartcalError(f"the planned model's payload_kg must be a number >= 0 (kg); got {self.payload_kg!r}")
        if self.parametrization not in ("auto", *PARAMETRIZATIONS):
            raise PartcalError(f"the planned model's parametrization must be auto, dh or complete; got "
                               f"{self.parametrization!r}")
        return self

    def parametrization_for(self, robot: Robot) -> str:
        """The parametrization planned for on ``robot`` (``auto`` resolved)."""
        return resolved_parametrization(self.parametrization, robot)

    def joint_errors(self, robot: Robot) -> JointErrors | None:
        """The joint errors planned for (None without)."""
        errors = JointErrors.for_robot(robot, list(self.compliance), self.joint_harmonics)
        return None if errors.empty else errors

    def describe(self, robot: Robot) -> str:
        """``DH with base and tool; compliance of joints 2, 3 (payload 0 kg); 2 harmonics per joint``."""
        flags = [name for name, flag in (("base", self.base), ("tool", self.tool)) if flag]
        kind = "DH" if self.parametrization_for(robot) == "dh" else "complete"
        parts = [kind + (" with " + " and ".join(flags) if flags else "")]
        if self.compliance:
            parts.append(f"compliance of joints {', '.join(map(str, self.compliance))} "
                         f"(payload {self.payload_kg:g} kg)")
        counts = JointErrors.for_robot(robot, (), self.joint_harmonics).harmonics
        if any(counts):
            parts.append(f"harmonics {list(counts)}" if len(set(counts)) > 1 else f"{counts[0]} harmonics per joint")
        return "; ".join(parts)


DH = PlannedModel()         # the geometry, with base and tool: what a plan is for unless told


def model_parameters(robot: Robot, model: PlannedModel = DH) -> tuple[list[tuple[str, str]], NDArray[np.float64]]:
    """``(name, unit)`` of the planned model's parameters and their nominal values, shape ``(P,)``.

    The one place that says which kinematic model is planned for (DH rows, tool, base, then the joint
    errors of ``model``); :func:`model_jacobian` and :func:`parameter_scales` read it.
    """
    errors, par = model.joint_errors(robot), model.parametrization_for(robot)
    return parameter_names(robot, errors, par), nominal_values(robot, errors, par)


def model_jacobian(robot: Robot, q_deg: NDArray[np.float64], model: PlannedModel = DH
                   ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The identification Jacobian at the nominal parameters and the mask of parameters asked for.

    Parameters
    ----------
    robot : Robot
    q_deg : ndarray, shape (n, N)
        Joint angles, degrees.
    model : PlannedModel
        The model planned for (the kinematic model's own Jacobian, joint errors included, at
        ``model.payload_kg``).

    Returns
    -------
    jac : ndarray, shape (3 n, P)
        ``d p / d parameters`` (mm per mm, mm per degree, ...); rows run over poses, then x, y, z.
    wanted : ndarray of bool, shape (P,)
    """
    names, values = model_parameters(robot, model)
    errors, par = model.joint_errors(robot), model.parametrization_for(robot)
    q_deg = held_still(np.asarray(q_deg, dtype=float))       # a held joint's jitter identifies nothing (as in a fit)
    if errors is None:
        jac = identification_jacobian(robot, q_deg, values, par)[1]
    else:
        # one payload: a compliance is a sag at the tool point like the masses' ones, not identifiable (its column
        # held at zero, as the identification does: KinematicModel.fit); only data at two payloads separate it
        jac = kinematic_jacobian(robot, errors, q_deg, values, np.zeros(len(q_deg)), par)[1]
    wanted = np.array([(model.tool or not n.startswith("tool.")) and (model.base or not n.startswith("base."))
                       for n, _ in names])
    return jac, wanted


def parameter_scales(robot: Robot, model: PlannedModel = DH) -> NDArray[np.float64]:
    """Column scales that make every parameter a length, shape ``(P,)``.

    ``L`` is the robot's reach (mm). A length stays in mm (scale 1); an angle
    counts as the arc it sweeps at the reach, ``180 / (pi L)``; a sag (deg/m)
    as the arc at the reach of its deflection at a lever of ``L``,
    ``180 / (pi L) * 1000 / L``; a compliance (deg/(N m)) as the sag of one kg,
    that over ``g``. Other units keep them (scale 1).

    >>> from partcal.robot import load_robot
    >>> s = parameter_scales(load_robot("universal_robots_ur10"))
    >>> float(s[1]), round(float(s[0]) * np.pi / 180 * load_robot("universal_robots_ur10").reach_mm, 12)
    (1.0, 1.0)
    """
    arc = 180.0 / (np.pi * robot.reach_mm)
    sag = arc * 1000.0 / robot.reach_mm
    per_unit = {"deg": arc, "deg/m": sag, "deg/(N m)": sag / GRAVITY_M_S2}
    return np.array([per_unit.get(unit, 1.0) for _, unit in model_parameters(robot, model)[0]])


def identifiable(jac: NDArray[np.float64], wanted: NDArray[np.bool_], rcond: float = 1e-6) -> NDArray[np.intp]:
    """Indices of the parameters a Jacobian ``(3 n, P)`` identifies: the first of each group of equivalent ones.

    The rank is the kinematic fit's rule (singular values of the unit-column
    Jacobian above ``rcond`` times the largest). Which parameters stand for a
    group that positions cannot separate (the first joint's offset and the
    base's turn about z, the ``d`` of parallel axes, a sag and a first
    harmonic of its joint) is decided in the order of the parameter table
    (DH rows, tool, base, then the joint errors), so it does not depend on the
    poses: indices of different pose sets are over the same parameters.
    """
    norms = np.linalg.norm(jac, axis=0)
    candidates = np.flatnonzero(wanted & (norms > 1e-12 * max(norms.max(), 1e-300)))
    if candidates.size == 0:
        return candidates
    unit = jac[:, candidates] / norms[candidates]
    gram = unit.T @ unit
    floor = rcond**2 * np.linalg.eigvalsh(gram)[-1]          # (rcond s_1)^2 in eigenvalues of J^T J
    kept: list[int] = []
    for k in range(candidates.size):
        trial = kept + [k]
        if np.linalg.eigvalsh(gram[np.ix_(trial, trial)])[0] > floor:
            kept = trial
    return candidates[kept]


# ---------------------------------------------------------------------- several targets
@dataclass(frozen=True)
class TargetIdentifiability:
    """What the primary target's positions identify, against all targets (and the orientation).

    Attributes
    ----------
    one : tuple of str
        Parameters of the one-target table (DH rows, tool, base) the primary target identifies.
    one_total : int
        Size of that table.
    all : tuple of str
        Parameters of the table with one offset per target (and the probe's turn) that all the
        measurements identify.
    all_total : int
    gained : tuple of str
        Parameters of the one-target table identifiable from all, not from one. Parameters that
        positions cannot tell apart form groups; a group is represented by its first parameter in
        the table's order (as in :func:`identifiable`), so these name the groups that grew.
    """

    one: tuple[str, ...]
    one_total: int
    all: tuple[str, ...]
    all_total: int
    gained: tuple[str, ...]

    @property
    def all_of_one(self) -> int:
        """How many parameters of the one-target table all the measurements identify."""
        return len(self.one) + len(self.gained)

    def text(self) -> str:
        return (f"identifiable from the primary target: {len(self.one)} of {self.one_total} parameters; from all "
                f"targets: {len(self.all)} of {self.all_total} ({self.all_of_one} of the same {self.one_total})" +
                (f"; made identifiable: {', '.join(self.gained)}" if self.gained else ""))


def target_identifiability(robot: Robot, q_deg: NDArray[np.float64], tools_mm: dict, *, orientation: bool = False,
                           base: bool = True, tool: bool = True, rcond: float = 1e-6) -> TargetIdentifiability:
    """Which parameters poses ``q_deg`` identify from one target, and from targets at offsets ``tools_mm``.

    Parameters
    ----------
    robot : Robot
        The nominal robot; its ``tool_mm`` is the primary target.
    q_deg : ndarray, shape (n, N)
    tools_mm : dict of str to array-like (3,)
        The extra targets' offsets in the flange frame, mm.
    orientation : bool
        Whether the orientation is measured too (weighted as in the identification).

    Examples
    --------
    >>> from partcal.robot import load_robot
    >>> ur10 = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    >>> q = np.random.default_rng(0).uniform(-170, 170, (20, 6))
    >>> found = target_identifiability(ur10, q, {"B": [100, 0, 90], "C": [-40, 90, 90]})
    >>> len(found.one), found.one_total, len(found.all), found.all_total
    (23, 33, 31, 39)
    >>> found.gained            # the wrist's last offsets and the tool, which one point leaves to others
    ('a[5]', 'alpha[5]', 'theta[6]', 'tool.x', 'tool.y', 'tool.z')
    """
    jac, wanted = model_jacobian(robot, q_deg, PlannedModel(base=base, tool=tool))
    one = identifiable(jac, wanted, rcond)
    flange = robot.forward(q_deg)[:, :3, :3]
    tools = {name: np.asarray(t, dtype=float) for name, t in tools_mm.items()}
    extra = Extra(tools, {name: robot.replace(tool_mm=t).positions(q_deg) for name, t in tools.items()},
                  flange if orientation else None)
    rows, cell = point_rows(q_deg, robot.positions(q_deg), extra)
    points = TrackerPoints.build(rows, cell)
    problem = StackedProblem(robot, None, rows, [points], np.zeros(len(rows)), "dh")
    jac_all = problem(problem.start)[1]
    wanted_all = np.concatenate([wanted, [tool or not points.follows_tool(name) for name, _ in problem.names]])
    found = identifiable(jac_all, wanted_all, rcond)
    names = [n for n, _ in model_parameters(robot)[0]] + [n for n, _ in problem.names]
    gained = sorted(set(found[found < wanted.size]) - set(one))
    return TargetIdentifiability(tuple(names[i] for i in one), int(wanted.sum()), tuple(names[i] for i in found),
                                 int(wanted_all.sum()), tuple(names[i] for i in gained))


# ---------------------------------------------------------------------- indices
@dataclass(frozen=True)
class Indices:
    """Observability indices of a pose set for a parameter set.

    Attributes
    ----------
    o1 : float
        Borm and Menq's O1, the geometric mean of the singular values over ``sqrt(n_poses)``.
    condition : float
        Largest over smallest singular value (``inf`` when the smallest is 0).
    smallest : float
        The smallest singular value (mm per mm).
    noise_amplification : float
        Nahvi and Hollerbach's index, ``smallest^2 / largest``.
    n_poses, n_parameters : int
    """

    o1: float
    condition: float
    smallest: float
    noise_amplification: float
    n_poses: int
    n_parameters: int

    def text(self) -> str:
        """One line: ``O1 ..., condition ..., smallest singular value ..., noise amplification ...``."""
        return (f"O1 {self.o1:.4g}, condition number {self.condition:.4g}, smallest singular value "
                f"{self.smallest:.4g}, noise amplification {self.noise_amplification:.4g} "
                f"({self.n_parameters} parameters, {self.n_poses} poses)")

    def to_dict(self) -> dict:
        return {"o1": self.o1, "condition": self.condition, "smallest": self.smallest,
                "noise_amplification": self.noise_amplification, "n_poses": self.n_poses,
                "n_parameters": self.n_parameters}


def indices_from_singular(singular: NDArray[np.float64], n_poses: int) -> Indices:
    """The four indices from the singular values of a scaled Jacobian (any order) of ``n_poses`` poses.

    Singular values below ``1e-12`` of the largest are rounding noise and count as zero.
    """
    s = np.sort(np.asarray(singular, dtype=float))[::-1]
    if s.size:
        s[s <= 1e-12 * s[0]] = 0.0          # rounding noise of a rank-deficient matrix counts as zero
    if s.size == 0:
        return Indices(0.0, np.inf, 0.0, 0.0, n_poses, 0)
    small, large = max(float(s[-1]), 0.0), float(s[0])
    with np.errstate(divide="ignore"):
        o1 = float(np.exp(np.mean(np.log(np.maximum(s, 0.0))))) / np.sqrt(n_poses)
    return Indices(o1, large / small if small > 0 else np.inf, small, small**2 / large if large > 0 else 0.0,
                   n_poses, int(s.size))


def indices(jac_scaled: NDArray[np.float64], n_poses: int) -> Indices:
    """The indices of a scaled Jacobian ``(3 n, L)`` (columns: the parameters considered)."""
    return indices_from_singular(np.linalg.svd(jac_scaled, compute_uv=False), n_poses)


# ---------------------------------------------------------------------- predicted uncertainty
def parameter_covariance(jac: NDArray[np.float64], noise_mm: float) -> NDArray[np.float64]:
    """``noise_mm^2 (J^T J)^-1`` for a full-rank Jacobian ``(3 n, L)`` in parameter units, shape ``(L, L)``.

    ``noise_mm``: standard deviation of each measured coordinate, mm.
    """
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    with np.errstate(divide="ignore"):
        inv = np.where(s > 0, 1.0 / s**2, np.inf)
    return noise_mm**2 * (vt.T * inv) @ vt


def position_std(blocks: NDArray[np.float64], covariance: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard deviation (3-D, ``sqrt`` of the trace) of the identified position at each pose.

    ``blocks`` are the Jacobian rows of the poses, ``(m, 3, L)``; returns ``(m,)`` mm.
    """
    return np.sqrt(np.maximum(np.einsum("mik,kl,mil->m", blocks, covariance, blocks), 0.0))


# ---------------------------------------------------------------------- DETMAX
@dataclass(frozen=True)
class ExchangeResult:
    """Outcome of :func:`detmax`.

    Attributes
    ----------
    indices : ndarray of int, shape (n,)
        The chosen candidates, sorted.
    logdet, start_logdet : float
        ``log det(J^T J + eps I)`` of the result and of the start.
    exchanges : int
        Accepted excursions.
    nit : int
        Excursions tried.
    message : str
    """

    indices: NDArray[np.intp]
    logdet: float
    start_logdet: float
    exchanges: int
    nit: int
    message: str


def information_logdet(blocks: NDArray[np.float64], chosen, ridge: float = 0.0) -> float:
    """``log det(sum_i J_i^T J_i + ridge I)`` over the chosen blocks (``-inf`` when singular)."""
    sign, value = np.linalg.slogdet(_information(blocks, list(np.asarray(chosen, dtype=np.intp)), ridge))
    return float(value) if sign > 0 else -np.inf


def detmax(blocks: NDArray[np.float64], n: int, *, start=None, random_state=None, max_excursion: int = 3,
           max_exchanges: int | None = None, callback=None) -> ExchangeResult:
    """Choose ``n`` of the candidates that maximise ``det(J^T J)``: Mitchell's DETMAX exchange.

    From a start design, an excursion of length ``k`` adds the ``k``
    candidates that raise the determinant most (one at a time), then removes
    the ``k`` design points whose loss is smallest. A better design is kept
    and the excursions start again at ``k = 1``; otherwise ``k`` grows up to
    ``max_excursion``. Candidates are never chosen twice. A tiny ridge
    (``1e-9`` of the mean information of one candidate) keeps a singular start
    workable; the result's determinant is never smaller than the start's.

    Parameters
    ----------
    blocks : ndarray, shape (C, r, L)
        The Jacobian rows of every candidate (``r`` rows per candidate, 3 for
        positions), columns scaled alike.
    n : int
        Design size, ``1 <= n <= C``.
    start : array-like of int, optional
        Initial candidates (``n`` distinct indices); default a random subset.
    random_state : None, int or Generator
        Seed of the random start.
    max_excursion : int
        The longest excursion tried before stopping.
    max_exchanges : int, optional
        Stop after this many accepted excursions (default ``50 n``).
    callback : callable, optional
        ``callback(exchanges, logdet)`` after every accepted excursion.

    Returns
    -------
    ExchangeResult
    """
    blocks = np.asarray(blocks, dtype=float)
    count, _, width = blocks.shape
    if not 1 <= n <= count:
        raise PartcalError(f"detmax: the design size must be in [1, {count}] (the candidates); got {n}")
    if start is None:
        rng = np.random.default_rng(seed_from(random_state))
        design = list(rng.choice(count, size=n, replace=False))
    else:
        design = [int(i) for i in np.asarray(start).ravel()]
        if len(design) != n or len(set(design)) != n or min(design) < 0 or max(design) >= count:
            raise PartcalError(f"detmax: start must be {n} distinct candidate indices in [0, {count - 1}]")
    flat = blocks.reshape(count * blocks.shape[1], width)
    ridge = 1e-9 * float(np.einsum("ij,ij->", flat, flat)) / count / width or 1e-300
    start_logdet = information_logdet(blocks, design, ridge)
    logdet, exchanges, nit, k = start_logdet, 0, 0, 1
    limit = 50 * n if max_exchanges is None else max_exchanges
    while k <= max_excursion and exchanges < limit:
        nit += 1
        trial = _excursion(blocks, design, k, ridge)
        value = information_logdet(blocks, trial, ridge)
        if value > logdet + 1e-10 * max(1.0, abs(logdet)):
            design, logdet, exchanges, k = trial, value, exchanges + 1, 1
            if callback is not None:
                callback(exchanges, logdet)
        else:
            k += 1
    message = "no excursion improves the design" if k > max_excursion else f"stopped after {limit} exchanges"
    log.debug("detmax: %d exchanges in %d excursions, log det %.6g -> %.6g", exchanges, nit, start_logdet, logdet)
    return ExchangeResult(np.sort(np.array(design, dtype=np.intp)), logdet, start_logdet, exchanges, nit, message)


def _excursion(blocks: NDArray[np.float64], design: list[int], k: int, ridge: float) -> list[int]:
    """Add the ``k`` best candidates one by one, then remove as many of the cheapest points one by one."""
    design = list(design)
    free = np.ones(blocks.shape[0], dtype=bool)
    free[design] = False
    added = 0
    for _ in range(min(k, int(free.sum()))):
        gain = _logdet_rank_update(blocks, _information(blocks, design, ridge), +1.0)
        gain[~free] = -np.inf
        best = int(np.argmax(gain))
        design.append(best)
        free[best] = False
        added += 1
    for _ in range(added):
        loss = _logdet_rank_update(blocks[design], _information(blocks, design, ridge), -1.0)
        design.pop(int(np.argmax(loss)))
    return design


def _information(blocks: NDArray[np.float64], design: list[int], ridge: float) -> NDArray[np.float64]:
    """``sum J_i^T J_i + ridge I`` over the design, summed afresh (no drift from updates)."""
    b = blocks[design].reshape(-1, blocks.shape[2])
    return b.T @ b + ridge * np.eye(blocks.shape[2])


def _logdet_rank_update(blocks: NDArray[np.float64], info: NDArray[np.float64], sign: float) -> NDArray[np.float64]:
    """``log det(info + sign J_c^T J_c) - log det(info)`` for every block ``J_c``.

    By the determinant lemma that is ``log det(I + sign J_c M^-1 J_c^T)`` (``M = info``): one small
    determinant per candidate.
    """
    inverse = scipy.linalg.cho_solve(scipy.linalg.cho_factor(info), np.eye(info.shape[0]))
    solved = (blocks.reshape(-1, blocks.shape[2]) @ inverse).reshape(blocks.shape)
    small = sign * (solved @ blocks.transpose(0, 2, 1)) + np.eye(blocks.shape[1])
    det_sign, value = np.linalg.slogdet(small)
    return np.where(det_sign > 0, value, -np.inf)


# ---------------------------------------------------------------------- the bound for any design
@dataclass(frozen=True)
class DesignBound:
    """Outcome of :func:`i_optimal_bound`.

    Attributes
    ----------
    weights : ndarray, shape (C,)
        The approximate design: a weight per candidate, summing to 1.
    value : float
        ``tr(T M(w)^-1)`` of ``weights``.
    bound : float
        ``value^2 / max_i d_i``: no design on the candidates, approximate or exact, does better (``d_i``
        is the criterion's derivative at candidate ``i``; ``bound = value`` at the optimum).
    nit : int
        Iterations.
    """

    weights: NDArray[np.float64]
    value: float
    bound: float
    nit: int


def i_optimal_bound(blocks: NDArray[np.float64], target: NDArray[np.float64], *, rtol: float = 1e-3,
                    max_iter: int = 5000) -> DesignBound:
    """The approximate I-optimal design over candidates, and the lower bound it proves.

    Minimises ``phi(w) = tr(T M(w)^-1)``, ``M(w) = sum_i w_i J_i^T J_i`` over
    weights ``w >= 0`` summing to 1, by the multiplicative algorithm
    ``w_i <- w_i sqrt(d_i / phi)`` with ``d_i = tr(J_i M^-1 T M^-1 J_i^T)``
    (Silvey, Titterington and Torsney 1978; monotone for this power, Yu
    2010). ``phi`` is convex and homogeneous of degree -1 in ``M``, so for any
    design ``phi* >= phi(w)^2 / max_i d_i`` at every iterate: the bound holds
    whether or not the iteration has converged. It stops when the bound is
    within ``rtol`` of the value.

    With ``T`` the mean ``J^T J`` of the test poses, ``sigma^2 tr(T M^-1)`` is
    the predicted mean squared 3-D position error over them for a tracker
    noise ``sigma`` (per coordinate). An exact design of ``n`` candidates has
    ``M_n = n M(w_n)`` (``w_n``: weight ``1 / n`` on each), so its predicted
    mean squared error is at least ``sigma^2 bound / n``. Rows scaled by
    ``1 / sigma_i`` give the bound for pose-dependent noise and a weighted fit.

    Parameters
    ----------
    blocks : ndarray, shape (C, r, L)
        The Jacobian rows of every candidate.
    target : ndarray, shape (L, L)
        Symmetric positive semi-definite: what the error is measured over.

    Returns
    -------
    DesignBound

    Examples
    --------
    Two candidates that each identify one parameter: the best design measures both equally.

    >>> b = i_optimal_bound(np.array([[[1.0, 0.0]], [[0.0, 1.0]]]), np.eye(2))
    >>> np.round(b.weights, 6).tolist(), round(b.value, 6), round(b.bound, 6)
    ([0.5, 0.5], 4.0, 4.0)
    """
    blocks = np.asarray(blocks, dtype=float)
    count, rows, width = blocks.shape
    flat = blocks.reshape(-1, width)
    w = np.full(count, 1.0 / count)
    value = bound = np.inf
    for nit in range(1, max_iter + 1):
        info = (flat * np.repeat(w, rows)[:, None]).T @ flat
        inverse = np.linalg.inv(info)
        value = float(np.trace(target @ inverse))
        d = np.sum((flat @ (inverse @ target @ inverse)) * flat, axis=1).reshape(count, rows).sum(axis=1)
        bound = value**2 / float(d.max())
        if value - bound <= rtol * value:
            break
        w = w * np.sqrt(np.maximum(d, 0.0) / value)
        w /= w.sum()
    return DesignBound(w, value, bound, nit)
