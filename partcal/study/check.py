"""``partcal check``: do a few new measurements agree with a model, and if not, what most likely moved.

The new measurements are judged by the model's own calibrated spread (``predict_with_std``: for a run's
model the spread scaled on held-out blocks of its identification data, :mod:`partcal.study.spread`), not by
the fit's residual sigma: residuals of real data are correlated, so the fit's sigma is too narrow for new
data (on the IPA UR10 it flagged 6 of 7 unchanged 50-pose windows of series B).

- Each coordinate's standardised residual ``z = (measured error - predicted error) / std``.
- The statistic: the mean of ``z^2`` over the ``m = 3 n`` coordinates (``m - 6`` after a tracker
  registration), against ``chi2(m) / m``; its p-value is ``chi2.sf(sum z^2, m)``. The verdict is
  ``moved`` when the p-value is below ``alpha`` (default :data:`ALPHA`, 0.01), else ``holds``.
- The explanations (for a model that identifies robot parameters): one event each, each joint's offset
  alone (the joint's zero moved: an encoder or a motor swapped), the tool offset (3), the base frame
  (6, unless the data's tracker frame was registered on them, which absorbs it). Each is fitted to the
  standardised residuals with the model's Jacobian, each parameter with a Gaussian prior of a plausible
  change (:data:`PLAUSIBLE_CHANGE`: 0.1 degree, 1 mm) and ranked by its evidence against "nothing moved",
  ``2 ln`` of the Bayes factor of the linear-Gaussian model::

      evidence = |z|^2 - min_d (|z - A d|^2 + |d / s|^2) - ln det(I + S A^T A S)

  (``A`` the explanation's Jacobian columns divided by each coordinate's std, ``s`` the prior standard
  deviations, ``S = diag(s)``). The last term is the penalty for the explanation's parameters, each by how
  much the data can tell about it (the BIC's ``k ln m`` is its large-sample form); the middle term
  penalises a change far beyond a plausible one. The fitted change is the minimiser ``d`` (the true joint
  angle minus the one read, the tool's or base's change), mm and degrees.
- Each explanation's ``shared``: the share of what its fitted change does to the standardised residuals (of
  its sum of squares) that the likeliest explanation's parameters can do too. Near 1 these poses can hardly
  tell the two apart, and what ranks them is the prior (the penalty for parameters) and the data's own
  misfit, not the change (a joint 2 turn with joint 1 held still is a rigid turn of every measured point
  about a fixed axis: a base frame change does all of it).
- Taken together: forward selection by evidence over the same explanations, their columns combined (nested
  linear-Gaussian models, the same priors): from nothing, the explanation whose addition raises the evidence
  most, while the gain exceeds :data:`GAIN` (2: "positive" on Kass and Raftery's scale). The first taken is
  the likeliest single explanation; the verdict names those taken beyond it.

Python::

    from partcal.study.check import check_file

    result = check_file("reports/ur10_ipa/models/dh.json", "new.csv", fmt="tmac.yaml", frame="tracker")
    result.holds, result.p_value, result.explanations[0].name
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ..data.formats import ROWS_EXPECTED, MeasurementFormat, RowSelection, load_format
from ..data.measurements import read_measurements
from ..data.measurement_rows import has_measurement_column, read_measurement_rows
from ..errors import ConfigError, DataError, ModelFileError
from ..calibration.chain import model_jacobian
from ..calibration.measurement import MeasurementRows
from ..calibration.parameters import geometric_size, parameter_names
from ..models.kindtable import identification_of
from ..robot.frames import kabsch
from ..robot.rotations import rotation_vector_from_matrix
from .check_types import model_cell, refuse_points_against_camera, stacked_at_model
from .predictor import load_predictor

ALPHA = 0.01
"""The verdict is ``moved`` below this p-value: one false alarm in a hundred checks of an unchanged robot
(a false alarm costs a new calibration)."""

PLAUSIBLE_CHANGE = {"mm": 1.0, "deg": 0.1}
"""The prior standard deviation of each explanation's parameters: a plausible change, by unit."""

GAIN = 2.0
"""Forward selection takes a further explanation only when it raises the evidence by more than this: ``2 ln``
Bayes factor above 2, "positive" evidence on Kass and Raftery's scale (J. Am. Stat. Assoc. 90, 1995, 773-795);
smaller gains are the fit's noise."""

