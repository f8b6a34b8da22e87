"""The virtual robot's contact data (partcal/data/simulate_contacts.py): checked against the true robot,
computed here from ``VirtualRobot.true_flange`` and the true tool, independently of the generators' IK."""

import dataclasses
import re

import numpy as np
import pytest
from conftest import ROOT

from partcal.data.measurement_rows import read_cell, read_measurement_rows
from partcal.data.simulate import Compliance, load_study, simulate, write_study
from partcal.data.simulate_contacts import (all_pairs, fixed_point_visits, pair_distances, plane_touches,
                                            random_pairs)
from partcal.errors import ConfigError, DataError, UnreachableError

CONFIG = ROOT / "configs" / "ur10_contacts_virtual.yaml"
PLANES = {"top": ([0.0, 0.0, 1.0], 500.0), "side": (np.array([1.0, 0.0, 0.02]) / np.hypot(1, 0.02), 600.0)}
POINTS = {"nest": np.array([500.0, -500.0, 400.0]), "cone": np.array([-500.0, 0.0, 500.0])}


@pytest.fixture(scope="module")
def study():
    return load_study(CONFIG)


@pytest.fixture(scope="module")
def vr(study):
    """The config's virtual UR10 with joint errors too: compliance on joint 2 and gear errors on 2 and 3, so
    that the commanded joints differ from the actual ones."""
    return dataclasses.replace(study.robot, compliance=(Compliance(2, 1, (2, 3), (10.0, 5.0), 500.0),),
                               gear=((2, 0.02, 2.0, 30.0), (3, 0.03, 1.0, -20.0)))


def true_tips(vr, q):
    """The true tool tip ``(n, 3)`` and orientation ``(n, 3, 3)`` in the base frame, from the flange."""
    p, r = vr.true_flange(q)
    return p + r @ vr.true.tool_mm, r


def angles_deg(r):
    """Pairwise rotation angles between orientations ``(n, 3, 3)``, degrees, ``(n, n)``."""
    rel = np.einsum("aji,bjk->abik", r, r)
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=2, axis2=3) - 1) / 2, -1, 1)))


def test_the_joint_errors_matter_here(vr):
    q = np.array([[10.0, -80.0, 60.0, -70.0, -90.0, 0.0]])
    assert np.abs(vr.actual_joints(q) - q).max() > 0.01


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_the_true_tip_touches_the_true_plane_up_to_the_noise(vr, noise):
    q, names = plane_touches(vr, PLANES, {"top": 60, "side": 40}, np.random.default_rng(1), noise)
    assert q.shape == (100, 6) and names == ("top",) * 60 + ("side",) * 40
    assert vr.nominal.within_limits(q).all()
    tips, rotations = true_tips(vr, q)
    for name, (normal, offset) in PLANES.items():
        rows = np.array(names) == name
        miss = tips[rows] @ np.asarray(normal) - offset
        if noise == 0:
            assert np.abs(miss).max() < 1e-6
        else:
            assert abs(miss.mean()) < 4 * noise / np.sqrt(rows.sum())
            assert 0.7 * noise < miss.std() < 1.3 * noise
        on_plane = tips[rows] - np.outer(tips[rows] @ np.asarray(normal), normal)
        assert np.sort(np.linalg.svd(on_plane - on_plane.mean(0), compute_uv=False))[-2] / np.sqrt(rows.sum()) > 100
        assert np.percentile(angles_deg(rotations[rows]), 10) > 20         # orientations spread too
    joints_exact = vr.true.positions(q) @ vr.base_rotation.T + vr.base_mm     # the joint errors ignored
    assert np.abs(joints_exact[:60, 2] - 500.0).max() > 0.05


def test_flush_touches_lay_the_tool_axis_along_the_normal(vr):
    q, _ = plane_touches(vr, PLANES, {"top": 20, "side": 10}, np.random.default_rng(2), 0.0, flush=True)
    tips, rotations = true_tips(vr, q)
    normals = np.array([PLANES["top"][0]] * 20 + [PLANES["side"][0]] * 10)
    assert np.abs(np.abs(np.einsum("ij,ij->i", rotations[:, :, 2], normals)) - 1).max() < 1e-9
    assert np.abs(tips[:20, 2] - 500.0).max() < 1e-6


