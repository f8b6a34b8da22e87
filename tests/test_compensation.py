"""False targets: the batched joint-model solve against the straightforward nested fixed point."""

import numpy as np
import pytest
from conftest import ROOT

from partcal import read_measurements
from partcal.models.series import ErrorModel
from partcal.robot.compensation import false_target, false_target_joints


@pytest.fixture(scope="module")
def joint_model():
    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    return m, ErrorModel(inputs="joint", degree=2, solver="lstsq").fit(m.q_deg, m.errors_mm)


def nested_fixed_point(predict, robot, targets, seeds, fixed, tol_mm, max_iter=50):
    """The straightforward false targets: q <- IK(p - e(q)), a full IK per iteration, from IK(p)."""
    q = robot.inverse(targets, seeds, fixed=fixed).q_deg
    for _ in range(max_iter):
        active = np.linalg.norm(robot.positions(q) + predict(q) - targets, axis=1) > tol_mm
        if not active.any():
            break
        cmd = targets[active] - predict(q[active])
        q[active] = robot.inverse(cmd, q[active], fixed=fixed, tol_mm=min(tol_mm, 1e-8)).q_deg
    return q


def valid_targets(sk120, m, n, seed):
    rng = np.random.default_rng(seed)
    q = m.q_deg[rng.integers(0, len(m.q_deg), 2 * n)] + rng.normal(0, 2, (2 * n, 6))
    q[:, 3:5] = m.q_deg[0, 3:5]
    q = q[sk120.within_limits(q)][:n]
    return sk120.positions(q)


def test_joint_false_targets_equal_the_nested_fixed_point(sk120, joint_model):
    # with q4, q5 and q6 held the solution is unique: both must find it, to 1e-9 mm
    m, model = joint_model
    targets = valid_targets(sk120, m, 150, seed=5)
    seeds = np.tile(sk120.home_deg, (len(targets), 1))
    fast = false_target_joints(model._predict_trusted, sk120, targets, seeds, (4, 5, 6), tol_mm=1e-11)
    q_ref = nested_fixed_point(model._predict_trusted, sk120, targets, seeds.copy(), (4, 5, 6), tol_mm=1e-11)
    # near the parallelogram's limit some false targets need q2 - q3 below 10 degrees: not converged
    np.testing.assert_array_equal(fast.converged, inside_the_sk120(fast.joints_deg))
    assert fast.converged.sum() > 100
    np.testing.assert_allclose(fast.commanded_mm, sk120.positions(q_ref), rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.commanded_mm + model.predict(fast.joints_deg), targets, rtol=0, atol=1e-9)


def test_redundant_joints_stay_on_the_branch_of_the_nested_fixed_point(sk120, joint_model):
    # q6 free: a one-dimensional self-motion; both land on it, within a hair of each other
    m, model = joint_model
    targets = valid_targets(sk120, m, 150, seed=6)
    seeds = np.tile(sk120.home_deg, (len(targets), 1))
    fast = false_target_joints(model._predict_trusted, sk120, targets, seeds, (4, 5), tol_mm=1e-10)
    q_ref = nested_fixed_point(model._predict_trusted, sk120, targets, seeds.copy(), (4, 5), tol_mm=1e-10)
    np.testing.assert_array_equal(fast.converged, inside_the_sk120(fast.joints_deg))
    assert fast.converged.sum() > 100 and np.all(fast.residual_mm <= 1e-10)
    np.testing.assert_allclose(fast.joints_deg, q_ref, rtol=0, atol=1e-4)
    assert np.all(fast.joints_deg[:, 3:5] == seeds[:, 3:5])


def test_unreachable_joint_targets_are_reported_not_returned(sk120, joint_model):
    _, model = joint_model
    targets = np.array([[1100.0, 0.0, 800.0], [9000.0, 0.0, 0.0]])
    res = false_target_joints(model._predict_trusted, sk120, targets, np.tile(sk120.home_deg, (2, 1)), (4, 5))
    assert res.converged.tolist() == [True, False] and res.residual_mm[1] > 5000


