"""ISO 9283 figures: against hand computations on a small fixture, and refusals naming file, line and field."""

import math

import numpy as np
import pytest

from partcal.data.iso9283 import (Cycles, cycles_from_column, cycles_from_joints, distance_figures, path_figures,
                                  pose_figures, require_repeats)
from partcal.errors import DataError
from partcal.study.iso_figures import summary

# Two poses, A commanded at (10, 0, 0) and B at (0, 10, 0), three cycles, rows interleaved A1 B1 A2 B2 A3 B3.
Q = np.array([[0.0, 0.0], [5.0, 5.0], [0.004, 0.0], [5.0, 5.003], [0.0, -0.002], [5.0, 5.0]])
COMMANDED = np.array([[10.0, 0, 0], [0, 10.0, 0]] * 3)
ATTAINED = np.array([[11.0, 0, 0], [0, 10, 4], [13, 0, 0], [0, 10, 4], [12, 0, 0], [3, 10, 4]])
TURN = np.array([[0.1, 0, 0], [0, 0, 0], [0.2, 0, 0], [0, 0, 0.5], [0.3, 0, 0], [0, 0, -0.5]])


def test_cycles_are_repeated_commanded_joints_within_the_tolerance():
    cyc = cycles_from_joints(Q, tol_deg=0.01)
    assert cyc.pose.tolist() == [0, 1, 0, 1, 0, 1]
    assert cyc.cycle.tolist() == [0, 0, 1, 1, 2, 2]
    assert cycles_from_joints(Q, tol_deg=0.001).n_poses == 5      # each jittered row is a pose of its own


def test_pose_figures_match_the_hand_computation():
    f = pose_figures(COMMANDED, ATTAINED, cycles_from_joints(Q), TURN)
    # A: barycentre (12, 0, 0), AP = 2; l = 1, 1, 0: mean 2/3, S_l = sqrt(((1/3)^2 * 2 + (2/3)^2) / 2) = sqrt(1/3)
    # B: barycentre (1, 10, 4), AP = sqrt(17); l = 1, 1, 2: mean 4/3, S_l = sqrt(1/3)
    assert f.ap_mm == pytest.approx([2.0, math.sqrt(17)])
    assert f.ap_xyz_mm == pytest.approx(np.array([[2.0, 0, 0], [1.0, 0, 4.0]]))
    assert f.l_mean_mm == pytest.approx([2 / 3, 4 / 3])
    assert f.s_l_mm == pytest.approx([math.sqrt(1 / 3)] * 2)
    assert f.rp_mm == pytest.approx([2 / 3 + 3 * math.sqrt(1 / 3), 4 / 3 + 3 * math.sqrt(1 / 3)])
    # orientation: A turns 0.1, 0.2, 0.3 deg about x (mean 0.2, S 0.1); B 0, 0.5, -0.5 about z (mean 0, S 0.5)
    assert f.ap_abc_deg == pytest.approx(np.array([[0.2, 0, 0], [0, 0, 0]]))
    assert f.rp_abc_deg == pytest.approx(np.array([[0.3, 0, 0], [0, 0, 1.5]]))
    s = summary(f)
    assert s["AP_max_mm"] == pytest.approx(math.sqrt(17))
    assert s["RP_max_mm"] == pytest.approx(4 / 3 + math.sqrt(3))


def test_distance_figures_match_the_hand_computation():
    d = distance_figures(COMMANDED, ATTAINED, cycles_from_joints(Q), (0, 1))
    lengths = [math.sqrt(121 + 100 + 16), math.sqrt(169 + 100 + 16), math.sqrt(81 + 100 + 16)]
    mean = sum(lengths) / 3
    std = math.sqrt(sum((v - mean) ** 2 for v in lengths) / 2)
    assert d.n_cycles == 3
    assert d.commanded_mm == pytest.approx(math.sqrt(200))
    assert d.ad_mm == pytest.approx(mean - math.sqrt(200))
    assert d.rd_mm == pytest.approx(3 * std)
    # per axis: D_x = 11, 13, 9 against 10; D_y = 10 against 10; D_z = 4 against 0
    assert d.ad_xyz_mm == pytest.approx([1.0, 0.0, 4.0])
    assert d.rd_xyz_mm == pytest.approx([3 * 2.0, 0.0, 0.0])


