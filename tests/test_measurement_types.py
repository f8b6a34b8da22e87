"""Measurement types (partcal.calibration.stacked, partcal.calibration.registry): residuals, Jacobians against finite
differences, identification of a virtual UR10 from each type against its truth, the scale no type fixes."""

import numpy as np
import pytest

from partcal import load_robot
from partcal.errors import DataError
from partcal.calibration import checks, fixed_points, plane_contacts
from partcal.calibration.tracker_points import TRACKER_FRAME
from partcal.robot.rotations import matrix_from_rotation_vector
from partcal.calibration.parameters import nominal_values, robot_with
from partcal.calibration.joint_errors import JointErrors
from partcal.calibration.measurement import MeasurementType, Residuals, MeasurementRows, SCALE
from partcal.calibration.registry import add_measurement_type, MEASUREMENT_TYPES
from partcal.calibration.stacked import identify_measurements, type_residuals, StackedProblem

ROBOT = load_robot("universal_robots_ur10")


def _configurations(n, rng):
    lo = np.array([-90, -150, -140, -180, -150, -180.0])
    hi = np.array([90, -30, 140, 180, 150, 180.0])
    return lo + (hi - lo) * rng.random((n, 6))


def _true_robot(rng):
    """The nominal UR10 with DH errors of a few tenths of a mm and hundredths of a degree, a shifted tool."""
    v = nominal_values(ROBOT)
    v[:24] += rng.normal(0, 1, 24) * np.tile([0.05, 0.3, 0.3, 0.03], 6)
    v[24:27] += [0.3, -0.2, 0.4]
    return robot_with(ROBOT, v)


def _newton(true, q, wanted, iters=8):
    """Commanded joints near ``q`` whose true tip reaches ``wanted(p)`` (a displacement), by joints 1-3."""
    q = q.copy()
    for _ in range(iters):
        p = true.positions(q)
        jac = true.jacobian(q)[:, :, :3]
        q[:, :3] += np.linalg.solve(jac, wanted(p)[:, :, None])[:, :, 0]        # jacobian: mm per degree
    return (q + 180.0) % 360.0 - 180.0          # the same tips with the joints in one turn (the steps may wind)


def _rows(q, measurements, numbers=None, texts=None):
    n = len(q)
    return MeasurementRows(q, tuple(measurements), tuple(str(i + 1) for i in range(n)), tuple(range(2, n + 2)), "test.csv",
                numbers or {}, texts or {})


def _mixed_rows(rng):
    """Rows of every type at random poses (residuals need not be small to check derivatives)."""
    q = _configurations(24, rng)
    measurements = ["plane"] * 8 + ["fixed"] * 6 + ["distance"] * 6 + ["point"] * 4
    feature = ["top"] * 4 + ["step"] * 4 + ["a"] * 3 + ["b"] * 3 + [""] * 10
    flush = np.array([1, 0, 1, 0, 0, 1, 0, 0] + [np.nan] * 16)
    to = [""] * 14 + ["1", "5", "9", "a", "pivot", "pivot"] + [""] * 4
    dist = np.array([np.nan] * 14 + [500, 700, 900, 800, 1000, 1200] + [np.nan] * 4)
    x = ROBOT.positions(q) + rng.normal(0, 1, (24, 3))
    angles = np.full((24, 3), np.nan)
    angles[20:22] = rng.uniform(-60, 60, (2, 3))        # two point rows with the tool's measured orientation
    numbers = {"flush": flush, "distance_mm": dist, "x_meas": x[:, 0], "y_meas": x[:, 1], "z_meas": x[:, 2],
               "rx_meas": angles[:, 0], "ry_meas": angles[:, 1], "rz_meas": angles[:, 2]}
    target = tuple([""] * 22 + ["B", "B"])              # two of a further target
    cell = {"planes": {"top": {"normal": [0.1, 0.0, 1.0], "offset_mm": 300.0},
                           "step": {"parallel_to": "top", "spacing_mm": -200.0}},
                "points": {"b": {"distance_to": "a", "distance_mm": 1000.0}, "pivot": {}}}
    return _rows(q, measurements, numbers, {"feature": tuple(feature), "to": tuple(to), "target": target}), cell