TOOL = ("tool.x", "tool.y", "tool.z")
BASE = ("base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz")


@dataclass(frozen=True)
class Explanation:
    """One candidate explanation fitted to the standardised residuals.

    ``parameters`` and ``units`` name its parameters, ``change`` their fitted change (mm, degrees);
    ``evidence`` is ``2 ln`` of its Bayes factor against nothing moved (larger is likelier);
    ``mean_z2`` and ``p_value`` the statistic left after it (over the coordinates less its parameters);
    ``shared`` the share of what its fitted change does to the standardised residuals (of its sum of squares)
    that the likeliest explanation's parameters can do too (1 for the likeliest itself; near 1: these poses can
    hardly tell the two apart, and the prior and the data's own misfit rank them).
    """

    name: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    change: NDArray[np.float64]
    evidence: float
    mean_z2: float
    p_value: float
    shared: float = 1.0

    def values_text(self) -> str:
        """``name change unit`` of each parameter."""
        return ", ".join(f"{p} {v:+.4g} {u}" for p, v, u in zip(self.parameters, self.change, self.units))


@dataclass(frozen=True)
class CheckResult:
    """What ``partcal check`` found.

    ``z`` (n, 3): the standardised residuals; ``dof``: the coordinates the statistic counts (``3 n``, less 6
    after a tracker registration); ``mean_z2`` the statistic, ``p_value`` its p-value, ``holds`` the verdict at
    ``alpha``; ``explanations`` ranked, likeliest first (empty for a model without robot parameters);
    ``registration``: ``(rotation vector deg, translation mm, 3-D RMS mm)`` of the tracker frame
    registered on the new data, or None; ``together``: ``(name, evidence gain)`` of the explanations forward
    selection takes together, in the order taken (:func:`forward_selection`).
    """

    z: NDArray[np.float64]
    dof: int
    mean_z2: float
    p_value: float
    alpha: float
    explanations: tuple[Explanation, ...]
    registration: tuple | None = None
    model: str = "model"
    data: str = "data"
    together: tuple[tuple[str, float], ...] = ()

    @property
    def holds(self) -> bool:
        return bool(self.p_value >= self.alpha)

    def verdict(self) -> str:
        """The verdict in one line."""
        said = (f"mean squared standardised residual {self.mean_z2:.3f} over {self.dof} coordinates, "
                f"p {'= ' if self.p_value > 0 else ''}{_p(self.p_value)}")
        if self.holds:
            return f"holds: {said} (moved below p = {self.alpha:g})"
        best = next((e for e in self.explanations if e.evidence > 0), None)
        likely = (f"; most likely {best.name} ({best.values_text()})" if best else
                  "; no single explanation tried is likelier than none" if self.explanations else "")
        beyond = [f"{name} ({gain:+.1f})" for name, gain in self.together[1:]]
        if best and self.together and self.together[0][0] == best.name and beyond:
            likely += f"; beyond it, {', '.join(beyond)}"
        return f"moved: {said}, below {self.alpha:g}{likely}"

    def lines(self, worst: int = 5) -> list[str]:
        """What the command line prints: the verdict, how it was judged, the largest residuals, the
        explanations."""
        n = len(self.z)
        out = [self.verdict(), f"checked {n} poses of {self.data} against {self.model}, each coordinate "
               "standardised by the model's calibrated spread; the statistic against chi-square with "
               f"{self.dof} degrees of freedom"]
        if self.registration is not None:
            rot, shift, rms = self.registration
            out.append("the tracker frame was registered on these poses first (rotation "
                       f"{_vector(rot)} deg, translation {_vector(shift)} mm, 3-D RMS {rms:.3f} mm): a moved base "
                       "frame cannot be told from it")
        norms = np.linalg.norm(self.z, axis=1)
        top = np.argsort(-norms)[:worst]
        out.append("largest standardised residuals (pose: |z|): " + ", ".join(f"{k + 1}: {norms[k]:.2f}"
                                                                                 for k in top))
        if not self.explanations:
            out.append("no explanations tried: the model identifies no robot parameters (kind kinematic does)")
        else:
            out.append("explanations, likeliest first (evidence: 2 ln Bayes factor against nothing moved, "
                       "prior of a change 0.1 deg or 1 mm per parameter; shared: the share of what its change does "
                       "that the first's parameters do too, near 1 where these poses hardly tell them apart):")
            width = max(len(e.name) for e in self.explanations)
            for rank, e in enumerate(self.explanations, 1):
                out.append(f"  {rank:2d}. {e.name:<{width}}  evidence {e.evidence:9.1f}  left {e.mean_z2:7.3f} "
                           f"(p {_p(e.p_value)})  shared {'   -' if rank == 1 else f'{e.shared:4.2f}'}  {e.values_text()}")
            out.append(f"taken together (forward selection, each step raising the evidence by more than {GAIN:g}): "
                       + (", ".join(f"{name} ({gain:+.1f})" for name, gain in self.together) or "none"))
        return out


