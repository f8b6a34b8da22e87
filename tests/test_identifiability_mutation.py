"""The rank rule's pieces (calibration/identifiability.py) on small Jacobians whose answers are worked out by hand
or by an SVD computed here: what mutation testing (issue 49) found no test checking."""

import numpy as np

from partcal.calibration.identifiability import (WEAK_LEVER, _most_independent, consistent_jacobian,
                                                 identifiable_parameters, null_direction)


def orthonormal_columns(rows, count, seed):
    return np.linalg.qr(np.random.default_rng(seed).normal(size=(rows, count)))[0]


def test_the_rank_rule_scales_columns_to_unit_length_before_it_counts_singular_values():
    """Two orthogonal columns of lengths 1e4 and 1e-2 (a unit the lever rule does not know): unit columns, two
    singular values of 1, rank 2 at any rcond below 1; a zero column and one not wanted never count."""
    q = orthonormal_columns(12, 3, 0)
    jac = np.column_stack([1e4 * q[:, 0], np.zeros(12), 1e-2 * q[:, 1], q[:, 2]])
    units = ["1/kg"] * 4
    free, rank = identifiable_parameters(jac, np.array([True, True, True, False]), 1e-6, units)
    assert free.tolist() == [0, 2] and rank == 2
    assert identifiable_parameters(jac, np.zeros(4, dtype=bool), 1e-6, units)[0].size == 0
    assert identifiable_parameters(jac, np.zeros(4, dtype=bool), 1e-6, units)[1] == 0
    assert identifiable_parameters(np.zeros((5, 2)), np.ones(2, dtype=bool), 1e-6, ["mm", "mm"])[1] == 0


def test_a_column_moves_nothing_below_1e_12_of_the_longest_whatever_the_jacobians_scale():
    """Columns of lengths 1, 1e-13 and 1e-11 (orthogonal) times 1e-6, 1 or 1e6: the second never counts, the third
    always does (1e-11 is above 1e-12 of the longest, and unit columns make it as independent as the first)."""
    q = orthonormal_columns(10, 3, 6)
    for scale in (1e-6, 1.0, 1e6):
        jac = scale * np.column_stack([q[:, 0], 1e-13 * q[:, 1], 1e-11 * q[:, 2]])
        free, rank = identifiable_parameters(jac, np.ones(3, dtype=bool), 1e-15, ["1/kg"] * 3)
        assert free.tolist() == [0, 2] and rank == 2, scale


def test_the_rank_counts_singular_values_above_rcond_times_the_largest():
    """Two unit columns at an angle of 2 theta: singular values sqrt(2) cos(theta) and sqrt(2) sin(theta), by hand;
    rank 2 when tan(theta) exceeds rcond, else 1; three columns, the third the sum of the first two: rank 2."""
    e = np.eye(6)
    theta = 1e-4                                                       # tan(theta) = 1e-4
    jac = np.column_stack([np.cos(theta) * e[0] + np.sin(theta) * e[1], np.cos(theta) * e[0] - np.sin(theta) * e[1],
                           e[2]])
    units = ["1/kg"] * 3
    assert identifiable_parameters(jac, np.ones(3, dtype=bool), 1e-3, units)[1] == 2    # 1e-4 < 1e-3: one of the pair
    assert identifiable_parameters(jac, np.ones(3, dtype=bool), 1e-5, units)[1] == 3
    pair = jac[:, :2]                                                  # the pair alone: 1e-4 of the largest, not of 1
    assert identifiable_parameters(pair, np.ones(2, dtype=bool), 1e-3, units[:2])[1] == 1
    assert identifiable_parameters(pair, np.ones(2, dtype=bool), 1e-5, units[:2])[1] == 2
    # three unit columns e0 and e0 +- 1e-3 e1 (to first order): singular values sqrt(3) and sqrt(2) 1e-3, a ratio of
    # 8.2e-4: rank 1 at rcond 1e-3, 2 at 5e-4 (rcond times the largest, not over it)
    fan = np.column_stack([e[0], e[0] + 1e-3 * e[1], e[0] - 1e-3 * e[1]])
    assert identifiable_parameters(fan, np.ones(3, dtype=bool), 1e-3, units)[1] == 1
    assert identifiable_parameters(fan, np.ones(3, dtype=bool), 5e-4, units)[1] == 2
    q = orthonormal_columns(8, 2, 1)
    summed = np.column_stack([q[:, 0], q[:, 1], q[:, 0] + q[:, 1]])
    free, rank = identifiable_parameters(summed, np.ones(3, dtype=bool), 1e-6, units)
    assert rank == 2 and free.tolist() == [0, 1]                           # ties and order: the first of the table