@pytest.mark.parametrize("parametrization, tracker", [("dh", False), ("complete", False), ("dh", True)])
def test_jacobian_of_every_measurement_type_matches_finite_differences(parametrization, tracker, monkeypatch):
    for module in (plane_contacts, fixed_points):     # random poses: no touch is near its plane
        monkeypatch.setattr(module, "NEAR_MM", 1e9)
    monkeypatch.setattr(plane_contacts, "GIVEN_NORMAL_DEG", 180.0)
    monkeypatch.setattr(checks, "LENGTH_FACTOR", 1e9)  # nor does a known length agree with them
    rng = np.random.default_rng(5)
    rows, cell = _mixed_rows(rng)
    if tracker:         # the points in a tracker's frame turned 30 degrees: its pose among the unknowns
        turn = matrix_from_rotation_vector(np.radians([10.0, -20.0, 15.0]))
        x = np.column_stack([rows.numbers[c] for c in ("x_meas", "y_meas", "z_meas")]) @ turn + [5.0, -3.0, 2.0]
        numbers = {k: v for k, v in rows.numbers.items() if not k.startswith("r")}      # no orientation there
        rows = MeasurementRows(rows.q_deg, rows.types, rows.ids, rows.lines, rows.source,
                    {**numbers, "x_meas": x[:, 0], "y_meas": x[:, 1], "z_meas": x[:, 2]}, rows.texts)
        cell = {**cell, TRACKER_FRAME: True}
    errors = JointErrors.for_robot(ROBOT, [2, 3], 0)
    payload = np.full(len(rows), 5.0)
    measurements = [cls.build(rows, cell) for cls in MEASUREMENT_TYPES.values()]
    problem = StackedProblem(ROBOT, errors, rows, [k for k in measurements if k is not None], payload, parametrization)
    v = problem.start + rng.normal(0, 1e-3, problem.start.size) * 1.0
    r, jac = problem(v)
    numeric = np.empty_like(jac)
    for k in range(v.size):
        step = np.zeros(v.size)
        step[k] = 1e-6
        numeric[:, k] = (problem(v + step, jacobian=False)[0] - problem(v - step, jacobian=False)[0]) / 2e-6
    assert np.all(np.abs(jac - numeric) <= 1e-5 * np.abs(numeric).max(axis=0) + 1e-6)    # central differences


def _score(true, model_values, parametrization, rng, rigid):
    q = _configurations(500, rng)
    model = robot_with(ROBOT, model_values, parametrization).positions(q)
    truth = true.positions(q)
    if rigid:
        from partcal.robot.frames import kabsch
        rot, t = kabsch(model, truth)
        model = model @ rot.T + t
    return float(np.sqrt(np.mean(np.sum((model - truth) ** 2, axis=1))))


def _touches(true, rng, planes, per_plane, noise):
    """Commanded joints whose true tip lies on each plane (plus a miss of ``noise`` along the normal)."""
    qs, names = [], []
    for name, (normal, offset) in planes.items():
        normal = np.asarray(normal, float) / np.linalg.norm(normal)
        q = _configurations(3 * per_plane, rng)
        q = _newton(true, q, lambda p: -np.outer(p @ normal - offset - rng.normal(0, noise, len(p)), normal))
        ok = np.abs(true.positions(q) @ normal - offset) < 5 * noise + 1e-6
        qs.append(q[ok][:per_plane])
        names += [name] * len(qs[-1])
    return np.vstack(qs), names


