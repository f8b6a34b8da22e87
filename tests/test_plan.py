"""Planning the measurement: observability indices, predicted uncertainty, DETMAX, ``partcal plan``."""

import contextlib
import io

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from partcal.data.measurements import read_columns, read_measurements
from partcal.calibration import design
from partcal.calibration.parameters import parameter_names
from partcal.robot import load_robot
from partcal.robot.kinematics import Robot
from partcal.study import plan

DATA = ROOT / "data" / "sk120"


def planar_arm(a1=400.0, a2=300.0) -> Robot:
    """Two links in the x-y plane: ``p = (a1 c1 + a2 c12, a1 s1 + a2 s12, 0)``."""
    return Robot(name="planar", n_joints=2, alpha_deg=np.zeros(2), d_mm=np.zeros(2), a_mm=np.array([a1, a2]),
                 theta_offset_deg=np.zeros(2), coupling=np.eye(2), tool_mm=np.zeros(3),
                 limits_deg=np.array([[-170.0, 170.0], [-150.0, 150.0]]), home_deg=np.zeros(2))


def columns(robot, names):
    index = [n for n, _ in parameter_names(robot)]
    return [index.index(n) for n in names]


def cli(*args):
    from partcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


# ---------------------------------------------------------------------- indices by hand
def test_the_jacobian_of_a_planar_arm_is_the_hand_derived_one():
    robot = planar_arm()
    q = np.array([[30.0, 45.0], [-60.0, 100.0], [10.0, -20.0]])
    jac, wanted = design.model_jacobian(robot, q)
    c1, s1 = np.cos(np.radians(q[:, 0])), np.sin(np.radians(q[:, 0]))
    c12, s12 = np.cos(np.radians(q.sum(1))), np.sin(np.radians(q.sum(1)))
    zero, per_deg = np.zeros(3), np.pi / 180
    hand = {"a[1]": np.column_stack([c1, s1, zero]), "a[2]": np.column_stack([c12, s12, zero]),
            "theta[1]": np.column_stack([-400 * s1 - 300 * s12, 400 * c1 + 300 * c12, zero]) * per_deg,
            "theta[2]": np.column_stack([-300 * s12, 300 * c12, zero]) * per_deg}
    got = jac[:, columns(robot, list(hand))]
    np.testing.assert_allclose(got, np.column_stack([v.ravel() for v in hand.values()]), atol=1e-12)
    assert wanted.all()
    assert not design.model_jacobian(robot, q, design.PlannedModel(base=False, tool=False))[1][-9:].any()


def test_indices_match_a_hand_computation_on_two_poses():
    # a1, a2 from the poses (0, 0) and (0, 90): J = [[1, 1], [0, 0], [0, 0], [1, 0], [0, 1], [0, 0]],
    # J^T J = [[2, 1], [1, 2]] with eigenvalues 3 and 1, so the singular values are sqrt(3) and 1
    robot = planar_arm()
    q = np.array([[0.0, 0.0], [0.0, 90.0]])
    jac = design.model_jacobian(robot, q)[0][:, columns(robot, ["a[1]", "a[2]"])]
    np.testing.assert_allclose(jac, [[1, 1], [0, 0], [0, 0], [1, 0], [0, 1], [0, 0]], atol=1e-12)
    ind = design.indices(jac, 2)
    assert ind.o1 == pytest.approx(3**0.25 / np.sqrt(2))
    assert ind.condition == pytest.approx(np.sqrt(3))
    assert ind.smallest == pytest.approx(1.0)
    assert ind.noise_amplification == pytest.approx(1 / np.sqrt(3))
    assert (ind.n_poses, ind.n_parameters) == (2, 2)
    # covariance sigma^2 (J^T J)^-1 = sigma^2 / 3 [[2, -1], [-1, 2]]; at the pose (0, 0) the position moves
    # by da1 + da2 along x, whose variance is sigma^2 / 3 (2 - 1 - 1 + 2)
    cov = design.parameter_covariance(jac, 0.05)
    np.testing.assert_allclose(cov, 0.05**2 / 3 * np.array([[2, -1], [-1, 2]]), atol=1e-15)
    assert design.position_std(jac[None, :3], cov)[0] == pytest.approx(0.05 * np.sqrt(2 / 3))


