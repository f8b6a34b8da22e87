"""The virtual SK120 and the shipped data."""

import dataclasses

import numpy as np
import pytest
from conftest import ROOT

from partcal import ConfigError, read_measurements
from partcal.data.simulate import load_study, simulate, write_study
from partcal.metrics import rms_per_axis
from partcal.robot.trajectories import rectangle, spiral

CONFIG = ROOT / "configs" / "sk120_virtual.yaml"
SHIPPED = ROOT / "data" / "sk120"
NAMES = ["identification", "test_rectangle", "test_spiral_xy", "test_spiral_yz"]


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory):
    study = load_study(CONFIG)
    out = tmp_path_factory.mktemp("sk120")
    study = dataclasses.replace(study, output=out)
    data = simulate(study)
    write_study(study, data)
    return out, data


def test_shipped_data_regenerate_bit_for_bit(regenerated):
    out, _ = regenerated
    for name in NAMES:
        assert (out / f"{name}.csv").read_bytes() == (SHIPPED / f"{name}.csv").read_bytes(), name


def test_sizes_and_start_points():
    sets = {name: read_measurements(SHIPPED / f"{name}.csv") for name in NAMES}
    assert [len(sets[n]) for n in NAMES] == [85, 200, 200, 200]
    np.testing.assert_allclose(sets["test_rectangle"].nominal_mm[0], [1100, 800, 600], atol=1e-6)
    np.testing.assert_allclose(sets["test_spiral_xy"].nominal_mm[0], [1200, -600, 600], atol=1e-6)
    np.testing.assert_allclose(sets["test_spiral_yz"].nominal_mm[0], [500, 500, 1400], atol=1e-6)
    for m in sets.values():
        assert np.all(m.q_deg[:, 3:5] == 0.0)     # the wrist stays at q4 = q5 = 0


def test_paths_follow_the_paper_formulas():
    # Archimedes spiral r = phi, x = W r cos phi, y = W r sin phi, W = 20, step 5 pi / 200.
    k = 37
    phi = k * 5 * np.pi / 200
    path = spiral((1200, -600, 600), "xy")
    np.testing.assert_allclose(path[k, :2], [1200 + 20 * phi * np.cos(phi), -600 + 20 * phi * np.sin(phi)])
    assert path[-1, 2] == pytest.approx(1000.0) and np.all(np.diff(path[:, 2]) > 0)
    yz = spiral((500, 500, 1400), "yz")
    np.testing.assert_allclose(yz[k, 1:], [500 + 20 * phi * np.cos(phi), 1400 + 20 * phi * np.sin(phi)])
    rect = rectangle()
    sides = np.linalg.norm(np.diff(np.vstack([rect, rect[:1]]), axis=0), axis=1)
    np.testing.assert_allclose(sides, np.repeat([1200 / 50, np.hypot(200, 500) / 50, 1200 / 50,
                                                  np.hypot(200, 500) / 50], 50))


def test_uncompensated_errors_in_the_range_of_table_2(regenerated):
    _, data = regenerated
    paper = np.array([8.0, 7.5, 17.9])
    ratio = rms_per_axis(data["identification"].errors_mm) / paper
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio


def test_identification_spreads_over_the_sampled_ranges(regenerated):
    _, data = regenerated
    q = data["identification"].q_deg
    for j, (lo, hi) in {0: (-60, 60), 1: (-160, -100), 2: (-205, -145), 5: (-90, 90)}.items():
        assert q[:, j].min() < lo + 0.15 * (hi - lo) and q[:, j].max() > hi - 0.15 * (hi - lo)


def test_error_sources_each_change_the_measurements():
    study = load_study(CONFIG)
    vr = study.robot
    q = data_q = np.array([[0, -120, -170, 0, 0, 0], [30, -140, -190, 0, 0, 45]], dtype=float)
    nominal = vr.nominal.positions(q)
    assert np.all(np.linalg.norm(vr.true_positions(q) - nominal, axis=1) > 1.0)
    stiff = dataclasses.replace(vr, compliance=())
    sag = vr.true_positions(data_q)[:, 2] - stiff.true_positions(data_q)[:, 2]
    assert np.all(sag < -1.0)     # gravity pulls the tool down
    no_gear = dataclasses.replace(vr, gear=())
    assert np.abs(vr.true_positions(q) - no_gear.true_positions(q)).max() > 0.1


def test_tracker_noise_is_small_and_averaged():
    study = load_study(CONFIG)
    q = np.tile([[0.0, -120, -170, 0, 0, 0]], (2000, 1))
    measured = study.robot.measure(q, np.random.default_rng(3))
    spread = measured.std(axis=0)
    # 5 ppm at ~2.5 m is 12.5 um per reading; the mean of 100 readings: ~1.25 um
    assert np.all(spread < 3e-3) and np.all(spread > 3e-4)