def test_planes_tied_by_a_known_step_identify_the_robot_and_unknown_planes_name_the_scale():
    rng = np.random.default_rng(11)
    true = _true_robot(rng)
    planes = {"top": ([0, 0, 1], 300.0), "step": ([0, 0, 1], 100.0), "side": ([1, 0, 0], 700.0)}
    q, names = _touches(true, rng, planes, 120, 0.01)
    rows = _rows(q, ["plane"] * len(q), texts={"feature": tuple(names)})
    before = _score(true, nominal_values(ROBOT), "dh", np.random.default_rng(0), rigid=True)
    tied = {"planes": {"top": {}, "step": {"parallel_to": "top", "spacing_mm": -200.0}, "side": {}}}
    table, notes = identify_measurements(ROBOT, rows, tied)
    after = _score(true, table.value[:33], "dh", np.random.default_rng(0), rigid=True)
    assert table.target_rms_mm["plane"] < 0.02
    assert after < 0.05 < before
    assert not any(n.startswith(SCALE) for n in notes)
    loose, notes = identify_measurements(ROBOT, rows, {})
    assert notes[0].startswith(SCALE)
    # the scale held: the fit is exactly as good on the touches, but lengths stay nominal where the step fixed them
    assert loose.target_rms_mm["plane"] < 0.02
    assert _score(true, loose.value[:33], "dh", np.random.default_rng(0), rigid=True) > 3 * after


def test_fixed_points_with_a_known_bar_and_their_held_out_residuals():
    rng = np.random.default_rng(3)
    true = _true_robot(rng)
    nests = {"a": np.array([600., -500., 200.]), "c": np.array([500., 400., 500.])}
    nests["b"] = nests["a"] + 1000 * np.array([0.0, 0.6, 0.8])
    qs, names = [], []
    for name, c in nests.items():
        q = _newton(true, _configurations(60, rng), lambda p: c - p + rng.normal(0, 0.01, p.shape))
        ok = np.linalg.norm(true.positions(q) - c, axis=1) < 0.1
        qs.append(q[ok][:30])
        names += [name] * len(qs[-1])
    q = np.vstack(qs)
    rows = _rows(q, ["fixed"] * len(q), texts={"feature": tuple(names)})
    cell = {"points": {"b": {"distance_to": "a", "distance_mm": 1000.0}}}
    train = np.arange(len(q)) % 5 != 0
    table, _ = identify_measurements(ROBOT, rows.take(np.flatnonzero(train)), cell)
    found = dict(zip(table.names, table.value))
    where = {name: np.array([found[f"point {name}.{c}"] for c in "xyz"]) for name in nests}
    assert np.linalg.norm(where["b"] - where["a"]) == pytest.approx(1000.0, abs=0.01)
    assert np.linalg.norm(where["c"] - where["a"]) == pytest.approx(np.linalg.norm(nests["c"] - nests["a"]), abs=0.05)
    assert _score(true, table.value[:33], "dh", np.random.default_rng(0), rigid=True) < 0.05
    held = type_residuals(ROBOT, rows.take(np.flatnonzero(~train)), cell, table)["fixed"]
    assert held.size == 3 * np.sum(~train)
    assert 0.005 < np.sqrt(np.mean(held ** 2)) < 0.05      # the visits' own noise, 0.01 mm per axis


def test_distances_between_poses_identify_the_shape_and_hold_the_base():
    rng = np.random.default_rng(8)
    true = _true_robot(rng)
    q = _configurations(40, rng)
    tips = true.positions(q)
    i, j = np.triu_indices(len(q), 1)
    measured = np.linalg.norm(tips[i] - tips[j], axis=1) + rng.normal(0, 0.01, i.size)
    all_q = np.vstack([q, q[i]])
    measurements = ["pose"] * len(q) + ["distance"] * i.size
    rows = _rows(all_q, measurements, {"distance_mm": np.concatenate([np.full(len(q), np.nan), measured])},
                 {"to": tuple([""] * len(q) + [str(k + 1) for k in j])})
    table, notes = identify_measurements(ROBOT, rows, {})
    base = [s for n, s in zip(table.names, table.status) if n.startswith("base.")]
    assert base.count("identified") == 0
    assert _score(true, table.value[:33], "dh", np.random.default_rng(0), rigid=True) < 0.03
    assert any(n.startswith("distance") for n in notes)