def test_path_figures_count_only_the_deviation_normal_to_the_path():
    commanded = np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]] * 2)
    # every point reached 1 mm late along x (not a path error); off the path by y = 0.5 / 0.1 / 0.3 and 0.3 / 0.1 / 0.1
    attained = commanded + np.array([[1, 0.5, 0], [1, 0.1, 0], [1, 0.3, 0], [1, 0.3, 0], [1, 0.1, 0], [1, 0.1, 0]])
    cyc = Cycles(np.array([0, 1, 2, 0, 1, 2]), np.array([0, 0, 0, 1, 1, 1]))
    p = path_figures(commanded, attained, cyc)
    assert p.deviation_mm == pytest.approx([0.4, 0.1, 0.2])        # barycentres' y
    assert p.at_mm == pytest.approx(0.4) and p.at_point == 0
    # point 1: l = 0.1, 0.1 (mean 0.1, S 0); point 3: l = 0.1, 0.1
    assert p.repeatability_mm == pytest.approx([0.1, 0.0, 0.1])
    assert p.rt_mm == pytest.approx(0.1)


def test_a_cycle_column_pairs_the_kth_rows_of_every_cycle():
    cyc = cycles_from_column(["c1", "c1", "c2", "c2", "c3", "c3"], Q, 0.01)
    assert cyc.pose.tolist() == [0, 1, 0, 1, 0, 1]
    assert cyc.cycle.tolist() == [0, 0, 1, 1, 2, 2]


def test_commanded_poses_that_differ_between_cycles_are_refused_with_file_line_and_field():
    q = Q.copy()
    q[3, 1] = 6.0
    with pytest.raises(DataError, match=r"^plan\.csv:7: column 'q2': pose 2 of cycle '2' commands 6 deg, "
                                        r"expected 5 .*commanded poses differ"):
        cycles_from_column(["1", "1", "2", "2", "3", "3"], q, 0.01, source="plan.csv", lines=[3, 4, 5, 7, 8, 9])


def test_a_cycle_with_fewer_rows_is_refused():
    with pytest.raises(DataError, match=r"^d\.csv: data row 5: column 'cycle': cycle '3' has 1 rows, expected 2"):
        cycles_from_column(["1", "1", "2", "2", "3"], Q[:5], source="d.csv")


def test_repeatability_of_a_pose_measured_once_is_refused_naming_its_line():
    cyc = cycles_from_joints(np.vstack([Q, [[9.0, 9.0]]]))
    with pytest.raises(DataError, match=r"^d\.csv:12: column 'cycle': pose 3 was measured in 1 cycle, but "
                                        r"repeatability needs at least 2"):
        require_repeats(cyc, source="d.csv", lines=[4, 5, 6, 7, 8, 9, 12])
    f = pose_figures(np.zeros((7, 3)), np.zeros((7, 3)), cyc)
    assert np.isnan(f.rp_mm[2]) and f.ap_mm[2] == 0.0


@pytest.fixture(scope="module")
def sk120_cycles():
    """The virtual SK120 (configs/sk120_virtual.yaml) with a known repeatability, and the ISO cube's poses."""
    import dataclasses

    from conftest import ROOT

    from partcal.data.simulate import load_study
    from partcal.robot.iso_cube import largest_cube

    virtual = dataclasses.replace(load_study(ROOT / "configs" / "sk120_virtual.yaml").robot, repeatability_mm=0.05)
    return virtual, largest_cube(virtual.nominal, random_state=0)