def test_a_rank_deficient_set_has_infinite_condition_and_zero_o1():
    ind = design.indices(np.array([[1.0, 2.0], [2.0, 4.0], [0.0, 0.0]]), 1)
    assert ind.condition == np.inf and ind.smallest == pytest.approx(0, abs=1e-12) and ind.o1 < 1e-6


def test_angles_are_scaled_to_the_arc_at_the_reach():
    robot = planar_arm()
    scales = design.parameter_scales(robot)
    units = [u for _, u in parameter_names(robot)]
    for s, unit in zip(scales, units):
        assert s == (1.0 if unit == "mm" else pytest.approx(180 / (np.pi * 700.0)))


def test_evaluate_names_what_a_set_without_elbow_motion_cannot_identify():
    robot = planar_arm()
    space = plan.workspace(robot, random_state=0, n_poses=200)
    stiff = np.column_stack([np.linspace(-150, 150, 12), np.full(12, 40.0)])     # the elbow never moves
    weak = plan.evaluate_poses(robot, stiff, space=space)
    full = plan.evaluate_poses(robot, space.q_deg[:12], space=space)
    assert full.missing == () and len(weak.missing) >= 1
    assert set(weak.missing) | set(weak.identified) == set(full.identified)
    assert np.isnan(weak.std_error[columns(robot, list(weak.missing))]).all()
    # every parameter is in exactly one group
    groups = [set(full.identified), set(full.missing), set(full.never)]
    assert sum(len(g) for g in groups) == len(full.names) and set().union(*groups) == set(full.names)
    # the tool's height is z = d1 + d2 + tool.z + base.z at every pose: one of the four is identified
    assert len({"d[1]", "d[2]", "tool.z", "base.z"} & set(full.identified)) == 1


def test_predicted_standard_errors_scale_with_the_noise_and_match_monte_carlo():
    robot = planar_arm()
    space = plan.workspace(robot, random_state=1, n_poses=300)
    q = space.q_deg[:10]
    ev1, ev2 = (plan.evaluate_poses(robot, q, space=space, noise_mm=s) for s in (0.01, 0.04))
    np.testing.assert_allclose(ev2.std_error, 4 * ev1.std_error, rtol=1e-9)
    assert ev2.position_rms_mm == pytest.approx(4 * ev1.position_rms_mm)
    # Monte Carlo on the linear model: least squares on noisy data gives the predicted spread
    jac = design.model_jacobian(robot, q)[0]
    own = [ev1.names.index(n) for n in ev1.identified]
    rng = np.random.default_rng(0)
    estimates = np.linalg.lstsq(jac[:, own], rng.normal(0, 0.01, (jac.shape[0], 4000)), rcond=None)[0]
    np.testing.assert_allclose(estimates.std(axis=1), ev1.std_error[own], rtol=0.06)