def test_bad_rows_are_refused_naming_file_line_and_column():
    q = _configurations(4, np.random.default_rng(0))
    with pytest.raises(DataError, match=r"test.csv:2: column 'measurement': 'laser'"):
        identify_measurements(ROBOT, _rows(q, ["laser", "plane", "plane", "plane"],
                                       texts={"feature": ("",) + ("p",) * 3}), {})
    with pytest.raises(DataError, match=r"test.csv:2: column 'feature': plane 'p' has 2 touches"):
        identify_measurements(ROBOT, _rows(q[:2], ["plane"] * 2, texts={"feature": ("p", "p")}), {})
    with pytest.raises(DataError, match=r"test.csv:3: column 'to': 'nine' names no row"):
        identify_measurements(ROBOT, _rows(q[:2], ["pose", "distance"], {"distance_mm": np.array([np.nan, 5.0])},
                                       {"to": ("", "nine")}), {})
    with pytest.raises(DataError, match=r"test.csv:2: column 'feature': fixed point 'n' is reached once"):
        identify_measurements(ROBOT, _rows(q[:1], ["fixed"], texts={"feature": ("n",)}), {})


def test_a_measurement_type_added_elsewhere_joins_the_identification():
    class Height(MeasurementType):
        """A toy type: the tip's height above the floor, measured."""
        name = "height_toy"

        def residuals(self, positions, rotations, u):
            grad = np.tile([0.0, 0.0, 1.0], (self.index.size, 1))
            return Residuals(positions[self.index, 2] - self.rows.number("z_mm", self.index), self.index.copy(),
                             grad, np.zeros((self.index.size, 0)))

    add_measurement_type(Height)
    try:
        q = _configurations(60, np.random.default_rng(1))
        rows = _rows(q, ["height_toy"] * 60, {"z_mm": ROBOT.positions(q)[:, 2] + 0.5})
        table, _ = identify_measurements(ROBOT, rows, {})
        assert table.target_rms_mm["height_toy"] < 1e-6
        other = _configurations(10, np.random.default_rng(2))
        lifted = robot_with(ROBOT, table.value[:33]).positions(other) - ROBOT.positions(other)
        assert np.allclose(lifted[:, 2], 0.5, atol=1e-6)
    finally:
        del MEASUREMENT_TYPES["height_toy"]


def test_a_kinematic_model_fitted_on_touches_is_the_same_model_file_and_predictor(tmp_path):
    from partcal.models.kinematic import KinematicModel
    from partcal.study.persist import load_model, save_model
    rng = np.random.default_rng(11)
    true = _true_robot(rng)
    planes = {"top": ([0, 0, 1], 300.0), "step": ([0, 0, 1], 100.0), "side": ([1, 0, 0], 700.0)}
    q, names = _touches(true, rng, planes, 120, 0.01)
    rows = _rows(q, ["plane"] * len(q), texts={"feature": tuple(names)})
    tied = {"planes": {"top": {}, "step": {"parallel_to": "top", "spacing_mm": -200.0}, "side": {}}}
    model = KinematicModel(robot=ROBOT, parametrization="dh").fit(q, None, rows=rows, cell=tied)
    table, _ = identify_measurements(ROBOT, rows, tied)
    other = _configurations(50, np.random.default_rng(4))
    expected = robot_with(ROBOT, table.value[:33]).positions(other) - ROBOT.positions(other)
    assert np.allclose(model.predict(other), expected, atol=1e-9)
    assert model.run_summary()["kinematic"]["rms_by_type"]["plane"] == pytest.approx(table.target_rms_mm["plane"])
    mean, std = model.std_validated(other)
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    path = tmp_path / "touches.json"
    save_model(model, path, robot=ROBOT)
    assert np.allclose(load_model(path)[0].predict(other), expected, atol=1e-9)
    with pytest.raises(DataError, match="residual model"):
        from partcal.models.series import ErrorModel
        KinematicModel(robot=ROBOT, residual=ErrorModel(solver="lstsq")).fit(q, None, rows=rows, cell=tied)