def test_a_geometric_parameter_whose_plausible_error_moves_the_tool_a_hundredth_of_the_median_ones_is_dropped():
    """Lengths (1 mm plausible) with levers 1, 1, 1, 0.02 and 0.005 of the median: the last one (below WEAK_LEVER,
    0.01) is dropped, the 0.02 one kept; an angle counts its lever per 0.1 degree; a unit the rule does not know
    is never dropped; with ``data_rows`` the median is read on the measurements' rows alone, at any scale of the
    columns."""
    assert WEAK_LEVER == 0.01
    q = orthonormal_columns(20, 7, 2)
    jac = q * np.array([1.0, 1.0, 1.0, 0.02, 0.005, 0.05, 1e-3])
    wanted = np.ones(7, dtype=bool)
    units = ["mm", "mm", "mm", "mm", "mm", "deg", "1/kg"]                  # the angle: 0.1 * 0.05 = 0.005 of the median
    free, rank = identifiable_parameters(jac, wanted, 1e-6, units)
    assert free.tolist() == [0, 1, 2, 3, 6] and rank == 5
    angle = jac.copy()
    angle[:, 5] *= 4.0                                                     # 0.1 * 0.2 = 0.02 of the median: kept
    assert identifiable_parameters(angle, wanted, 1e-6, units)[0].tolist() == [0, 1, 2, 3, 5, 6]
    # a prior's rows below the measurements' (moving no tool) raise columns 0-2 a thousandfold; read on them the
    # median lever would drop column 3 as well; read on the first 20 rows it does not
    for scale in (1.0, 1e-3):                                          # levers of a thousandth of a mm: the same
        prior = np.zeros((3, 7))
        prior[[0, 1, 2], [0, 1, 2]] = 1e3 * scale
        stacked = np.vstack([scale * jac, prior])
        assert identifiable_parameters(stacked, wanted, 1e-6, units, data_rows=20)[0].tolist() == [0, 1, 2, 3, 6]
        assert 3 not in identifiable_parameters(stacked, wanted, 1e-6, units)[0].tolist()


def test_column_pivoting_takes_the_longest_part_left_and_the_first_of_equal_ones():
    """Worked by hand: columns (2, 0, 0), (0, 2, 0), (0, 0, 1), (2, 2, 0): the longest is the fourth (sqrt 8);
    after it, what is left of the first is (1, -1, 0) (length sqrt 2), of the second (-1, 1, 0) (sqrt 2), of the
    third (0, 0, 1) (1): the first of the two equal ones; then the third (the second has nothing left)."""
    columns = np.array([[2.0, 0.0, 0.0, 2.0], [0.0, 2.0, 0.0, 2.0], [0.0, 0.0, 1.0, 0.0]])
    assert _most_independent(columns, 3).tolist() == [3, 0, 2]
    assert _most_independent(columns, 1).tolist() == [3]