@pytest.mark.parametrize("noise", [0.0, 0.02])
def test_fixed_points_are_visited_from_different_orientations(vr, noise):
    q, names = fixed_point_visits(vr, POINTS, {"nest": 40, "cone": 30}, np.random.default_rng(3), noise)
    assert names == ("nest",) * 40 + ("cone",) * 30 and vr.nominal.within_limits(q).all()
    tips, rotations = true_tips(vr, q)
    for name, point in POINTS.items():
        rows = np.array(names) == name
        miss = tips[rows] - point
        if noise == 0:
            assert np.abs(miss).max() < 1e-6
        else:
            assert np.all((0.65 * noise < miss.std(axis=0)) & (miss.std(axis=0) < 1.35 * noise))
        between = angles_deg(rotations[rows])[np.triu_indices(rows.sum(), 1)]
        assert between.min() > 0.5 and np.median(between) > 20


def test_distances_are_those_between_the_true_tips(vr):
    q = np.random.default_rng(4).uniform(-150, 150, (30, 6))
    pairs = all_pairs(30)
    exact = pair_distances(vr, q, pairs, np.random.default_rng(5), 0.0)
    tips, _ = true_tips(vr, q)
    np.testing.assert_allclose(exact, np.linalg.norm(tips[pairs[:, 0]] - tips[pairs[:, 1]], axis=1), atol=1e-9)
    noisy = pair_distances(vr, q, pairs, np.random.default_rng(5), 0.01)
    assert 0.008 < (noisy - exact).std() < 0.012 and abs((noisy - exact).mean()) < 0.002


def test_pairs():
    assert all_pairs(4).tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    some = random_pairs(50, 300, np.random.default_rng(0))
    assert len({tuple(p) for p in some.tolist()}) == 300 and (some[:, 0] < some[:, 1]).all() and some.max() < 50


def test_bad_arguments_are_refused_naming_them(vr):
    rng = np.random.default_rng(0)
    with pytest.raises(DataError, match=r"counts names the plane 'floor', which the planes given do not hold "
                                        r"\(top, side\)"):
        plane_touches(vr, PLANES, {"floor": 3}, rng, 0.01)
    with pytest.raises(DataError, match=r"counts\['nest'\] must be a number of rows >= 1; got 0"):
        fixed_point_visits(vr, POINTS, {"nest": 0}, rng, 0.01)
    with pytest.raises(DataError, match=r"noise_mm must be a finite number >= 0 \(mm\); got -0.1"):
        plane_touches(vr, PLANES, {"top": 3}, rng, -0.1)
    with pytest.raises(DataError, match=r"Expected pairs with shape \(m, 2\) of row indices in \[0, 2\)"):
        pair_distances(vr, np.zeros((2, 6)), np.array([[0, 2]]), rng, 0.01)


def test_a_plane_out_of_reach_is_refused_naming_it(vr):
    with pytest.raises(UnreachableError, match=r"plane 'far': the arm reached it 0 times of 5"):
        plane_touches(vr, {"far": ([0, 0, 1], 5000.0)}, {"far": 5}, np.random.default_rng(0), 0.01)