def test_tracker_points_in_their_own_frame_are_registered_by_the_fit():
    rng = np.random.default_rng(21)
    true = _true_robot(rng)
    q = _configurations(60, rng)
    turn = matrix_from_rotation_vector(np.radians([2.0, -5.0, 40.0]))
    seen = (true.positions(q) - [2000.0, 100.0, -50.0]) @ turn + rng.normal(0, 0.02, (60, 3))  # tracker frame
    rows = _rows(q, ["point"] * 60, {"x_meas": seen[:, 0], "y_meas": seen[:, 1], "z_meas": seen[:, 2]})
    table, notes = identify_measurements(ROBOT, rows, {TRACKER_FRAME: True})
    assert table.target_rms_mm["point"] < 0.03
    assert _score(true, table.value[:33], "dh", np.random.default_rng(0), rigid=True) < 0.03
    assert any(n.startswith("point: the tracker's frame") for n in notes)


@pytest.mark.parametrize("name", ["point", "plane", "fixed", "distance"])
def test_the_reader_requires_what_each_type_declares_required(name, tmp_path):
    """A row of each built-in type with every declared column empty: refused naming the first required one and
    the list of those the type requires, as its declaration says."""
    from partcal.data.measurement_rows import read_measurement_rows
    cls = MEASUREMENT_TYPES[name]
    assert cls.reads == tuple(cls.columns) and cls.summary and cls.unit
    required = [c for c, column in cls.columns.items() if column.required]
    path = tmp_path / "rows.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,measurement," + ",".join(cls.columns) + "\n0,-90,90,0,90,0," + name +
                    "," * len(cls.columns) + "\n")
    with pytest.raises(DataError, match=rf"rows.csv:2: column '{required[0]}': expected a value on a {name} row "
                                        rf"\({name} rows read {', '.join(required)}\)"):
        read_measurement_rows(path, "universal_robots_ur10")


def test_several_targets_and_the_orientation_on_the_seam_agree_with_the_tracker_path():
    """The virtual UR10 of configs/ur10_targets_virtual.yaml (three reflectors and a T-Mac's orientation):
    identified by ``identify`` with its targets and orientation (its further targets started at their nominal
    offsets), and by ``identify_measurements`` from the same data as a measurement run reads them (a ``target`` column, the
    orientation on the primary rows; the targets started from the data): the same robot, targets and probe."""
    from pathlib import Path

    from partcal.data.simulate import load_study, simulate
    from partcal.calibration.identification import identify
    from partcal.calibration.identification import extra_from
    from partcal.robot.kinematics import flange_offset
    from partcal.study.measurement_run import point_rows

    study = load_study(Path(__file__).resolve().parent.parent / "configs" / "ur10_targets_virtual.yaml")
    data = simulate(study)["identification"]
    robot = study.robot.nominal
    n = len(data)
    flange = robot.flange(data.q_deg)
    targets = {t: (flange_offset(flange, data.nominal_of(t)), data.measured_of(t) - data.nominal_of(t))
               for t in data.target_names[1:]}
    old = identify(robot, data.q_deg, data.measured_mm,
                   extra=extra_from(robot, data.q_deg, targets, data.orientation_errors_deg))
    names = ["", *data.target_names[1:]]
    rows = point_rows(data, "identification.csv")         # what a measurement run makes of such a point CSV
    assert rows.texts["target"] == tuple(t for t in names for _ in range(n))
    assert np.isfinite(rows.numbers["rx_meas"]).sum() == n
    new, _ = identify_measurements(robot, rows, {})
    assert new.rank == old.rank            # of exactly dependent parameters they may hold different ones
    other = _configurations(300, np.random.default_rng(1))
    before = robot_with(robot, old.value[:33]).forward(other)
    after = robot_with(robot, new.value[:33]).forward(other)
    assert np.abs(after[:, :3, 3] - before[:, :3, 3]).max() < 1e-6
    assert np.abs(after[:, :3, :3] - before[:, :3, :3]).max() < 1e-9
    was, found = dict(zip(old.names, old.value)), dict(zip(new.names, new.value))
    for t in names[1:]:                 # each further target where both put it
        tool = np.array([was[f"tool@{t}.{c}"] for c in "xyz"])
        expected = robot_with(robot, np.concatenate([old.value[:24], tool, old.value[27:33]])).positions(other)
        offset = np.array([found[f"tool@{t}.{c}"] for c in "xyz"])           # on the flange, as the tracker path's
        placed = robot_with(robot, np.concatenate([new.value[:24], offset, new.value[27:33]])).positions(other)
        assert np.abs(placed - expected).max() < 1e-6
    probe = [found[f"probe.r{c}"] for c in "xyz"]
    assert np.allclose(probe, old.value[-3:], atol=1e-7)