def test_rp_of_simulated_cycles_recovers_the_known_repeatability_over_20_seeds(sk120_cycles):
    virtual, cube = sk120_cycles
    sigma, n = 0.05, 30
    # x_j - barycentre ~ N(0, sigma^2 (1 - 1/n) I): its length is sigma sqrt(1 - 1/n) times a chi variable of 3
    # degrees of freedom, mean 2 sqrt(2 / pi), standard deviation sqrt(3 - 8 / pi)
    known = sigma * math.sqrt(1 - 1 / n) * (2 * math.sqrt(2 / math.pi) + 3 * math.sqrt(3 - 8 / math.pi))
    q = np.tile(cube.q_deg, (n, 1))
    cyc = cycles_from_joints(q)
    assert cyc.n_poses == 5 and (cyc.counts == n).all()
    per_seed = []
    for seed in range(20):
        measured = virtual.measure(q, np.random.default_rng(seed))
        f = pose_figures(virtual.nominal.positions(q), measured, cyc)
        per_seed.append(f.rp_mm.mean())
        assert abs(per_seed[-1] / known - 1) < 0.10, (seed, per_seed[-1], known)
    assert abs(np.mean(per_seed) / known - 1) < 0.02


def test_plan_writes_the_cube_and_iso9283_reads_its_measured_cycles(tmp_path, sk120_cycles):
    import json

    from conftest import partcal_cli

    from partcal.data.measurements import Measurements, write_measurements
    from partcal.robot.iso_cube import cube_points

    virtual, _ = sk120_cycles
    poses = tmp_path / "poses.csv"
    res = partcal_cli("plan", "motoman_sk120", "--iso9283", "--cube", "1500", "0", "1000", "400", "--cycles", "4",
                      "-o", str(poses))
    assert res.returncode == 0, res.stderr
    text = poses.read_text().splitlines()
    rows = [line.split(",") for line in text if not line.startswith("#")]
    assert rows[0][-2:] == ["set", "cycle"] and len(rows) == 1 + 5 * 4
    assert [r[-2] for r in rows[1:6]] == ["P1", "P2", "P3", "P4", "P5"] and {r[-1] for r in rows[1:]} == {"1", "2",
                                                                                                          "3", "4"}
    nominal = np.array([[float(v) for v in r[6:9]] for r in rows[1:6]])
    np.testing.assert_allclose(nominal, cube_points([1500, 0, 1000], 400.0), atol=1e-5)   # P2 = C1 + (C7 - C1) / 10
    q = np.array([[float(v) for v in r[:6]] for r in rows[1:]])
    m = Measurements(q, virtual.nominal.positions(q), virtual.measure(q, np.random.default_rng(0)))
    data = tmp_path / "measured.csv"
    write_measurements(m, data)
    out = tmp_path / "iso.json"
    res = partcal_cli("iso9283", str(data), "--distance", "2", "4", "-o", str(out))
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["summary"]["poses"] == 5 and [p["cycles"] for p in doc["poses"]] == [4] * 5
    bary = m.measured_mm.reshape(4, 5, 3).mean(axis=0)       # rows are cycle-major: P1..P5, P1..P5, ...
    assert [p["AP_mm"] for p in doc["poses"]] == pytest.approx(np.linalg.norm(bary - nominal, axis=1), abs=1e-4)
    assert doc["distance"]["Dc_mm"] == pytest.approx(np.linalg.norm(nominal[1] - nominal[3]), abs=1e-4)