def test_a_direction_is_null_when_the_jacobian_answers_it_below_the_square_root_of_rcond():
    q = orthonormal_columns(10, 3, 3)
    jac = 0.1 * np.column_stack([q[:, 0], q[:, 1], q[:, 0] + q[:, 1], np.zeros(10)])   # short columns, one nil
    wanted = np.ones(4, dtype=bool)
    assert null_direction(jac, np.array([1.0, 1.0, -1.0, 5.0]), wanted, 1e-6)         # J s = 0; the nil column aside
    assert not null_direction(jac, np.array([1.0, 0.0, 0.0, 0.0]), wanted, 1e-6)
    assert not null_direction(jac, np.array([0.0, 0.0, 0.0, 1.0]), wanted, 1e-6)       # only the nil column: none
    assert not null_direction(jac, np.array([1.0, 1.0, -1.0, 0.0]), np.array([True, True, False, True]), 1e-6)
    for length in (1e-3, 1e3):                                          # a direction's length does not matter
        assert not null_direction(jac, length * np.array([1.0, 0.0, 0.0, 0.0]), wanted, 1e-6)
        assert null_direction(jac, length * np.array([1.0, 1.0, -1.0, 0.0]), wanted, 1e-6)
    # a weak direction: in unit columns |J t| = 1e-4 of the largest singular value (sqrt 2 sin, worked out below)
    eps = 1e-4
    weak = np.column_stack([q[:, 0], q[:, 0] + eps * q[:, 1]])
    unit = weak / np.linalg.norm(weak, axis=0)
    t = np.array([1.0, -1.0]) / np.sqrt(2.0)                            # the unit columns' difference
    ratio = np.linalg.norm(unit @ t) / np.linalg.svd(unit, compute_uv=False)[0]
    assert 1e-5 < ratio < 1e-4
    direction = t / np.linalg.norm(weak, axis=0)                        # the same direction in the raw columns
    assert null_direction(weak, direction, np.ones(2, dtype=bool), 1e-6)       # below sqrt(1e-6) = 1e-3
    assert not null_direction(weak, direction, np.ones(2, dtype=bool), 1e-12)  # above sqrt(1e-12) = 1e-6
    largest = np.linalg.svd(unit, compute_uv=False)[0]                  # sqrt(rcond) times it, not over it (1.414)
    answer = np.linalg.norm(unit @ t)
    assert null_direction(weak, direction, np.ones(2, dtype=bool), (1.2 * answer / largest) ** 2)
    assert not null_direction(weak, direction, np.ones(2, dtype=bool), (0.8 * answer / largest) ** 2)


def test_the_consistent_jacobian_answers_a_misfit_direction_with_nothing_and_leaves_the_others():
    """A Jacobian whose answer to a direction ``d`` is only the misfit ``m = J d``: told so, the Jacobian returned
    answers ``d`` with zero (its rank one lower), answers every direction orthogonal to it in unit columns as
    before, and still answers with zero a direction it already could not see (``n``), even when ``d`` has a part
    along ``n``."""
    rng = np.random.default_rng(5)
    base = orthonormal_columns(30, 4, 4) * np.array([3.0, 0.5, 0.2, 2.0])
    jac = np.column_stack([base, base[:, 0] * 0.75, np.zeros(30)])      # n: column 4 = 0.75 column 0; column 5 nil
    norms = np.linalg.norm(jac, axis=0)
    n = np.array([0.75, 0, 0, 0, -1.0, 0])
    assert np.allclose(jac @ n, 0.0)
    d = np.array([0.3, -1.0, 0.6, 0.2, 0.0, 0.0]) + 0.5 * n
    misfit = (jac @ d)[:, None]
    out = consistent_jacobian(jac, misfit, d[:, None], 1e-6)
    assert np.linalg.norm(out @ d) < 1e-9 * np.linalg.norm(jac @ d)
    assert np.linalg.norm(out @ n) < 1e-12
    assert np.all(out[:, 5] == 0.0)
    def rank(m):                                                        # of the unit columns, from their SVD
        singular = np.linalg.svd(m[:, :5] / norms[:5], compute_uv=False)
        return int(np.sum(singular > 1e-6 * singular[0]))
    assert rank(jac) == 4 and rank(out) == 3
    t = d * norms
    t -= (t @ (n * norms)) / np.sum((n * norms) ** 2) * (n * norms)     # d's part off n, in unit columns
    for _ in range(5):
        w = rng.normal(size=6)
        w[5] = 0.0
        w_unit = w * norms
        w_unit -= (w_unit @ t) / (t @ t) * t                               # orthogonal to it in unit columns
        w = np.divide(w_unit, norms, out=np.zeros(6), where=norms > 0)
        np.testing.assert_allclose(out @ w, jac @ w, atol=1e-9)
    # a direction it already cannot see is left alone, whatever misfit is said to come with it
    assert consistent_jacobian(jac, rng.normal(size=(30, 1)), n[:, None], 1e-6) is jac
    assert consistent_jacobian(jac, rng.normal(size=(30, 1)), np.zeros((6, 1)), 1e-6) is jac       # no direction
    tiny = 1e-12 * d                                                    # a direction's length does not matter
    out = consistent_jacobian(jac, (jac @ tiny)[:, None], tiny[:, None], 1e-6)
    assert np.linalg.norm(out @ d) < 1e-9 * np.linalg.norm(jac @ d)