def test_simulate_writes_each_measurement_type_its_truth_and_the_cells_features(study, tmp_path):
    study = dataclasses.replace(study, output=tmp_path / "a")
    paths = write_study(study, simulate(study))
    assert sorted(p.name for p in paths) == sorted(
        ["test.csv", "cell.yaml"] + [f"{n}{s}" for n in ("touches", "flush", "nests", "ballbar")
                                         for s in (".csv", ".truth.yaml")])
    cell = read_cell(tmp_path / "a" / "cell.yaml")
    assert cell["planes"]["step"] == {"parallel_to": "top", "spacing_mm": -200.0}
    assert cell["planes"]["side"] == {} and cell["points"]["cone"] == {}
    assert cell["points"]["nest_b"] == {"distance_to": "nest_a", "distance_mm": 1000.0}
    assert cell["points"]["sphere"] == {"known_mm": [0.0, -600.0, 700.0]}
    top = cell["planes"]["top"]        # approximate: 0.5 degrees and 1 mm off the truth
    assert np.degrees(np.arccos(top["normal"][2])) == pytest.approx(0.5, abs=1e-6)
    assert abs(top["offset_mm"] - 500.0) == pytest.approx(1.0)
    assert cell["noise"] == {"plane": 0.01, "fixed": 0.01, "distance": 0.01}
    touches = read_measurement_rows(tmp_path / "a" / "touches.csv", study.robot.nominal, cell=cell)
    assert touches.texts["feature"].count("side") == 200 and set(touches.types) == {"plane"}
    tips, _ = true_tips(study.robot, touches.q_deg)
    side = np.array(touches.texts["feature"]) == "side"
    assert np.abs(tips[side] @ PLANES["side"][0] - 600.0).max() < 0.06
    ballbar = read_measurement_rows(tmp_path / "a" / "ballbar.csv", study.robot.nominal, cell=cell)
    assert ballbar.types.count("pose") == 100 and ballbar.types.count("distance") == 4950
    at = {name: k for k, name in enumerate(ballbar.ids)}
    rows = ballbar.of("distance")
    tips, _ = true_tips(study.robot, ballbar.q_deg)
    ends = [at[t] for t in np.array(ballbar.texts["to"])[rows]]
    err = ballbar.numbers["distance_mm"][rows] - np.linalg.norm(tips[rows] - tips[ends], axis=1)
    assert 0.008 < err.std() < 0.012
    flush = read_measurement_rows(tmp_path / "a" / "flush.csv", study.robot.nominal)
    assert (flush.numbers["flush"] == 1).all()
    truth = (tmp_path / "a" / "nests.truth.yaml").read_text()
    assert "nest_b:\n    position_mm: [500.0, 500.0, 400.0]" in truth and "true_robot:" in truth
    again = dataclasses.replace(study, output=tmp_path / "b")
    write_study(again, simulate(again))
    for p in paths:
        assert (tmp_path / "b" / p.name).read_bytes() == p.read_bytes()


def _config(tmp_path, old, new):
    text = CONFIG.read_text()
    assert old in text
    path = tmp_path / "c.yaml"
    path.write_text(text.replace(old, new).replace("output: ../data/ur10_contacts", f"output: {tmp_path / 'o'}"))
    return path


@pytest.mark.parametrize("old, new, pattern", [
    ("plane: {top: 300,", "plane: {floor: 300,", r"datasets\.touches\.plane\.floor \(line \d+\): names no plane "
                                                 r"of cell\.planes \(top, step, side\)"),
    ("given: approximate}", "given: tied}", r"cell\.planes\.top\.given \(line \d+\): must be one of"),
    ("distance_to: nest_a}", "distance_to: nest_z}", r"cell\.points\.nest_b\.distance_to \(line \d+\): must "
                                                     r"name a feature of cell\.points"),
    ("cone:   {position_mm: [-500, 0, 500]}", "cone:   {position_mm: [-500, 0, 500], distance_to: nest_a}",
     r"cell\.points\.cone\.distance_to \(line \d+\): is read with given: tied only"),
    ("pairs: all, poses: 100", "pairs: 5000, poses: 100", r"datasets\.ballbar\.distance\.pairs \(line \d+\): must "
                                                          r"be at most 4950"),
    ("test:    {sample: 400}", "test:    {sample: 400, plane: {top: 3}}", r"datasets\.test \(line \d+\): give "
                                                                          r"exactly one of"),
])
def test_config_refusals_name_key_and_line(tmp_path, old, new, pattern):
    path = _config(tmp_path, old, new)
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: {pattern}"):
        load_study(path)


def test_a_feature_out_of_reach_is_refused_naming_its_key(tmp_path):
    path = _config(tmp_path, "offset_mm: 600, given: unknown}", "offset_mm: 4000, given: unknown}")
    study = load_study(path)
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: cell\.planes\.side \(line \d+\): plane "
                                          r"'side': the arm reached it 0 times of 200 .*\(datasets\.touches asks"):
        write_study(study, simulate(study))
    assert not (tmp_path / "o").exists()                      # no file, and no empty folder either


def test_a_refused_simulation_through_the_command_leaves_no_folder(tmp_path, capsys):
    from partcal.cli import main
    path = _config(tmp_path, "offset_mm: 600, given: unknown}", "offset_mm: 4000, given: unknown}")
    assert main(["simulate", str(path)]) == 2
    assert "plane 'side': the arm reached it 0 times" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "mine.txt").write_text("kept")          # a folder that was there stays, with its files
    assert main(["simulate", str(path)]) == 2
    assert (tmp_path / "o" / "mine.txt").read_text() == "kept"