# ---------------------------------------------------------------------- DETMAX
@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 5), st.integers(1, 3), st.integers(0, 12))
def test_detmax_never_returns_a_smaller_determinant_than_its_start(seed, width, rows, extra):
    rng = np.random.default_rng(seed)
    n = max(1, -(-width // rows)) + rng.integers(0, 3)
    count = n + 1 + extra
    blocks = rng.normal(size=(count, rows, width)) * rng.uniform(0.1, 10, size=width)
    singular = rng.random() < 0.3
    if singular:
        blocks[:, :, -1] = blocks[:, :, 0]                  # a singular problem: det 0 for every design
    start = rng.choice(count, n, replace=False)
    result = design.detmax(blocks, n, start=start)

    def det(chosen):
        b = blocks[chosen]
        return np.linalg.det(np.einsum("nik,nil->kl", b, b))

    assert len(set(result.indices.tolist())) == n and result.indices.size == n
    assert result.logdet >= result.start_logdet
    if not singular:
        assert det(result.indices) >= det(start) * (1 - 1e-9)


def test_detmax_finds_the_best_pair_of_a_small_problem():
    # candidates along the axes of the plane with lengths 1..5: the best two are the longest of each axis
    blocks = np.array([[[1.0, 0.0]], [[3.0, 0.0]], [[5.0, 0.0]], [[0.0, 1.0]], [[0.0, 4.0]], [[0.0, 2.0]]])
    result = design.detmax(blocks, 2, start=[0, 1])
    assert result.indices.tolist() == [2, 4]
    assert result.logdet == pytest.approx(np.log(400.0), abs=1e-6)


def test_detmax_refuses_a_bad_size_or_start():
    blocks = np.ones((4, 3, 2))
    with pytest.raises(ValueError, match=r"design size must be in \[1, 4\].*got 5"):
        design.detmax(blocks, 5)
    with pytest.raises(ValueError, match="start must be 2 distinct candidate indices"):
        design.detmax(blocks, 2, start=[1, 1])


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 5), st.integers(1, 3))
def test_the_i_optimal_bound_is_below_every_exact_design(seed, width, rows):
    rng = np.random.default_rng(seed)
    count = 12
    blocks = rng.normal(size=(count, rows, width)) * rng.uniform(0.1, 10, size=width)
    test = rng.normal(size=(40, width))
    target = test.T @ test / 40
    result = design.i_optimal_bound(blocks, target)
    assert result.bound <= result.value * (1 + 1e-12) and result.weights.sum() == pytest.approx(1.0)
    uniform = np.einsum("cri,crj->ij", blocks, blocks) / count
    assert result.value <= np.trace(np.linalg.solve(uniform, target)) * (1 + 1e-9)   # never worse than its start
    n = max(-(-width // rows), 1) + 1
    for start in (None, rng.choice(count, n, replace=False)):
        chosen = design.detmax(blocks, n, start=start, random_state=seed).indices if start is None else start
        b = blocks[chosen].reshape(-1, width)
        if np.linalg.matrix_rank(b) == width:
            assert n * np.trace(np.linalg.solve(b.T @ b, target)) >= result.bound * (1 - 1e-9)


# ---------------------------------------------------------------------- planning
@pytest.fixture(scope="module")
def sk120_space(sk120):
    return plan.workspace(sk120, random_state=3, n_poses=400)


def test_a_plan_of_the_sk120_respects_its_limits_and_beats_random_sets(sk120, sk120_space):
    result = plan.plan_poses(sk120, 15, space=sk120_space, random_state=0)
    assert result.q_deg.shape == (15, 6) and sk120.within_limits(result.q_deg).all()
    q23 = result.q_deg[:, 1] - result.q_deg[:, 2]
    assert ((q23 >= 10) & (q23 <= 120)).all()
    np.testing.assert_array_equal(result.q_deg, sk120_space.q_deg[result.chosen])
    assert result.exchange.logdet > result.exchange.start_logdet
    rng = np.random.default_rng(1)
    random = [plan.evaluate_poses(sk120, sk120_space.q_deg[rng.choice(400, 15, replace=False)], space=sk120_space)
              for _ in range(9)]
    assert result.evaluation.indices.o1 > np.median([r.indices.o1 for r in random])
    assert result.evaluation.position_rms_mm < np.median([r.position_rms_mm for r in random])


def test_the_pose_count_is_checked_against_parameters_and_candidates(sk120, sk120_space):
    k = sk120_space.structural.size
    with pytest.raises(ValueError, match=rf"whole number in \[{-(-k // 3)}, 400\].*identifiable parameters.*got 2"):
        plan.plan_poses(sk120, 2, space=sk120_space)
    with pytest.raises(ValueError, match=r"at most the 400 candidates; got 401"):
        plan.plan_poses(sk120, 401, space=sk120_space)


def test_box_candidates_put_the_tool_inside_the_box(sk120):
    box = np.array([[1000.0, -800.0, 0.0], [2500.0, 800.0, 1500.0]])
    q = plan.candidates_within_limits(sk120, 50, np.random.default_rng(0), box)
    p = sk120.positions(q)
    assert sk120.within_limits(q).all() and np.all((p >= box[0]) & (p <= box[1]))
    with pytest.raises(ValueError, match=r"admissible with the tool inside the box"):
        plan.candidates_within_limits(sk120, 5, np.random.default_rng(0), np.array([[9e3] * 3, [9.1e3] * 3]))


def test_the_curve_falls_with_the_pose_count(sk120, sk120_space):
    rows = plan.pose_curve(sk120, [10, 20, 40], space=sk120_space, random_state=0)
    rms = [r["position_rms_mm"] for r in rows]
    assert rms[0] > rms[1] > rms[2]
    assert all(r["position_rms_mm"] <= r["random_position_rms_mm"] for r in rows)


# ---------------------------------------------------------------------- joint errors in the plan
def test_harmonic_columns_are_the_joint_columns_times_sin_and_cos_by_hand():
    robot = planar_arm()
    q = np.array([[30.0, 45.0], [-60.0, 100.0], [10.0, -20.0]])
    model = design.PlannedModel(joint_harmonics=(1, 2))
    names = [n for n, _ in design.model_parameters(robot, model)[0]]
    jac = design.model_jacobian(robot, q, model)[0]
    assert names[-6:] == ["sin1[1]", "cos1[1]", "sin1[2]", "cos1[2]", "sin2[2]", "cos2[2]"]
    c1, s1 = np.cos(np.radians(q[:, 0])), np.sin(np.radians(q[:, 0]))
    c12, s12 = np.cos(np.radians(q.sum(1))), np.sin(np.radians(q.sum(1)))
    per_deg, zero = np.pi / 180, np.zeros(3)
    turn1 = np.column_stack([-400 * s1 - 300 * s12, 400 * c1 + 300 * c12, zero]) * per_deg   # d p / d q1, mm/deg
    turn2 = np.column_stack([-300 * s12, 300 * c12, zero]) * per_deg
    r1, r2 = np.radians(q[:, 0])[:, None], np.radians(q[:, 1])[:, None]
    hand = [turn1 * np.sin(r1), turn1 * np.cos(r1), turn2 * np.sin(r2), turn2 * np.cos(r2), turn2 * np.sin(2 * r2),
            turn2 * np.cos(2 * r2)]
    np.testing.assert_allclose(jac[:, -6:], np.column_stack([h.ravel() for h in hand]), atol=1e-12)


def test_an_arm_turning_about_vertical_axes_has_no_gravity_torque_to_plan_for():
    robot = planar_arm()
    model = design.PlannedModel(compliance=(1, 2), payload_kg=10.0)
    space = plan.workspace(robot, model=model, random_state=0, n_poses=200)
    ev = plan.evaluate_poses(robot, space.q_deg[:10], space=space)
    assert {"compliance[1]", "compliance[2]", "sag[1,f2]"} <= set(ev.never)
    assert not any(n.startswith(("sag", "compliance")) for n in ev.identified)


def test_compliance_is_planned_for_by_its_sags_at_any_one_payload(sk120):
    at_rest, loaded = (design.PlannedModel(compliance=(2, 3), payload_kg=p) for p in (0.0, 40.0))
    spaces = [plan.workspace(sk120, model=m, random_state=3, n_poses=400) for m in (at_rest, loaded)]
    evs = [plan.plan_poses(sk120, 25, space=s, random_state=0).evaluation for s in spaces]
    for ev in evs:
        assert ev.missing == () and any(n.startswith("sag[2,") for n in ev.identified)
        assert any(n.startswith("sag[3,") for n in ev.identified)
    # at one payload, zero or not, the compliance is the tool point's share of the sags: not identifiable, and
    # given no standard error (it had one at 40 kg: a plan at one payload cannot separate it)
    for ev, kg in zip(evs, (0, 40)):
        assert {"compliance[2]", "compliance[3]"} <= set(ev.never)
        assert f"a compliance is not identifiable from data at one payload ({kg} kg)" in ev.lines()[2]
        assert not {"compliance[2]", "compliance[3]"} & set(ev.identified)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_plan_with_harmonics_identifies_what_random_sets_do_and_raises_its_determinant(sk120, seed):
    model = design.PlannedModel(joint_harmonics=(1, 2, 2, 0, 0, 1))
    space = plan.workspace(sk120, model=model, random_state=seed, n_poses=300)
    result = plan.plan_poses(sk120, 20, space=space, random_state=seed)
    assert result.exchange.logdet >= result.exchange.start_logdet
    rng = np.random.default_rng(seed)
    harmonic = {n for n in result.evaluation.names if n.startswith(("sin", "cos"))}
    assert len(harmonic) == 12
    for _ in range(5):
        random = plan.evaluate_poses(sk120, space.q_deg[rng.choice(300, 20, replace=False)], space=space)
        assert (set(random.identified) & harmonic) <= set(result.evaluation.identified)
    assert harmonic - set(result.evaluation.never) <= set(result.evaluation.identified)


def test_a_workspace_of_another_model_is_refused(sk120, sk120_space):
    with pytest.raises(ValueError, match="differs from the workspace's"):
        plan.plan_poses(sk120, 15, space=sk120_space, model=design.PlannedModel(joint_harmonics=1))
    with pytest.raises(ValueError, match=r"compliance must be a list of distinct joint numbers in \[1, 6\].*\(7,\)"):
        plan.workspace(sk120, model=design.PlannedModel(compliance=(7,)))


# ---------------------------------------------------------------------- the command line
def test_plan_writes_a_pose_list_that_evaluate_reads(tmp_path):
    out = tmp_path / "poses.csv"
    code, stdout, err = cli("plan", "motoman_sk120", "-n", 12, "-o", out, "--pool", 300, "--seed", 4)
    assert code == 0, err
    assert f"wrote 12 poses to {out}" in stdout and "O1 " in stdout
    assert err.startswith("partcal: plan: motoman_sk120, DH with base and tool: ")
    cols, q, _ = read_columns(out, [["q1", "q2", "q3", "q4", "q5", "q6"]])
    _, nominal, _ = read_columns(out, [["x_nom", "y_nom", "z_nom"]])
    robot = load_robot("motoman_sk120")
    np.testing.assert_allclose(nominal, robot.positions(q), atol=2e-5)
    assert robot.within_limits(q).all()
    code, stdout2, err = cli("plan", "motoman_sk120", "--evaluate", out, "-q")
    assert code == 0 and err == ""
    assert "not identifiable from this set (joint-limit poses would identify them): none" in stdout2
    # the same seed gives the same file
    again = tmp_path / "again.csv"
    assert cli("plan", "motoman_sk120", "-n", 12, "-o", again, "--pool", 300, "--seed", 4, "-q")[0] == 0
    assert again.read_text() == out.read_text()


def test_plan_from_the_users_candidates(tmp_path):
    robot = load_robot("motoman_sk120")
    q = plan.candidates_within_limits(robot, 60, np.random.default_rng(5))
    cand = tmp_path / "cand.csv"
    cand.write_text("q1,q2,q3,q4,q5,q6\n" + "".join(",".join(f"{v:.6f}" for v in row) + "\n" for row in q))
    out = tmp_path / "poses.csv"
    code, stdout, err = cli("plan", "motoman_sk120", "-n", 20, "-o", out, "--candidates", cand, "-q")
    assert code == 0, err
    chosen = read_columns(out, [["q1", "q2", "q3", "q4", "q5", "q6"]])[1]
    assert all(np.abs(q - row).max(axis=1).min() < 1e-5 for row in chosen)


def test_plan_for_compliance_and_harmonics_from_the_command_line(tmp_path):
    out = tmp_path / "poses.csv"
    code, stdout, err = cli("plan", "motoman_sk120", "-n", 25, "-o", out, "--pool", 300, "--compliance", "2,3",
                            "--joint-harmonics", "1", "--payload-kg", 40, "-q")
    assert code == 0, err
    assert "sin1[2]" in stdout and "sag[2,f3]" in stdout and "compliance[3]" in stdout
    assert "(DH with base and tool; compliance of joints 2, 3 (payload 40 kg); 1 harmonics per joint)" in \
        out.read_text().splitlines()[0]
    code, evaluated, err = cli("plan", "motoman_sk120", "--evaluate", out, "--compliance", "2,3", "--joint-harmonics",
                               "1,1,1,0,0,0", "-q")
    assert code == 0, err
    assert "sag[2,f3]" in evaluated and "sin1[2]" in evaluated and "sin1[6]" not in evaluated


def test_a_joint_list_that_is_not_numbers_gets_one_line_and_exit_2(tmp_path):
    with pytest.raises(SystemExit) as exit_:
        cli("plan", "motoman_sk120", "-n", 10, "-o", tmp_path / "p.csv", "--compliance", "2;3")
    assert exit_.value.code == 2


@pytest.mark.parametrize("args, message", [
    (["plan", "no_such_robot", "-n", "10", "-o", "{tmp}/p.csv"], "robot 'no_such_robot': no such file"),
    (["plan", "motoman_sk120", "-n", "50", "-o", "{tmp}/p.csv", "--pool", "40"],
     r"at most the 40 candidates; got 50"),
    (["plan", "motoman_sk120", "-n", "3", "-o", "{tmp}/p.csv", "--pool", "200"], r"identifiable parameters .*got 3"),
    (["plan", "motoman_sk120", "-n", "10"], "-n N and -o POSES.csv go together"),
    (["plan", "motoman_sk120"], "give -n N -o POSES.csv"),
    (["plan", "motoman_sk120", "--evaluate", "{tmp}/bad.csv"], r"bad.csv:1: column 'q6' is missing"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--box", "1", "0", "0", "0", "1", "1"],
     "each min below its max"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--compliance", "2,7"],
     r"compliance must be a list of distinct joint numbers in \[1, 6\]"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--joint-harmonics", "1,2"],
     r"joint_harmonics must be an int in \[0, 8\] or a list of 6 such ints.*got \(1, 2\)"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--payload-kg", "-1"],
     r"payload_kg must be a number >= 0 \(kg\); got -1.0"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--noise-mm", "0"],
     "--noise-mm must be a positive number of mm; got 0.0"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/cand.csv", "--candidates", "{tmp}/cand.csv"],
     "is the candidate file"),
    (["plan", "motoman_sk120", "-n", "10", "-o", "{tmp}/p.csv", "--candidates", "{tmp}/outside.csv"],
     r"outside.csv: data row 2 .* outside the joint limits"),
    (["plan", "motoman_sk120", "--evaluate", "{tmp}/outside.csv"], r"outside.csv: data row 2 .* outside the joint limits"),
    (["plan", "motoman_sk120", "--evaluate", "{tmp}/rad.csv"],
     r"rad.csv:data row 1: every joint angle of the 6 poses lies within ±2.\d+ degrees: they look like radians"),
])
def test_bad_plan_input_gets_one_line_and_exit_2(tmp_path, args, message):
    (tmp_path / "bad.csv").write_text("q1,q2,q3,q4,q5\n0,0,0,0,0\n")
    (tmp_path / "cand.csv").write_text("q1,q2,q3,q4,q5,q6\n0,-125,-165,0,0,0\n")
    (tmp_path / "outside.csv").write_text("q1,q2,q3,q4,q5,q6\n0,-125,-165,0,0,0\n0,-125,-100,0,0,0\n")
    (tmp_path / "rad.csv").write_text("q1,q2,q3,q4,q5,q6\n" + "".join(f"0.{k},-2.{k},-2.8,0.{k},0.1,0.{k}\n"
                                                                      for k in range(1, 7)))
    before = (tmp_path / "cand.csv").read_text()
    code, stdout, err = cli(*[a.format(tmp=tmp_path) for a in args])
    assert code == 2 and err.count("\n") == 1 and err.startswith("partcal: error: "), err
    assert __import__("re").search(message, err), err
    assert (tmp_path / "cand.csv").read_text() == before and not (tmp_path / "p.csv").exists()


def test_run_prints_and_reports_the_identification_sets_indices(tmp_path):
    config = tmp_path / "configs" / "c.yaml"
    config.parent.mkdir()
    config.write_text(f"name: c\nrobot: motoman_sk120\ndata:\n  identification: {DATA / 'identification.csv'}\n"
                      "models:\n  - {name: DH, kind: kinematic}\n")
    code, stdout, err = cli("run", config, "-q")
    assert code == 0, err
    line = next(x for x in stdout.splitlines() if x.startswith("identification set: O1 "))
    robot = load_robot("motoman_sk120")
    q = read_columns(DATA / "identification.csv", [["q1", "q2", "q3", "q4", "q5", "q6"]])[1]
    expected = plan.evaluate_poses(robot, q)
    assert expected.indices.text() in line
    assert "theta[7]" in line or "d[7]" in line          # the paper's wrist stays at q4 = q5 = 0
    html = (tmp_path / "reports" / "c" / "index.html").read_text()
    assert 'id="design-indices"' in html and f'data-o1="{expected.indices.o1}"' in html


def test_evaluate_reads_a_wrist_held_with_encoder_jitter_as_held(sk120):
    ident = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    jittered = ident.q_deg.copy()
    jittered[:, 3:5] += np.random.default_rng(0).normal(0.0, 0.001, (len(jittered), 2))
    exact, noisy = (plan.evaluate_poses(sk120, q) for q in (ident.q_deg, jittered))
    assert len(noisy.identified) == len(exact.identified) == 19 and noisy.missing == exact.missing