def test_the_consistent_jacobian_reads_a_direction_below_rcond_times_the_largest_singular_value_as_unseen():
    """Three nearly parallel unit columns: singular values about 1.7, 6e-4 and 1e-8 (by hand: the columns differ by
    1e-3 and 1e-8 across); with rcond 1e-6 the last is a direction the Jacobian cannot see (1e-8 < 1.7e-6), though
    it is above rcond times the second (6e-10): told of a misfit along it, the Jacobian is left as it is."""
    e = np.eye(5)
    jac = np.column_stack([e[0], e[0] + 1e-3 * e[1], e[0] + 1e-3 * e[1] + 1e-8 * e[2]])
    singular = np.linalg.svd(jac / np.linalg.norm(jac, axis=0), compute_uv=False)
    assert singular[0] > 1.7 and 1e-4 < singular[1] < 1e-3 and 1e-9 < singular[2] < 1e-7
    weak = np.array([0.0, 1.0, -1.0])                                  # column 2 - column 1: 1e-8 across
    out = consistent_jacobian(jac, (jac @ weak)[:, None], weak[:, None], 1e-6)
    assert out is jac
    # rcond 1.5 s3 / s1: the third singular value is below rcond times the largest (1.5 s3), above rcond over it
    assert consistent_jacobian(jac, (jac @ weak)[:, None], weak[:, None], 1.5 * singular[2] / singular[0]) is jac


def _problem(rows, cell):
    from partcal import load_robot
    from partcal.calibration.registry import built_types
    from partcal.calibration.stacked import StackedProblem
    robot = load_robot("universal_robots_ur10")
    return StackedProblem(robot, None, rows, built_types(rows, cell), np.zeros(len(rows)), "dh")


