"""partcal plan for measurement types: a measurements file judged, plane touches and fixed-point visits planned."""

import contextlib
import io

import numpy as np
import pytest

from partcal.data.measurement_rows import read_measurement_rows
from partcal.errors import PartcalError, UnreachableError
from partcal.calibration import design
from partcal.calibration.measurement import MeasurementRows, SCALE
from partcal.robot import load_robot
from partcal.study import plan, plan_measurements

UR10 = load_robot("universal_robots_ur10")
RANGES = {1: (-90.0, 90.0), 2: (-150.0, -30.0), 3: (-140.0, 140.0)}
GIVEN = {"planes": {"top": {"normal": [0.0, 0.0, 1.0], "offset_mm": 500.0},
                    "step": {"parallel_to": "top", "spacing_mm": -200.0},
                    "side": {"normal": [1.0, 0.0, 0.02], "offset_mm": 600.0}}}
# the same planes by hand: top z = 500, step z = 300, side (1, 0, 0.02) / |.| . p = 600
BY_HAND = {"top": (np.array([0.0, 0.0, 1.0]), 500.0), "step": (np.array([0.0, 0.0, 1.0]), 300.0),
           "side": (np.array([1.0, 0.0, 0.02]) / np.sqrt(1.0004), 600.0)}
FEATURES_YAML = """planes:
  top:  {normal: [0, 0, 1], offset_mm: 500}
  step: {parallel_to: top, spacing_mm: -200}
  side: {normal: [1, 0, 0.02], offset_mm: 600}
"""


def cli(*args):
    from partcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def pool():
    """Touch candidates of the three planes on the nominal UR10 (about 60 a plane)."""
    return plan_measurements.touch_candidates(UR10, GIVEN, "plane", 180, np.random.default_rng(5), ranges_deg=RANGES,
                                       floor=None)


def test_candidates_put_the_nominal_tip_on_their_plane(pool):
    tips = UR10.positions(pool.q_deg)
    for name, (normal, offset) in BY_HAND.items():
        mine = np.array([f == name for f in pool.texts["feature"]])
        assert mine.sum() >= 50
        np.testing.assert_allclose(tips[mine] @ normal, offset, atol=1e-5)
    assert UR10.within_limits(pool.q_deg).all()


def test_evaluate_names_the_scale_for_unknown_planes_and_not_for_the_tied_step(pool):
    loose = plan_measurements.evaluate_measurements(UR10, pool, {}, model=design.PlannedModel(parametrization="complete"))
    assert loose.notes[0].startswith(SCALE)
    approximate = {"planes": {"top": GIVEN["planes"]["top"], "step": {"normal": [0, 0, 1.0], "offset_mm": 300.0},
                              "side": GIVEN["planes"]["side"]}}
    assert plan_measurements.evaluate_measurements(UR10, pool, approximate).notes[0].startswith(SCALE)
    tied = plan_measurements.evaluate_measurements(UR10, pool, GIVEN, model=design.PlannedModel(parametrization="complete"))
    assert not any(note.startswith(SCALE) for note in tied.notes)
    assert any(note.startswith("plane") for note in tied.notes)
    # one length more is identified when the step ties the planes
    assert len(loose.held) == len(tied.held) + 1


def test_evaluate_of_tracker_points_as_measurement_types_is_the_pose_evaluation():
    """Point rows (0.02 mm, weight one) on the nominal tips: the same Jacobian as a tracker's pose set."""
    rng = np.random.default_rng(1)
    q = plan.candidates_within_limits(UR10, 40, rng)
    ws = plan.candidates_within_limits(UR10, 200, rng)
    p = UR10.positions(q)
    rows = MeasurementRows(q, ("point",) * 40, tuple(str(i) for i in range(40)), tuple(range(40)), "t",
                {"x_meas": p[:, 0], "y_meas": p[:, 1], "z_meas": p[:, 2]}, {})
    mine = plan_measurements.evaluate_measurements(UR10, rows, {}, workspace_q_deg=ws)
    ref = plan.evaluate_poses(UR10, q, space=plan.workspace(UR10, ws), noise_mm=0.02)
    assert mine.position_rms_mm == pytest.approx(ref.position_rms_mm, rel=1e-9)
    assert mine.indices.condition == pytest.approx(ref.indices.condition, rel=1e-9)
    assert set(mine.held) == set(ref.never) | set(ref.missing)
    assert not mine.notes