def test_cartesian_false_targets_solve_the_defining_equation():
    def predict(p):                                       # a smooth error field, 1e-3 mm per mm
        return np.c_[2 + 1e-3 * p[:, 1], -1 + 5e-4 * p[:, 0], 3e-3 * p[:, 2]]

    targets = np.random.default_rng(0).uniform(-1000, 1000, size=(500, 3))
    res = false_target(predict, targets, tol_mm=1e-10)
    assert res.converged.all()
    np.testing.assert_allclose(res.commanded_mm + predict(res.commanded_mm), targets, rtol=0, atol=1e-9)


def test_a_diverging_false_target_is_reported_not_returned_and_warns_nothing():
    """Far outside the data a quadratic error grows faster than the position: the iteration diverges.
    It used to overflow to inf (numpy warnings, then an error for the whole file); now that target alone
    is not converged and keeps itself as the command, while the others converge as before."""
    import warnings

    def grows(p):                                  # 1 mm per m^2: tiny at 1 m, 1e8 mm at 10 km
        return 1e-6 * p**2

    targets = np.array([[1e7, 0.0, 0.0], [1000.0, 500.0, 800.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")            # no RuntimeWarning from numpy
        res = false_target(grows, targets)
    assert res.converged.tolist() == [False, True]
    assert res.residual_mm[0] == np.inf and res.residual_mm[1] <= 1e-4
    np.testing.assert_array_equal(res.commanded_mm[0], targets[0])
    cmd = res.commanded_mm[1]
    np.testing.assert_allclose(cmd + grows(cmd), targets[1], atol=1e-4)


def inside_the_sk120(q):
    """The SK120's limits and parallelogram constraint, written out from its YAML (degrees)."""
    low = np.array([-180, -175, -250, -180, -130, -360])
    high = np.array([180, -60, -110, 180, 130, 360])
    return np.all((q >= low) & (q <= high), axis=1) & (q[:, 1] - q[:, 2] >= 10) & (q[:, 1] - q[:, 2] <= 120)


def test_joint_solutions_that_break_the_robots_constraint_are_not_converged(sk120, joint_model):
    m, model = joint_model
    rng = np.random.default_rng(4)
    targets = np.vstack([[912.609, 0.0, 122.994],                       # the home seed folds the parallelogram
                         sk120.positions(rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], (400, 6)))])
    seeds = np.tile(sk120.home_deg, (len(targets), 1))
    result = false_target_joints(model.predict, sk120, targets, seeds, fixed=(4, 5, 6), tol_mm=1e-4)
    q = result.joints_deg
    assert q[0, 1] - q[0, 2] < 10 and not result.converged[0]         # 0.62 degrees: folded flat
    assert np.all(inside_the_sk120(q[result.converged]))
    solved = np.linalg.norm(sk120.positions(q) + model.predict(q) - targets, axis=1) <= 1e-4
    np.testing.assert_array_equal(result.converged, solved & inside_the_sk120(q))
    assert (solved & ~inside_the_sk120(q)).sum() > 1                   # the rule is what decides here


def test_reachable_is_the_robots_ik_within_its_limits(sk120):
    from partcal.robot.compensation import reachable

    rng = np.random.default_rng(2)
    q = rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], (200, 6))
    inside = q[inside_the_sk120(q)]
    assert reachable(sk120, sk120.positions(inside)).all()             # every pose the robot can take is reached
    far = np.array([[0.0, 0.0, 0.0], [5000.0, 0.0, 0.0], [np.inf, 0.0, 0.0]])
    assert not reachable(sk120, far).any()                             # its own base, beyond reach, not a number