def test_each_measurement_type_says_how_many_rows_name_each_plane_and_point():
    from partcal.calibration.registry import built_types
    q = _configurations(12, np.random.default_rng(4))
    feature = ["top", "step", "top", "step", "top", "step", "top", "a", "b", "a", "a", "b"]
    rows = _rows(q, ["plane"] * 7 + ["fixed"] * 5, numbers={"flush": np.array([1, 0, 1] + [np.nan] * 9)},
                 texts={"feature": tuple(feature)})
    plane, fixed = built_types(rows, {})
    assert plane.describe() == "7 touches on 2 planes (top 4, step 3), 2 flush"
    assert fixed.describe() == "5 visits of 2 fixed points (a 3, b 2)"


def test_a_tied_plane_touched_alone_measures_no_length_and_the_scale_is_named():
    from partcal.calibration.stacked import observability
    rng = np.random.default_rng(12)
    true = _true_robot(rng)
    q, names = _touches(true, rng, {"step": ([0, 0, 1], 100.0), "side": ([1, 0, 0], 700.0)}, 60, 0.01)
    rows = _rows(q, ["plane"] * len(q), texts={"feature": tuple(names)})
    tied = {"planes": {"top": {}, "step": {"parallel_to": "top", "spacing_mm": -200.0}, "side": {}}}
    notes, _ = observability(ROBOT, rows, tied)          # top never touched: the 200 mm is no length measured
    assert notes[0].startswith(SCALE), notes
    given = {"planes": {"top": {"normal": [0, 0, 1], "offset_mm": 300.0},
                        "step": {"parallel_to": "top", "spacing_mm": -200.0}, "side": {}}}
    assert observability(ROBOT, rows, given)[0][0].startswith(SCALE)   # an approximate top is still fitted
    q2, names2 = _touches(true, rng, {"top": ([0, 0, 1], 300.0)}, 60, 0.01)
    both = _rows(np.vstack([q, q2]), ["plane"] * (len(q) + len(q2)), texts={"feature": tuple(names + names2)})
    assert not any(n.startswith(SCALE) for n in observability(ROBOT, both, tied)[0])


def test_a_point_tied_to_one_never_visited_is_refused_naming_file_line_and_column():
    from partcal.calibration.stacked import observability
    q = _configurations(4, np.random.default_rng(5))
    positions = ROBOT.positions(q)
    q = _newton(ROBOT, q, lambda p: positions[0] - p)               # four orientations, one point
    rows = _rows(q, ["fixed"] * 4, texts={"feature": ("b",) * 4})
    cell = {"points": {"a": {}, "b": {"distance_to": "a", "distance_mm": 1000.0}}}
    with pytest.raises(DataError, match=r"^test\.csv:2: column 'feature': fixed point 'b' is tied to 'a' by "
                                        r"distance_mm .*no row visits 'a'"):
        observability(ROBOT, rows, cell)