def test_config_errors_name_key_and_line(tmp_path):
    text = CONFIG.read_text().replace("  readings: 100", "  readings: 100\n  readngs: 3")
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t.startswith("  readngs: 3"))
    with pytest.raises(ConfigError, match=rf"bad.yaml: tracker.readngs \(line {line}\): unknown key; did you mean 'readings'\?"):
        load_study(bad)
    bad.write_text(CONFIG.read_text().replace("seed: 2006", "seed: -1"))
    with pytest.raises(ConfigError, match=r"seed \(line \d+\): must be an int >= 0; got -1"):
        load_study(bad)
    bad.write_text(CONFIG.read_text().replace("seed: 2006", "seed: 1\nseed: 2"))
    with pytest.raises(ConfigError, match=r"seed \(line \d+\): duplicate key"):
        load_study(bad)


TARGETS_CONFIG = ROOT / "configs" / "ur10_targets_virtual.yaml"


def _noise_free(tmp_path):
    text = TARGETS_CONFIG.read_text().replace("repeatability_ppm: 10", "repeatability_ppm: 0").replace(
        "orientation_noise_deg: 0.005", "orientation_noise_deg: 0")
    path = tmp_path / "quiet.yaml"
    path.write_text(text)
    return load_study(path)


def test_three_targets_sit_rigidly_on_the_measured_tool(tmp_path):
    from scipy.spatial.transform import Rotation

    study = _noise_free(tmp_path)
    m = simulate(study)["identification"]
    assert m.target_names == ("A", "B", "C") and m.has_orientation
    # noise-free: the measured orientation carries the plate's drawing onto the measured points
    turn = Rotation.from_euler("XYZ", m.measured_orientation_deg, degrees=True).as_matrix()
    for name, offset in (("B", [100, 0, 90]), ("C", [-40, 90, 90])):
        in_flange = np.einsum("nji,nj->ni", turn, m.measured_of(name) - m.measured_mm)
        np.testing.assert_allclose(in_flange, np.tile(np.subtract(offset, [0, 0, 120]), (len(m), 1)), atol=1e-9)
        nominal_robot = study.robot.nominal.replace(tool_mm=np.array(offset, dtype=float))
        np.testing.assert_allclose(m.nominal_of(name), nominal_robot.positions(m.q_deg), atol=1e-9)
    np.testing.assert_allclose(study.robot.nominal.tool_mm, [0, 0, 120])     # A is the robot's tool
    flange = study.robot.nominal.replace(tool_mm=np.zeros(3)).forward(m.q_deg)[:, :3, :3]
    nominal_turn = Rotation.from_euler("XYZ", m.nominal_orientation_deg, degrees=True).as_matrix()
    np.testing.assert_allclose(nominal_turn, flange, atol=1e-12)


def test_each_target_and_the_orientation_get_their_own_noise():
    study = load_study(TARGETS_CONFIG)
    q = np.tile([[0.0, -90, 90, 0, 90, 0]], (4000, 1))
    m_extra, orientation = study.robot.measure_more(q, np.random.default_rng(5))
    dist = np.linalg.norm(study.robot.true_positions(q[:1]) - [2500, 0, 0])
    # 10 ppm per reading, one reading: about 0.025 mm at 2.5 m, per axis and per target
    for name in ("B", "C"):
        np.testing.assert_allclose(m_extra[name].std(axis=0), 10e-6 * dist, rtol=0.1)
    assert abs(np.corrcoef(m_extra["B"][:, 0], m_extra["C"][:, 0])[0, 1]) < 0.1
    from partcal.data.measurements import Measurements

    same = Measurements(q, np.zeros((4000, 3)), np.zeros((4000, 3)), measured_orientation_deg=orientation,
                        nominal_orientation_deg=np.tile(orientation.mean(axis=0), (4000, 1)))
    np.testing.assert_allclose(same.orientation_errors_deg.std(axis=0), 0.005, rtol=0.1)