@pytest.mark.parametrize("name", ["motoman_sk120", "universal_robots_ur10"])
def test_full_pose_false_targets_put_the_true_robot_on_the_wanted_pose(name):
    """The error model is the exact pose error of a 'true' robot (other DH lengths and twists): commanding
    the nominal robot to the compensated joints puts the true robot's tool on the wanted pose, position and
    orientation, checked with the true robot's forward kinematics."""
    from scipy.spatial.transform import Rotation

    from partcal import load_robot
    from partcal.robot.compensation import false_target_poses

    nominal = load_robot(name).replace(tool_mm=np.array([30.0, -20.0, 150.0]))
    rng = np.random.default_rng(5)
    rows = nominal.alpha_deg.size
    true = nominal.replace(a_mm=nominal.a_mm + rng.normal(0, 1.0, rows), d_mm=nominal.d_mm + rng.normal(0, 1.0, rows),
                           alpha_deg=nominal.alpha_deg + rng.normal(0, 0.05, rows),
                           theta_offset_deg=nominal.theta_offset_deg + rng.normal(0, 0.05, rows))

    def pose_error(q):
        T, N = true.forward(q), nominal.forward(q)
        turn = Rotation.from_matrix(T[:, :3, :3] @ N[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
        return np.hstack([T[:, :3, 3] - N[:, :3, 3], turn])

    lo, hi = np.maximum(nominal.limits_deg[:, 0], -150), np.minimum(nominal.limits_deg[:, 1], 150)
    q = rng.uniform(lo, hi, (300, nominal.n_joints))
    q = q[nominal.within_limits(q)][:60]
    wanted = nominal.forward(q)
    result = false_target_poses(pose_error, nominal, wanted, q, tol_mm=1e-6, tol_deg=1e-6)
    assert result.converged.mean() > 0.9
    ok = result.converged
    reached = true.forward(result.joints_deg[ok])
    np.testing.assert_allclose(reached[:, :3, 3], wanted[ok, :3, 3], atol=1e-5)
    np.testing.assert_allclose(reached[:, :3, :3], wanted[ok, :3, :3], atol=1e-7)
    commanded = nominal.forward(result.joints_deg)
    np.testing.assert_allclose(result.commanded_mm, commanded[:, :3, 3])
    np.testing.assert_allclose(result.commanded_rotation, commanded[:, :3, :3])
    before = true.forward(q)                                   # uncompensated: the true robot misses
    assert np.linalg.norm(before[:, :3, 3] - wanted[:, :3, 3], axis=1).min() > 0.1
    # predictions that are not finite leave their targets unconverged; a wrong shape is refused
    broken = false_target_poses(lambda q: np.full((len(q), 6), np.nan), nominal, wanted[:3], q[:3])
    assert not broken.converged.any() and (broken.residual_mm == np.inf).all()
    from partcal import DataError

    with pytest.raises(DataError, match=r"predict must give pose errors of shape \(3, 6\)"):
        false_target_poses(lambda q: np.zeros((len(q), 3)), nominal, wanted[:3])


def test_each_unconverged_target_says_why(sk120, joint_model):
    """Diverged, not converged in the iterations given, out of reach, or a joint solution beyond the limits."""
    def grows(p):                                  # 1 mm per m^2: diverges at 10 km, converges slowly near 1 km
        return 1e-6 * p**2

    targets = np.array([[1e7, 0.0, 0.0], [1000.0, 500.0, 800.0]])
    assert false_target(grows, targets).reasons(1e-4) == ["diverged", ""]
    assert false_target(grows, targets[1:], max_iter=1).reasons(1e-4) == ["not converged"]

    m, model = joint_model
    targets = np.array([[912.609, 0.0, 122.994], [9000.0, 0.0, 0.0], sk120.positions(m.q_deg[:1])[0]])
    seeds = np.tile(sk120.home_deg, (3, 1))
    res = false_target_joints(model.predict, sk120, targets, seeds, fixed=(4, 5, 6), tol_mm=1e-4)
    assert res.converged.tolist() == [False, False, True]
    assert res.reasons(1e-4, robot=sk120, targets_mm=targets) == ["joint limit", "out of reach", ""]
    assert res.reasons(1e-4, robot=sk120)[1] == "joint limit"     # without the targets: what the solve ran into


def test_a_pose_beyond_the_stretched_elbow_is_refused_as_singular():
    """A UR10 with its elbow straight (q3 = 0) whose model says it falls 1 mm short in z: the command would have to
    lie 1 mm beyond the arm's reach. The solve stops at the stretched elbow and says so; the same error at a bent
    elbow (q3 = 60) is compensated."""
    from partcal import load_robot
    from partcal.robot.compensation import false_target_poses

    ur10 = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    q = np.array([[0.0, -90.0, 0.0, -90.0, 30.0, 0.0], [0.0, -90.0, 60.0, -90.0, 30.0, 0.0]])
    wanted = ur10.forward(q)
    result = false_target_poses(lambda q: np.tile([0.0, 0.0, -1.0, 0.0, 0.0, 0.0], (len(q), 1)), ur10, wanted, q)
    assert result.converged.tolist() == [False, True]
    assert result.residual_mm[0] > 0.5 and result.singular.tolist() == [True, False]
    assert result.reasons(1e-4, 1e-5, ur10, wanted[:, :3, 3]) == ["singular", ""]


def test_unconverged_warnings_name_the_source_and_each_targets_reason():
    """Each listed target carries its reason: a miss inside the tolerance is listed as what failed (here the joint
    limit), never as a bare number."""
    from partcal import load_robot
    from partcal.robot.compensation import CompensationResult, CompensationWarning

    sk120 = load_robot("motoman_sk120")
    q = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [400.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    q[:2] = sk120.home_deg
    result = CompensationResult(sk120.positions(np.clip(q, -180, 180)), q, np.ones(3, dtype=np.int64),
                                np.array([0.0, 0.5, 1e-6]), np.array([True, False, False]))
    with pytest.warns(CompensationWarning, match=r"^model 'M' on data set 'test': 2 of 3 targets did not converge to "
                                                 r"0.0001 mm: #1 \(0.5 mm: not converged\), #2 \(1e-06 mm: joint "
                                                 r"limit\)$"):
        result.warn_unconverged(1e-4, robot=sk120, source="model 'M' on data set 'test'")


def test_a_straight_wrists_shared_turn_is_split_nearest_the_reference_without_moving_the_pose(sk120):
    """Axis 5 at 0: axes 4 and 6 of the SK120 turn about one line, only q4 + q6 is the pose's. The split nearest
    a reference (r4, r6) is the least squares one, q4 = (q4 + q6 + r4 - r6) / 2, by hand; bounds clip it; a
    wrist bent 1 degree has no shared turn and is left as it was."""
    from partcal.robot.wrist import nearest_split, shared_turns

    rng = np.random.default_rng(7)
    q = np.column_stack([rng.uniform(-40, 40, 20), rng.uniform(-140, -110, 20), rng.uniform(-175, -150, 20),
                         rng.uniform(-60, 60, 20), np.zeros(20), rng.uniform(-60, 60, 20)])
    ref = q + rng.uniform(-30, 30, q.shape)
    j, k, c = shared_turns(sk120, q)
    assert np.all(j == 3) and np.all(k == 5) and np.allclose(c, 1.0)
    split = nearest_split(sk120, q, ref)
    total = q[:, 3] + q[:, 5]
    np.testing.assert_allclose(split[:, 3], (total + ref[:, 3] - ref[:, 5]) / 2, atol=1e-9)
    np.testing.assert_allclose(split[:, 3] + split[:, 5], total, atol=1e-9)
    np.testing.assert_array_equal(split[:, :3], q[:, :3])
    before, after = sk120.forward(q), sk120.forward(split)
    np.testing.assert_allclose(after, before, atol=1e-9)
    low = np.full(q.shape, -np.inf)
    low[:, 3] = np.maximum(split[:, 3], 0) + 1.0                    # axis 4 held above where the nearest lies
    bounded = nearest_split(sk120, q, ref, low, np.full(q.shape, np.inf))
    np.testing.assert_allclose(bounded[:, 3], low[:, 3], atol=1e-9)
    bent = q.copy()
    bent[:, 4] = 1.0
    assert np.all(shared_turns(sk120, bent)[0] == -1)
    np.testing.assert_array_equal(nearest_split(sk120, bent, ref), bent)