def test_a_uniform_scale_leaves_touches_of_unknown_planes_where_they_are():
    """Touches of two unknown planes (one tilted) by the nominal UR10: consistent data, so the cell scaled by one
    moves no residual (J s = 0, to rounding, with s not zero); the scale moves the robot's lengths and each plane's
    offset by its own value, never a plane's slopes (which are no lengths)."""
    from test_measurement_types import ROBOT, _rows as rows_of, _touches

    from partcal.calibration.identifiability import scale_direction
    rng = np.random.default_rng(4)
    q, names = _touches(ROBOT, rng, {"top": ([0.1, 0.0, 1.0], 300.0), "side": ([1.0, 0.0, 0.0], 700.0)}, 20, 0.0)
    problem = _problem(rows_of(q, ["plane"] * len(q), texts={"feature": tuple(names)}), {})
    s = scale_direction(problem)
    jac = problem(problem.start)[1]
    assert np.linalg.norm(s) > 1.0
    assert np.linalg.norm(jac @ s) < 1e-6 * np.linalg.norm(jac) * np.linalg.norm(s)
    from partcal.calibration.parameters import parameter_names
    units = np.array([u for _, u in parameter_names(ROBOT, None, "dh")])
    assert np.all(s[:problem.own][units == "deg"] == 0.0)             # the robot's angles do not scale
    planes = s[problem.own:]
    assert planes[[0, 1, 3, 4]].tolist() == [0.0, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(planes[[2, 5]], problem.start[problem.own:][[2, 5]], rtol=1e-12)


def test_the_misfits_parts_are_the_weighted_residuals_and_their_turns_by_hand():
    """Tracker points 1, 2 and 3 mm off the nominal UR10 (inconsistent data) and touches of a plane, the first
    flush: column 0 holds each residual that is a length, weighted (a flush touch's two tilts are not); columns 1-3
    the point residuals' triples crossed by the base axes (e_k x r), weighted; a touch does not turn (zeros)."""
    from test_measurement_types import ROBOT, _rows as rows_of, _touches

    from partcal.calibration.identifiability import misfit_parts
    rng = np.random.default_rng(4)
    q_planes, names = _touches(ROBOT, rng, {"top": ([0.1, 0.0, 1.0], 300.0)}, 6, 0.0)
    q_points = q_planes[:3]
    off = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])
    seen = ROBOT.positions(q_points) + off
    nan3 = np.full(len(q_planes), np.nan)
    flush = np.r_[np.full(3, np.nan), 1.0, np.zeros(len(q_planes) - 1)]
    rows = rows_of(np.vstack([q_points, q_planes]), ["point"] * 3 + ["plane"] * len(q_planes),
                   {"x_meas": np.r_[seen[:, 0], nan3], "y_meas": np.r_[seen[:, 1], nan3],
                    "z_meas": np.r_[seen[:, 2], nan3], "flush": flush}, {"feature": ("",) * 3 + tuple(names)})
    problem = _problem(rows, {"noise": {"point": 0.01, "plane": 0.04}})
    parts = misfit_parts(problem, problem.start)
    r = -off.ravel()                                       # the point residuals: nominal tip minus measured
    w_point, w_plane = 0.02 / 0.01, 0.02 / 0.04
    expected_points = np.zeros((9, 4))
    expected_points[:, 0] = w_point * r
    for k in range(3):
        expected_points[:, 1 + k] = w_point * np.cross(np.eye(3)[k], r.reshape(3, 3)).ravel()
    types = [m.name for m in problem.measurements]
    first = 0 if types[0] == "point" else len(q_planes)
    np.testing.assert_allclose(parts[first:first + 9], expected_points, atol=1e-9)
    touches = parts[9:] if first == 0 else parts[:len(q_planes) + 2]
    np.testing.assert_allclose(touches[:, 1:], 0.0, atol=1e-12)
    plane_values = problem.each(problem.start)[types.index("plane")].values
    assert plane_values.size == len(q_planes) + 2 and np.all(plane_values[-2:] != 0.0)      # the two tilts
    np.testing.assert_allclose(touches[:, 0], w_plane * np.r_[plane_values[:-2], 0.0, 0.0], atol=1e-12)
    assert parts.shape == (9 + len(q_planes) + 2, 4)


def test_a_uniform_scale_moves_a_cameras_and_boards_places_never_its_pixels(tmp_path):
    """Camera rows (a cell camera seeing a board on the flange): the cell scaled by one moves each of the camera's
    and the board's coordinates by its own value (mm) and leaves their turns (deg) and the camera's intrinsics
    (px, and the unitless distortion) alone."""
    from test_camera_misfit import _read_cell, _rows

    from partcal.calibration.identifiability import scale_direction
    from partcal.calibration.registry import built_types
    from partcal.calibration.stacked import StackedProblem
    study, rows = _rows(tmp_path)
    problem = StackedProblem(study.robot.nominal, None, rows, built_types(rows, _read_cell(tmp_path)),
                             np.zeros(len(rows)), "dh")
    s, start = scale_direction(problem)[problem.own:], problem.start[problem.own:]
    units = np.array([u for _, u in problem.names])
    assert sorted(set(units)) == ["1", "deg", "mm", "px"] and (start[units == "px"] > 500).all()
    np.testing.assert_array_equal(s[units == "mm"], start[units == "mm"])
    assert np.all(s[units != "mm"] == 0.0)