def test_the_targets_key_is_checked(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(TARGETS_CONFIG.read_text().replace("  C: [-40, 90, 90]", "  C: [-40, 90]"))
    with pytest.raises(ConfigError, match=r"bad.yaml: targets.C \(line \d+\): must be a list of three numbers"):
        load_study(bad)
    bad.write_text(TARGETS_CONFIG.read_text().replace("  C: [-40, 90, 90]", "  C D: [-40, 90, 0]"))
    with pytest.raises(ConfigError, match=r"targets.C D \(line \d+\): a target name is letters, digits and '_'"):
        load_study(bad)


def test_tilts_between_parallel_axes_turn_the_true_rows_about_y(tmp_path):
    """``errors.tilt_deg: {q2: 0.03, q3: -0.02}`` on the UR10: the true robot's FK is the DH matrix product
    with ``Ry(0.03)`` after row 2 and ``Ry(-0.02)`` after row 3; a joint beyond the robot is refused."""
    from scipy.spatial.transform import Rotation

    study = load_study(ROOT / "configs" / "ur10_tilts_virtual.yaml")
    true = study.robot.true
    untilted = true.replace(origins=None)
    q = np.random.default_rng(8).uniform(-180, 180, (50, 6))
    poses = untilted.forward(q)
    # frames after rows 2 and 3, then the rest of the chain, by hand: T = T_0..2 Ry(a) T_3 Ry(b) T_4..6
    partial = [untilted.replace(alpha_deg=true.alpha_deg[:k], d_mm=true.d_mm[:k], a_mm=true.a_mm[:k],
                                theta_offset_deg=true.theta_offset_deg[:k], coupling=true.coupling[:k],
                                tool_mm=np.zeros(3)).forward(q) for k in (2, 3)]
    ry = [np.eye(4), np.eye(4)]
    ry[0][:3, :3] = Rotation.from_euler("y", 0.03, degrees=True).as_matrix()
    ry[1][:3, :3] = Rotation.from_euler("y", -0.02, degrees=True).as_matrix()
    row3 = np.linalg.inv(partial[0]) @ partial[1]
    rest = np.linalg.inv(partial[1]) @ poses
    expected = partial[0] @ ry[0] @ row3 @ ry[1] @ rest
    np.testing.assert_allclose(true.forward(q), expected, rtol=0, atol=1e-9)
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "configs" / "ur10_tilts_virtual.yaml").read_text().replace("{q2: 0.03,", "{q7: 0.03,")
                   .replace("output: ../data/ur10_tilts", f"output: {tmp_path}"))
    with pytest.raises(ConfigError, match="tilt_deg.*q7"):
        load_study(bad)


@pytest.mark.parametrize("dataset", ["{iso9283: 3, cube: [9000, 0, 800, 100]}",
                                     "{path: rectangle, start_mm: [9000, 0, 800]}"])
def test_a_data_set_out_of_reach_is_refused_naming_the_config_and_the_data_set(tmp_path, dataset):
    text = (ROOT / "configs" / "sk120_virtual.yaml").read_text()
    text = text[:text.index("datasets:")] + f"datasets:\n  far: {dataset}\n"
    (tmp_path / "far.yaml").write_text(text.replace("output: ../data/sk120", f"output: {tmp_path / 'out'}"))
    with pytest.raises(ConfigError, match=r"far\.yaml: datasets\.far: .*(out of reach|unreachable)"):
        simulate(load_study(tmp_path / "far.yaml"))


def test_the_regenerate_command_in_the_files_names_the_config_where_it_is(tmp_path, monkeypatch):
    (tmp_path / "elsewhere").mkdir()
    config = tmp_path / "elsewhere" / "sim.yaml"
    config.write_text(CONFIG.read_text())
    study = dataclasses.replace(load_study(config), output=tmp_path / "out")
    (tmp_path / "out").mkdir()
    data = {"identification": simulate(study)["identification"]}
    monkeypatch.chdir(tmp_path)
    write_study(study, data)
    assert "Regenerate with: partcal simulate elsewhere/sim.yaml." in (tmp_path / "out" / "identification.csv").read_text()
    monkeypatch.chdir(tmp_path / "out")
    write_study(study, data)
    assert f"Regenerate with: partcal simulate {config.resolve()}." in (tmp_path / "out" / "identification.csv").read_text()


def test_a_robot_description_given_as_a_virtual_robot_is_named_as_such(tmp_path):
    from partcal.study.config import load_config
    from partcal.study.prepare import prepare

    robot_file = ROOT / "partcal" / "robot" / "builtin" / "motoman_sk120.yaml"
    with pytest.raises(ConfigError, match=r"motoman_sk120\.yaml: a robot description \(it has 'links' and 'joints'\), "
                                          r"not a virtual robot's config"):
        load_study(robot_file)
    config = tmp_path / "run.yaml"
    config.write_text((ROOT / "configs" / "paper_sk120.yaml").read_text()
                      .replace("../data/", f"{ROOT}/data/").replace("sk120_virtual.yaml", str(robot_file)))
    with pytest.raises(ConfigError, match=r"run\.yaml: verify\.virtual_robot: .*motoman_sk120\.yaml: a robot "
                                          r"description"):
        prepare(load_config(config))


def test_the_paper_column_is_printed_for_the_papers_robot_only():
    """`partcal simulate` sets the paper's Table 2 beside the virtual SK120's figures, not beside a UR10's."""
    from types import SimpleNamespace

    from partcal.study.tables import simulation_table

    class Errors(SimpleNamespace):
        def __len__(self):
            return len(self.errors_mm)

    data = {"identification": Errors(errors_mm=np.array([[3.0, 0.0, 4.0], [-3.0, 0.0, -4.0]]))}
    for name, paper in (("motoman_sk120", True), ("universal_robots_ur10", False)):
        study = SimpleNamespace(robot=SimpleNamespace(nominal=SimpleNamespace(name=name)), seed=0)
        lines = simulation_table(study, data)
        assert ("paper Table 2" in lines[1]) == paper
        assert lines[2].split()[:5] == ["identification", "2", "3.00", "0.00", "4.00"]
        assert lines[2].endswith("8.0 / 7.5 / 17.9") == paper