def test_each_measurement_type_moves_its_unknowns_with_the_cell_as_its_residuals_say(monkeypatch):
    """A rigid motion of the whole cell (the robot's base, every type's unknowns by ``moved``) leaves the residuals
    that do not turn unchanged, and turns the x, y, z triples that do: checked by central differences, to 1e-5 mm
    per unit of motion (their own error is about 1e-7 where the residuals reach 7,000 mm). The tracker stands
    2.5 m from the base, turned 30 degrees, so that its place turns with the cell. (A flush touch's tilts, read
    against fixed axes, do neither: their part is left out of the consistent Jacobian as the tilts of consistent
    data are small; this test has none.)"""
    from scipy.spatial.transform import Rotation
    from partcal.calibration.identifiability import rigid_directions
    for module in (plane_contacts, fixed_points):     # random poses: no touch is near its plane
        monkeypatch.setattr(module, "NEAR_MM", 1e9)
    monkeypatch.setattr(plane_contacts, "GIVEN_NORMAL_DEG", 180.0)
    monkeypatch.setattr(checks, "LENGTH_FACTOR", 1e9)  # nor does a known length agree with them
    rng = np.random.default_rng(9)
    rows, cell = _mixed_rows(rng)
    cell = {**cell, TRACKER_FRAME: True}
    numbers = {k: v for k, v in rows.numbers.items() if not k.startswith("r") and k != "flush"}
    turn, place = Rotation.from_euler("z", 30.0, degrees=True).as_matrix(), np.array([2500.0, -300.0, 100.0])
    seen = (np.column_stack([numbers[c] for c in ("x_meas", "y_meas", "z_meas")]) - place) @ turn   # tracker frame
    numbers.update({"x_meas": seen[:, 0], "y_meas": seen[:, 1], "z_meas": seen[:, 2]})
    texts = {**rows.texts, "target": ("",) * len(rows)}           # four primary points: the tracker is placed
    rows = MeasurementRows(rows.q_deg, rows.types, rows.ids, rows.lines, rows.source, numbers, texts)
    measurements = [k for k in (cls.build(rows, cell) for cls in MEASUREMENT_TYPES.values()) if k is not None]
    problem = StackedProblem(ROBOT, None, rows, measurements, np.zeros(len(rows)), "dh")
    tracker = [problem.own + [n for n, _ in problem.names].index(f"tracker.{c}") for c in "xyz"]
    assert np.linalg.norm(problem.start[tracker]) > 2000.0
    directions = rigid_directions(problem)
    base = problem(problem.start, jacobian=False)[0]
    chain = problem.chain(problem.start, False)
    turning = np.concatenate([
        k.residuals(chain.positions, chain.rotations, u).turning if
        k.residuals(chain.positions, chain.rotations, u).turning is not None else
        np.zeros(k.residuals(chain.positions, chain.rotations, u).values.size, dtype=bool)
        for k, u in zip(problem.measurements, problem.split(problem.start))])
    step = 1e-5
    for g in range(6):
        change = (problem(problem.start + step * directions[:, g], jacobian=False)[0] -
                  problem(problem.start - step * directions[:, g], jacobian=False)[0]) / (2 * step)
        expected = np.zeros_like(base)
        if g >= 3:                  # a triple that turns: e_k x r
            at = np.flatnonzero(turning)
            expected[at] = np.cross(np.eye(3)[g - 3], base[at].reshape(-1, 3)).ravel()
        np.testing.assert_allclose(change, expected, atol=1e-5, err_msg=f"rigid motion {g}")