@pytest.mark.parametrize("noise", [0.02, 0.05])
def test_a_predicted_standard_error_is_the_stated_noise_times_the_jacobians(noise):
    """Tracker points of a stated noise: each identified parameter's predicted standard error is
    ``noise sqrt(diag((J^T J)^-1))`` in its own unit (mm, degrees), J the positions' central differences by the
    parameters the plan identifies (written out from the robot's fields: conftest.moved_positions)."""
    from conftest import moved_positions
    rng = np.random.default_rng(2)
    q = plan.candidates_within_limits(UR10, 40, rng)
    p = UR10.positions(q)
    rows = MeasurementRows(q, ("point",) * 40, tuple(str(i) for i in range(40)), tuple(range(40)), "t",
                {"x_meas": p[:, 0], "y_meas": p[:, 1], "z_meas": p[:, 2]}, {})
    got = plan_measurements.evaluate_measurements(UR10, rows, {"noise": {"point": noise}},
                                    workspace_q_deg=plan.candidates_within_limits(UR10, 20, rng))
    free = np.flatnonzero(np.isfinite(got.std_error))
    assert {got.units[k] for k in free} == {"mm", "deg"} and free.size > 20
    jac = np.column_stack([(moved_positions(UR10, q, k, 1e-5) - moved_positions(UR10, q, k, -1e-5)).ravel() / 2e-5
                           for k in free])
    expected = noise * np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
    np.testing.assert_allclose(got.std_error[free], expected, rtol=1e-4)


def test_planned_touches_beat_random_draws_of_the_same_candidates(pool):
    result = plan_measurements.plan_measurements(UR10, 40, GIVEN, "plane", candidates=pool, random_state=3)
    planned = design.information_logdet(result.blocks, result.chosen)
    rng = np.random.default_rng(0)
    random = [design.information_logdet(result.blocks, rng.choice(len(pool), 40, replace=False)) for _ in range(30)]
    assert planned > max(random)
    assert set(result.rows.texts["feature"]) == {"top", "step", "side"}
    tips = UR10.positions(result.rows.q_deg)
    for tip, name in zip(tips, result.rows.texts["feature"]):
        normal, offset = BY_HAND[name]
        assert tip @ normal == pytest.approx(offset, abs=1e-5)


def test_plan_writes_a_measurements_file_whose_nominal_tips_lie_on_their_planes(tmp_path):
    cell = tmp_path / "cell.yaml"
    cell.write_text(FEATURES_YAML)
    out = tmp_path / "touches.csv"
    code, text, err = cli("plan", "universal_robots_ur10", "-q", "-n", 45, "-o", out, "--cell", cell,
                          "--measurement", "plane", "--pool", 300)
    assert code == 0, err
    table = read_measurement_rows(out, UR10)
    assert len(table) == 45 and set(table.types) == {"plane"}
    tips = UR10.positions(table.q_deg)
    for tip, name in zip(tips, table.texts["feature"]):
        normal, offset = BY_HAND[name]
        assert tip @ normal == pytest.approx(offset, abs=1e-4)       # 6 decimals of a degree in the file
    assert "wrote 45 plane rows" in text and "the plan leaves unidentifiable" in text
    assert "scale" not in text.split("the plan leaves unidentifiable")[1]
    # the written file judged with all planes unknown: the scale is named
    code, text, err = cli("plan", "universal_robots_ur10", "--evaluate", out)
    assert code == 0, err
    assert f"  {SCALE}: nothing here measures a length" in text