def test_a_cube_out_of_reach_is_refused_naming_the_corner(tmp_path):
    from conftest import partcal_cli

    res = partcal_cli("plan", "motoman_sk120", "--iso9283", "--cube", "1500", "0", "1000", "3000", "-o",
                      str(tmp_path / "p.csv"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert "leaves the workspace or the joint limits of motoman_sk120 at corner C1 [0.0, -1500.0, -500.0] mm" in \
        res.stderr
    assert not (tmp_path / "p.csv").exists()


def test_iso9283_refuses_single_cycles_when_repeatability_is_asked(tmp_path):
    from conftest import ROOT, partcal_cli

    res = partcal_cli("iso9283", str(ROOT / "data" / "sk120" / "identification.csv"), "--repeatability")
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert ("identification.csv:4: columns q1..q6 (no other row commands the same joints within 0.01 deg; a 'cycle' "
            "column names the cycles): pose 1 was measured in 1 cycle" in res.stderr), res.stderr


def test_the_virtual_robots_repeatability_is_read_from_its_yaml(tmp_path):
    from conftest import ROOT

    from partcal.data.simulate import load_study

    text = (ROOT / "configs" / "sk120_virtual.yaml").read_text()
    (tmp_path / "v.yaml").write_text(text.replace("errors:\n", "errors:\n  repeatability_mm: 0.02\n", 1))
    assert load_study(tmp_path / "v.yaml").robot.repeatability_mm == 0.02
    assert load_study(ROOT / "configs" / "sk120_virtual.yaml").robot.repeatability_mm == 0.0


def test_a_runs_figures_are_those_of_each_test_set_uncompensated_and_left_by_each_model():
    from partcal.data.measurements import Measurements
    from partcal.study.iso_figures import run_figures

    m = Measurements(Q, COMMANDED, ATTAINED, name="cubes")
    perfect = ATTAINED - COMMANDED                              # a model that predicts every error exactly
    out = run_figures({"identification": m, "cubes": m}, {"perfect": {"cubes": perfect}, "none": {}})
    assert list(out) == ["cubes"] and out["cubes"]["poses"] == 2 and out["cubes"]["cycles_max"] == 3
    assert out["cubes"]["uncompensated"]["AP_max_mm"] == pytest.approx(math.sqrt(17))
    assert out["cubes"]["uncompensated"]["RP_max_mm"] == pytest.approx(4 / 3 + math.sqrt(3))
    assert out["cubes"]["models"]["perfect"]["AP_max_mm"] == pytest.approx(0.0, abs=1e-12)
    assert "none" not in out["cubes"]["models"]


def test_the_virtual_robot_measures_the_iso_cube_in_cycles(tmp_path):
    from conftest import ROOT

    from partcal.data.simulate import load_study, simulate
    from partcal.robot.iso_cube import cube_points

    text = (ROOT / "configs" / "sk120_virtual.yaml").read_text()
    text = text.replace("errors:\n", "errors:\n  repeatability_mm: 0.05\n", 1)
    text = text[:text.index("datasets:")] + "datasets:\n  cube: {iso9283: 30, cube: [1500, 0, 1000, 400]}\n"
    (tmp_path / "v.yaml").write_text(text)
    m = simulate(load_study(tmp_path / "v.yaml"))["cube"]
    assert len(m) == 150 and m.labels[:6] == ("P1", "P2", "P3", "P4", "P5", "P1")
    np.testing.assert_allclose(m.nominal_mm[:5], cube_points([1500, 0, 1000], 400.0), atol=1e-6)
    f = pose_figures(m.nominal_mm, m.measured_mm, cycles_from_joints(m.q_deg))
    known = 0.05 * math.sqrt(1 - 1 / 30) * (2 * math.sqrt(2 / math.pi) + 3 * math.sqrt(3 - 8 / math.pi))
    assert f.n_cycles.tolist() == [30] * 5 and abs(f.rp_mm.mean() / known - 1) < 0.10


def test_the_cubes_points_keep_p1s_tool_orientation_where_the_robot_can():
    from partcal.robot.description import load_robot
    from partcal.robot.iso_cube import cube_points, solve_cube

    ur10 = load_robot("universal_robots_ur10")
    cube = solve_cube(ur10, [300.0, -500.0, 500.0], 300.0)
    pose = ur10.forward(cube.q_deg)
    assert cube.held_orientation
    np.testing.assert_allclose(pose[:, :3, 3], cube_points([300.0, -500.0, 500.0], 300.0), atol=1e-5)
    np.testing.assert_allclose(pose[:, :3, :3], np.repeat(pose[:1, :3, :3], 5, axis=0), atol=1e-7)


def test_iso9283_reads_the_data_with_the_models_robot_and_refuses_another_robots_data(tmp_path):
    from conftest import ROOT, partcal_cli

    from partcal import ErrorModel, load_robot
    from partcal.study.persist import save_model

    rng = np.random.default_rng(0)
    X = rng.uniform(-1000, 1000, (40, 3))
    model = ErrorModel(inputs="cartesian", degree=1, solver="lstsq").fit(X, np.tile([0.3, -0.2, 0.1], (40, 1)))
    save_model(model, tmp_path / "ur.json", name="ur", robot=load_robot("universal_robots_ur10"))
    res = partcal_cli("iso9283", str(ROOT / "data" / "sk120" / "test_rectangle.csv"), "--model",
                      str(tmp_path / "ur.json"), "-o", str(tmp_path / "iso.json"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert "test_rectangle.csv:" in res.stderr and "universal_robots_ur10" in res.stderr
    assert not (tmp_path / "iso.json").exists()


@pytest.mark.parametrize("centre", [["inf", "0", "800"], ["1200", "nan", "800"]])
def test_a_cube_centre_that_is_not_a_finite_number_is_refused_naming_it(tmp_path, centre):
    from conftest import partcal_cli

    res = partcal_cli("plan", "motoman_sk120", "--iso9283", "-o", str(tmp_path / "p.csv"), "--cube", *centre, "100")
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert "the cube's centre must be three finite numbers of mm" in res.stderr
    assert not (tmp_path / "p.csv").exists()


def test_figures_measured_after_compensation_count_the_converged_targets_only(tmp_path):
    from conftest import ROOT

    from partcal.data.simulate import load_study, simulate
    from partcal.study.iso_figures import measured_after

    text = (ROOT / "configs" / "sk120_virtual.yaml").read_text()
    text = text.replace("errors:\n", "errors:\n  repeatability_mm: 0.05\n", 1)
    text = text[:text.index("datasets:")] + "datasets:\n  cube: {iso9283: 30, cube: [1500, 0, 1000, 400]}\n"
    (tmp_path / "v.yaml").write_text(text)
    study = load_study(tmp_path / "v.yaml")
    m = simulate(study)["cube"]
    reached = study.robot.measure(m.q_deg, np.random.default_rng(7))
    sent = np.ones(len(m), dtype=bool)
    sent[m.labels.index("P3"):: 5] = False                    # P3 never converged: not a pose of the figures
    sent[0] = False                                            # one cycle of P1 not sent
    s = measured_after(m, reached, sent)
    assert (s["poses"], s["converged"], s["n"]) == (4, 149 - 30, 150)
    kept = ("P1", "P2", "P4", "P5")
    miss = [np.linalg.norm(reached[sent & (np.array(m.labels) == p)].mean(axis=0) - m.nominal_mm[m.labels.index(p)])
            for p in kept]
    assert s["AP_max_mm"] == pytest.approx(max(miss)) and s["AP_mean_mm"] == pytest.approx(np.mean(miss))
    known = 0.05 * math.sqrt(1 - 1 / 30) * (2 * math.sqrt(2 / math.pi) + 3 * math.sqrt(3 - 8 / math.pi))
    assert abs(s["RP_mean_mm"] / known - 1) < 0.15
    assert measured_after(m, reached, np.zeros(len(m), dtype=bool)) is None


def test_printed_measured_rows_say_how_many_targets_converged_when_some_did_not():
    from partcal.study.iso_figures import run_lines

    def stats(**extra):
        return {"AP_mean_mm": 0.05, "AP_max_mm": 0.13, "RP_max_mm": None, **extra}

    figures = {"test": {"poses": 400, "cycles_max": 1, "uncompensated": stats(), "models": {"DH": stats()},
                        "measured": {"DH": stats(converged=391, n=400)}},
               "cube": {"poses": 5, "cycles_max": 30, "uncompensated": stats(), "models": {"DH": stats()},
                        "measured": {"DH": stats(converged=150, n=150)}}}
    lines = run_lines(figures)
    assert lines[-1] == "measured over the targets whose compensation converged: DH on test: 391 of 400"
    figures["test"]["measured"]["DH"]["converged"] = 400
    assert run_lines(figures)[-1].startswith("poses (cycles, RP max)")