@pytest.mark.parametrize("factor", [1e-3, 1e3])
def test_distances_from_a_tool_the_nominal_robot_lacks_are_accepted_and_a_wrong_unit_refused(factor):
    """A 93 mm reflector on a robot whose nominal tool is nil (the IPA UR10 from distances alone): short distances
    differ from the nominal ones by tens of mm and are data, not bad input; a long distance in metres (a thousand
    times too short) or in micrometres (a thousand times too long) is refused."""
    rng = np.random.default_rng(14)
    values = nominal_values(ROBOT)
    values[24:27] = [0.0, 0.0, 93.0]
    true = robot_with(ROBOT, values)
    q = _configurations(40, rng)
    q[1] = q[0] + [0, 0, 0, 0, 20.0, 0]            # two poses whose tips are close: the tool dominates
    tips = true.positions(q)
    i, j = np.triu_indices(len(q), 1)
    measured = np.linalg.norm(tips[i] - tips[j], axis=1)
    nominal = np.linalg.norm(ROBOT.positions(q)[i] - ROBOT.positions(q)[j], axis=1)
    assert np.max(np.abs(measured - nominal)) > 20.0          # beyond the touches' NEAR_MM
    rows = _rows(np.vstack([q, q[i]]), ["pose"] * len(q) + ["distance"] * i.size,
                 {"distance_mm": np.concatenate([np.full(len(q), np.nan), measured])},
                 {"to": tuple([""] * len(q) + [str(k + 1) for k in j])})
    table, _ = identify_measurements(ROBOT, rows, {})
    assert table.target_rms_mm["distance"] < 1e-6
    long = int(np.argmax(nominal))
    wrong = measured.copy()
    wrong[long] *= factor
    rows = _rows(rows.q_deg, rows.types, {"distance_mm": np.concatenate([np.full(len(q), np.nan), wrong])},
                 rows.texts)
    with pytest.raises(DataError, match=rf"test.csv:{len(q) + long + 2}: column 'distance_mm': .*\(metres\?\)"):
        identify_measurements(ROBOT, rows, {})


def _touches_at(orientation_deg):
    """Six touches of the plane z = 400 mm by the nominal UR10's tool, at six places, the tool pointing down and
    turned about x by ``orientation_deg[k]`` degrees at touch ``k``: their rows and the plane's cell."""
    from scipy.spatial.transform import Rotation
    places = np.array([[700.0, -300, 400], [800, 0, 400], [700, 300, 400], [900, -200, 400], [900, 200, 400],
                       [600, 0, 400]])
    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("x", 180.0 + np.asarray(orientation_deg)[:, None], degrees=True).as_matrix()
    poses[:, :3, 3] = places
    q = np.full((6, 6), np.nan)
    for seed in _configurations(40, np.random.default_rng(3)):
        ik = ROBOT.inverse_pose(poses, np.tile(seed, (6, 1)))
        q[np.isnan(q[:, 0]) & ik.success] = ik.q_deg[np.isnan(q[:, 0]) & ik.success]
        if np.isfinite(q).all():
            break
    assert np.isfinite(q).all()
    return (_rows(q, ["plane"] * 6, texts={"feature": ("top",) * 6}),
            {"planes": {"top": {"normal": [0.0, 0.0, 1.0], "offset_mm": 400.0}}})


def test_a_plane_touched_from_one_orientation_is_refused():
    """Touches with the tool never turned cannot tell the tool's length from the plane's place: refused naming the
    plane; the same places touched with the tool turned by up to 20 degrees are identified from."""
    rows, cell = _touches_at(np.zeros(6))
    with pytest.raises(DataError, match=r"test.csv:2: column 'feature': plane 'top' is touched from one orientation "
                                        r"of the tool only \(it turns less than 1 degree over the 6 touches\)"):
        identify_measurements(ROBOT, rows, cell)
    rows, cell = _touches_at([0.0, 10.0, 20.0, -10.0, -20.0, 5.0])
    table, _ = identify_measurements(ROBOT, rows, cell)
    assert table.target_rms_mm["plane"] < 1e-6