def test_planned_visits_bring_the_nominal_tip_to_the_known_points(tmp_path):
    points = {"sphere": [0.0, -600.0, 700.0], "cone": [-500.0, 0.0, 500.0]}
    cell = {"points": {name: {"known_mm": p} for name, p in points.items()}}
    result = plan_measurements.plan_measurements(UR10, 20, cell, "fixed", pool=120, random_state=1, ranges_deg=RANGES)
    tips = UR10.positions(result.rows.q_deg)
    for tip, name in zip(tips, result.rows.texts["feature"]):
        np.testing.assert_allclose(tip, points[name], atol=1e-5)
    assert set(result.rows.texts["feature"]) == set(points)
    # the tool's orientation differs from visit to visit
    z = UR10.forward(result.rows.q_deg)[:, :3, 2]
    assert np.linalg.svd(z - z.mean(axis=0), compute_uv=False)[1] > 0.1


@pytest.mark.parametrize("yaml_text, measurement, message", [
    ("planes:\n  top: {}\n", "plane", r"cell.yaml: planes.top: a plane without normal and offset_mm cannot be planned"),
    ("planes:\n  step: {parallel_to: top, spacing_mm: -200}\n  top: {}\n", "plane",
     r"planes.step: a plane without normal and offset_mm .*parallel_to 'top'"),
    ("points:\n  nest: {}\n", "fixed", r"cell.yaml: points.nest: a fixed point without known_mm cannot be planned"),
    ("points:\n  far: {known_mm: [9000, 0, 0]}\n", "fixed", r"cell.yaml: points.far: out of reach"),
    ("planes:\n  top: {normal: [0, 0, 1], offset_mm: 500, colour: red}\n", "plane", r"planes.top.colour .*unknown key"),
])
def test_bad_features_are_refused_naming_file_and_key(tmp_path, yaml_text, measurement, message):
    cell = tmp_path / "cell.yaml"
    cell.write_text(yaml_text)
    code, _, err = cli("plan", "universal_robots_ur10", "-q", "-n", 30, "-o", tmp_path / "out.csv", "--cell",
                       cell, "--measurement", measurement, "--pool", 60)
    assert code == 2
    assert __import__("re").search(message, err), err
    assert "Traceback" not in err and not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("args, message", [
    (["-n", 30, "-o", "x.csv", "--measurement", "plane"], r"--measurement plane: give -n N -o ROWS.csv --cell"),
    (["-n", 30, "-o", "x.csv", "--cell", "cell.yaml"], r"--cell goes with --measurement"),
    (["-n", 2, "-o", "x.csv", "--cell", "cell.yaml", "--measurement", "plane", "--pool", 60],
     r"number of plane rows must be a whole number in \[\d+, \d+\]"),
    (["-n", 30, "-o", "x.csv", "--cell", "cell.yaml", "--measurement", "plane", "--curve"], r"--curve goes with"),
])
def test_bad_options_are_refused(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cell.yaml").write_text(FEATURES_YAML)
    code, _, err = cli("plan", "universal_robots_ur10", "-q", *args)
    assert code == 2
    assert __import__("re").search(message, err), err


def test_an_unreachable_plane_is_refused_from_python():
    far = {"planes": {"high": {"normal": [0.0, 0.0, 1.0], "offset_mm": 5000.0}}}
    with pytest.raises(UnreachableError, match=r"planes.high: out of reach of universal_robots_ur10"):
        plan_measurements.touch_candidates(UR10, far, "plane", 10, np.random.default_rng(0))
    with pytest.raises(PartcalError, match=r"--measurement must be one of plane, fixed, camera \(a type without candidate poses cannot be planned\); got 'distance'"):
        plan_measurements.feature_targets(GIVEN, "distance", "cell.yaml")


@pytest.mark.parametrize("model", [design.DH, design.PlannedModel(parametrization="complete"),
                                   design.PlannedModel(base=False), design.PlannedModel(tool=False, joint_harmonics=1)])
def test_the_design_identifies_what_the_fit_does_not_hold(pool, model):
    """The planner's identified columns are exactly the parameters asked for that observability does not hold."""
    d = plan_measurements.stacked_design(UR10, pool, GIVEN, model)
    names = [n for n, _ in d.names]
    free = {names[i] for i in d.free}
    asked = {n for n in names
             if (model.base or not n.startswith("base.")) and (model.tool or not n.startswith("tool."))}
    assert free.isdisjoint(d.held) and free | set(d.held) == asked