def _p(p: float) -> str:
    """A p-value as text; one below the smallest double is said as such, not as 0."""
    return f"{p:.3g}" if p > 0 else "< 1e-300"


def _vector(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def candidate_columns(model, q_deg: NDArray[np.float64], payload_kg, base: bool = True
                      ) -> list[tuple[str, tuple[str, ...], tuple[str, ...], NDArray[np.float64]]]:
    """The explanations tried: ``(name, parameters, units, columns)``, each ``columns`` (3 n, k) mm per unit
    (rows pose by pose, x y z): each joint's offset (the identified arm's Jacobian), the tool offset and,
    with ``base``, the base frame (the model's identification Jacobian)."""
    table = identification_of(model)
    own = geometric_size(model.robot_, model.parametrization_) + model.joint_errors_.size
    payload = np.broadcast_to(np.asarray(model.default_payload_kg() if payload_kg is None else payload_kg,
                                         dtype=float), (len(q_deg),))
    _, jac = model_jacobian(model.robot_, model.joint_errors_, q_deg, table.value[:own], payload,
                            model.parametrization_)
    names = list(table.names[:own])
    joints = model.identified_robot_.jacobian(q_deg)                    # (n, 3, N) mm/deg
    out = [(f"joint {j + 1}'s offset", (f"q{j + 1}",), ("deg",), joints[:, :, j].reshape(-1, 1))
           for j in range(joints.shape[2])]
    groups = [("the tool offset", TOOL)] + ([("the base frame", BASE)] if base else [])
    for name, params in groups:
        units = tuple(table.units[names.index(p)] for p in params)
        out.append((name, params, units, jac[:, [names.index(p) for p in params]]))
    return out


def explain(z: NDArray[np.float64], std: NDArray[np.float64], candidates, dof: int
            ) -> tuple[tuple[Explanation, ...], tuple[tuple[str, float], ...]]:
    """Each candidate ``(name, parameters, units, columns)`` fitted to the standardised residuals ``z`` (n, 3)
    (the coordinates' spreads ``std`` (n, 3) mm), with a prior of a plausible change; ranked by evidence. Also
    the candidates taken together by forward selection (:func:`forward_selection`)."""
    zv, w = z.reshape(-1), 1.0 / std.reshape(-1)
    found, signals, spans = [], [], {}
    for name, params, units, cols in candidates:
        s = np.array([PLAUSIBLE_CHANGE[u] for u in units])
        B = cols * w[:, None] * s                                       # standardised, per prior std
        d, left, evidence = _fitted(zv, B)
        sse, free = float(left @ left), max(dof - len(s), 1)          # the coordinates its parameters leave
        found.append(Explanation(name, params, units, d * s, evidence, sse / free, float(chi2.sf(sse, free))))
        signals.append(B @ d)
        spans[name] = B
    order = sorted(range(len(found)), key=lambda k: -found[k].evidence)
    ranked = tuple(replace(found[k], shared=_share_in_span(signals[k], spans[found[order[0]].name])) for k in order)
    return ranked, forward_selection(zv, spans)


def _fitted(zv: NDArray[np.float64], B: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """The change ``d`` (per prior standard deviation) of standardised columns ``B`` fitted to ``zv`` with a
    unit Gaussian prior, the residuals it leaves and its evidence against nothing (``2 ln`` Bayes factor)."""
    gram = B.T @ B + np.eye(B.shape[1])
    d = np.linalg.solve(gram, B.T @ zv)
    left = zv - B @ d
    return d, left, float(zv @ zv - left @ left - d @ d - np.linalg.slogdet(gram)[1])


def forward_selection(zv: NDArray[np.float64], spans: dict[str, NDArray[np.float64]]) -> tuple[tuple[str, float], ...]:
    """The candidates taken together: from nothing, the one whose columns (``spans``: standardised, per prior
    standard deviation) added to those taken raise the evidence most, while the gain exceeds :data:`GAIN`;
    ``(name, gain)`` in the order taken (the first is the likeliest single explanation)."""
    taken: list[tuple[str, float]] = []
    columns, current = np.zeros((len(zv), 0)), 0.0
    while len(taken) < len(spans):
        names = [k for k in spans if k not in dict(taken)]
        gains = [_fitted(zv, np.hstack([columns, spans[k]]))[2] - current for k in names]
        best = int(np.argmax(gains))
        if gains[best] <= GAIN:
            break
        taken.append((names[best], gains[best]))
        columns, current = np.hstack([columns, spans[names[best]]]), current + gains[best]
    return tuple(taken)


def _share_in_span(signal: NDArray[np.float64], columns: NDArray[np.float64]) -> float:
    """The share of ``signal``'s sum of squares that a combination of ``columns`` reproduces (1 for a nil
    signal: nothing tells it apart)."""
    total = float(signal @ signal)
    if total == 0.0:
        return 1.0
    fit = columns @ np.linalg.lstsq(columns, signal, rcond=None)[0]
    return min(float(fit @ fit) / total, 1.0)


def model_inputs(model, robot, q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """What ``model`` reads at joints ``q_deg`` (n, N) deg: the joints, or for a Cartesian model the nominal
    positions of ``robot`` (mm)."""
    return q_deg if model.inputs == "joint" else robot.positions(q_deg)


def check_arrays(model, q_deg, errors_mm, *, robot=None, payload_kg=None, registered: bool = False,
                 alpha: float = ALPHA, model_name: str = "model", data_name: str = "data", registration=None
                 ) -> CheckResult:
    """Check measured errors ``errors_mm`` (n, 3) mm (measured minus ``robot``'s nominal positions; default
    robot the model's own, ``model.robot_``) at joints ``q_deg`` (n, N) deg against a fitted ``model`` with a
    spread (any kind; explanations for a kind that identifies robot parameters). ``registered``: the data's
    frame was fitted to them (6 coordinates fewer, no base-frame explanation)."""
    problem = model.spread_problem()
    if problem is not None:
        raise ModelFileError(f"{model_name}: {problem}")
    if not 0.0 < alpha < 1.0:
        raise ConfigError(f"check: alpha must lie in (0, 1); got {alpha!r}")
    q = np.asarray(q_deg, dtype=float)
    errors = np.asarray(errors_mm, dtype=float)[:, :3]
    kw = {} if payload_kg is None or not model.reads_payload else {"payload_kg": payload_kg}
    mean, std = model.predict_with_std(model_inputs(model, robot or model.robot_, q), **kw)
    mean, std = np.asarray(mean).reshape(len(q), -1)[:, :3], np.asarray(std).reshape(len(q), -1)[:, :3]
    z = (errors - mean) / std
    dof = z.size - (6 if registered else 0)
    if dof < 1:
        raise DataError(f"{data_name}: {len(q)} poses leave no degree of freedom to check"
                        + (" once the tracker frame is registered on them (give at least 3)" if registered else ""))
    total = float((z ** 2).sum())
    expl, together = (), ()
    if identification_of(model) is not None:
        expl, together = explain(z, std, candidate_columns(model, q, payload_kg, base=not registered), dof)
    return CheckResult(z, dof, total / dof, float(chi2.sf(total, dof)), alpha, expl, registration,
                       model_name, data_name, together)


def registered_on_model(model, q_deg, tracker_mm, payload_kg=None, robot=None) -> tuple[NDArray[np.float64], tuple]:
    """Points measured in a tracker's frame ``tracker_mm`` (n, 3) mm carried into the model's base frame by the
    rigid fit (Kabsch) onto the positions the model predicts at ``q_deg`` (nominal plus its predicted error);
    returns them and ``(rotation vector deg, translation mm, 3-D RMS mm)`` of the fit."""
    kw = {} if payload_kg is None or not model.reads_payload else {"payload_kg": payload_kg}
    robot = robot or model.robot_
    predicted = robot.positions(q_deg) + np.asarray(model.predict(model_inputs(model, robot, q_deg), **kw)
                                                    ).reshape(len(q_deg), -1)[:, :3]
    rot, shift = kabsch(tracker_mm, predicted)
    moved = np.asarray(tracker_mm, dtype=float) @ rot.T + shift
    rms = float(np.sqrt(np.mean(np.sum((moved - predicted) ** 2, axis=1))))
    return moved, (np.degrees(rotation_vector_from_matrix(rot)), shift, rms)


def check_file(model_path: str | Path, data_path: str | Path, *, fmt: str | Path | MeasurementFormat | None = None,
               frame: str = "base", rows: str | None = None, alpha: float = ALPHA) -> CheckResult:
    """``partcal check``: the measurement file ``data_path`` (its format ``fmt``, the data rows ``rows``)
    against the model file ``model_path``. ``frame="tracker"``: the measured positions are in a tracker's
    frame, registered (a rigid fit) onto the positions the model predicts before they are judged."""
    predictor = load_predictor(model_path)
    model = predictor.model
    robot = getattr(model, "robot_", None) or predictor.robot       # a kinematic model's own, else the file's
    if robot is None:
        raise ModelFileError(f"{model_path}: the model file carries no robot: check needs one for the nominal "
                             "positions the errors are taken from (a model file of 'partcal run' with a robot)")
    if frame not in ("base", "tracker"):
        raise ConfigError(f"check: --frame must be base or tracker; got {frame!r}")
    fmt = load_format(fmt) if isinstance(fmt, (str, Path)) else fmt
    if has_measurement_column(data_path, fmt):                                        # pixels, touches, ...
        return check_rows_file(model, predictor.document, model_path, data_path, fmt, frame, rows, alpha)
    refuse_points_against_camera(model, model_path, data_path, "check")
    try:
        selection = RowSelection.parse(rows) if rows else None
    except ConfigError:
        raise ConfigError(f"check: --rows {rows!r}: expected {ROWS_EXPECTED}") from None
    m = read_measurements(data_path, robot, fmt=fmt, rows=selection, frame=frame)
    if m.n_joints != robot.n_joints:
        raise DataError(f"{data_path}: {m.n_joints} joint columns (q1..q{m.n_joints}); the model's robot "
                        f"{robot.name} has {robot.n_joints}")
    nominal = robot.positions(m.q_deg)            # the model predicts errors against its own robot (its tool)
    measured, registration = m.measured_mm, None
    if frame == "tracker":
        if len(m) < 3:
            raise DataError(f"{data_path}: registering a tracker frame needs at least 3 poses; got {len(m)}")
        measured, registration = registered_on_model(model, m.q_deg, measured, m.payload_kg, robot)
    return check_arrays(model, m.q_deg, measured - nominal, robot=robot, payload_kg=m.payload_kg,
                        registered=frame == "tracker",
                        alpha=alpha, model_name=str(model_path), data_name=str(data_path), registration=registration)


# ---------------------------------------------------------------------- rows of measurement types (pixels, touches)
@dataclass(frozen=True)
class RowsCheckResult(CheckResult):
    """:class:`~partcal.study.check.CheckResult` of rows of measurement types: ``z`` (residuals, 1) the weighted
    residuals over the model's sigma; ``worst`` the largest ``(where, type, |z|)``."""

    worst: tuple = ()
    types: str = ""

    def lines(self, worst: int = 5) -> list[str]:
        out = [self.verdict(), f"checked {self.dof} residuals of {self.types} rows of {self.data} against "
               f"{self.model}: the rows' noise the model's fit sigma, its parameters' uncertainty through its "
               f"covariance; the statistic against chi-square with {self.dof} degrees of freedom",
               "largest standardised residuals (file:line type |z|): "
               + ", ".join(f"{w} {t} {z:.2f}" for w, t, z in self.worst[:worst])]
        if self.explanations:
            out.append("explanations, likeliest first (evidence: 2 ln Bayes factor against nothing moved, "
                       "prior of a change 0.1 deg or 1 mm per parameter):")
            width = max(len(e.name) for e in self.explanations)
            for rank, e in enumerate(self.explanations, 1):
                out.append(f"  {rank:2d}. {e.name:<{width}}  evidence {e.evidence:9.1f}  {e.values_text()}")
        return out


def check_type_rows(model, doc: dict, rows: MeasurementRows, *, model_path="model", data_path="data",
                    alpha: float = ALPHA) -> RowsCheckResult:
    """Check rows of measurement types against a model identified from such rows (module docstring)."""
    if not 0.0 < alpha < 1.0:
        raise ConfigError(f"check: alpha must lie in (0, 1); got {alpha!r}")
    table = model.identification_
    if table.covariance is None or table.sigma_mm is None or not np.isfinite(table.sigma_mm):
        raise ModelFileError(f"{model_path}: field 'identification.covariance': the model has no covariance of its "
                             "parameters: fit it again with partcal run")
    problem, values = stacked_at_model(model, rows, model_cell(doc, model_path), model_path, data_path)
    r, jac = problem(values)
    names = [n for n, _ in parameter_names(model.robot_, model.joint_errors_, model.parametrization_)]
    names += [n for n, _ in problem.names]
    column = {n: k for k, n in enumerate(names)}
    identified = [table.names[k] for k in np.flatnonzero(np.array(table.status) == "identified")]
    at = [column.get(n, -1) for n in identified]
    cov = np.asarray(table.covariance, dtype=float)
    keep = np.array([a >= 0 for a in at], dtype=bool)
    w, v = np.linalg.eigh(cov[np.ix_(keep, keep)])
    lever = jac[:, np.array(at)[keep]] @ (v * np.sqrt(np.clip(w, 0.0, None)))       # J C^1/2
    s2 = float(table.sigma_mm) ** 2
    projected = lever.T @ r
    total = float(r @ r - projected @ np.linalg.solve(s2 * np.eye(lever.shape[1]) + lever.T @ lever, projected)) / s2
    dof = r.size
    z = r / np.sqrt(s2)
    jac = -jac                      # r is the model less the rows: a change of the truth moves it the other way
    candidates = [(f"joint {j}'s offset", (f"q{j}",), ("deg",), jac[:, [column[f"theta[{j}]"]]])
                  for j in range(1, model.robot_.n_joints + 1) if f"theta[{j}]" in column]
    poses = dict.fromkeys(n.rsplit(".", 1)[0] for n, _ in problem.names if "@" in n)
    for pose in poses:
        params = tuple(f"{pose}.{c}" for c in ("x", "y", "z", "rx", "ry", "rz"))
        if all(p in column for p in params):
            candidates.append((pose.replace("@", " on the ") + "'s pose", params, ("mm",) * 3 + ("deg",) * 3,
                               jac[:, [column[p] for p in params]]))
    expl, together = explain(z[:, None], np.full((dof, 1), np.sqrt(s2)), candidates, dof)
    row_of = problem.row_of
    order = np.argsort(-np.abs(z))
    worst, seen = [], set()
    for k in order:
        if row_of[k] >= 0 and row_of[k] not in seen:
            seen.add(row_of[k])
            worst.append((rows.where(row_of[k]), rows.types[row_of[k]], float(abs(z[k]))))
        if len(worst) == 5:
            break
    return RowsCheckResult(z[:, None], dof, total / dof, float(chi2.sf(total, dof)), alpha, expl, None,
                           str(model_path), str(data_path), together, tuple(worst),
                           ", ".join(m.name for m in problem.measurements))


def check_rows_file(model, doc, model_path, data_path, fmt: MeasurementFormat | None, frame: str, rows: str | None,
                    alpha: float) -> RowsCheckResult:
    """``partcal check`` of a measurements file (a ``measurement`` column; ``fmt`` its format, loaded): refused
    naming why for a model
    without robot parameters, a tracker frame or a row selection."""
    if frame != "base":
        raise ConfigError(f"check: --frame {frame}: {data_path} holds measurement types, whose unknowns (a "
                          "camera's pose, a plane's) are the model's: leave --frame out")
    if rows:
        raise ConfigError(f"check: --rows: {data_path} holds measurement types and is read whole (a distance's "
                          "'to' names rows by id): split the file instead")
    if getattr(model, "identification_", None) is None or not (doc.get("model") or {}).get("measurement_types"):
        raise ModelFileError(f"{model_path}: {data_path} holds measurement types (a 'measurement' column); this model "
                             "was not identified from any: check it with tracker points (x_meas, y_meas, z_meas), "
                             "or check a model of partcal run on these types")
    cell = model_cell(doc, model_path)
    table = read_measurement_rows(data_path, model.robot_, fmt, cell or None)
    return check_type_rows(model, doc, table, model_path=model_path, data_path=data_path, alpha=alpha)
