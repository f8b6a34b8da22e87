"""Joint compliance and transmission errors in the kinematic model, against the virtual robot.

The data come from ``partcal.data.simulate.VirtualRobot``, which deflects joints by its own code
(point masses at DH frame origins, torque about a pivot frame's z axis, ``dq = torque / stiffness``)
and adds gear errors ``A sin(k q + phase)``: an implementation independent of the model's.
"""

import dataclasses

import numpy as np
import yaml
import pytest
from threadpoolctl import threadpool_limits
from test_kinematic import sk120_poses

from partcal import KinematicModel, PartcalError
from partcal.data.simulate import Compliance, Tracker, VirtualRobot
from partcal.calibration.chain import actual_joints, model_jacobian, model_positions
from partcal.calibration.parameters import nominal_values, parameter_names, robot_with
from partcal.calibration.joint_errors import JointErrors
from partcal.robot.rotations import matrix_from_rpy_deg

@pytest.fixture(autouse=True, scope="module")
def one_blas_thread():
    """Small matrices: BLAS threads only wait on each other on a busy machine (ten times slower)."""
    with threadpool_limits(1):
        yield


GEARS = ((1, 0.02, 1, 30.0), (2, 0.03, 2, -45.0), (3, 0.03, 2, 60.0), (6, 0.05, 1, 0.0))
HARMONICS = [1, 2, 2, 0, 0, 1]


def virtual(nominal, free, payload_kg=0.0, seed=0, sigma_mm=0.0, gears=GEARS):
    """A virtual SK120 with the joint errors of configs/sk120_virtual.yaml (compliance on joints 2 and 3,
    gears on 1, 2, 3, 6), a payload at frame 8 (the flange), and a tracker of noise ``sigma_mm`` at 3 m.

    Its geometry (DH rows, tool, base) differs from the nominal one in the directions ``free`` (bool, per
    geometric parameter) only: a deviation along an unidentifiable direction is absorbed by the others to
    first order only, and exactness is the point here. Each joint bends about its own axis: the z axis of
    the first DH row it turns (frame 2 for joint 2, whose first row is ``q2 - q3``; frame 1 for joint 3).
    (The config's virtual robot takes joint 3's torque about frame 4, whose axis its random twist errors
    tilt by a few hundredths of a degree.)
    """
    size = free.size
    units = np.array([u for _, u in parameter_names(nominal)])
    values = nominal_values(nominal)
    values += np.random.default_rng(seed).normal(size=size) * np.where(units == "mm", 1.5, 0.05) * free
    if not nominal.tool_mm.any():                   # the payload sits at the tool point: the flange
        values[size - 9:size - 6] = 0.0
    own = values.copy()
    own[size - 6:] = 0.0
    compliance = (Compliance(2, 2, (4, 8), (300.0, payload_kg), 10000.0),
                  Compliance(3, 1, (6, 8, 8), (250.0, 120.0, payload_kg), 8000.0))
    true = robot_with(nominal, own)
    tracker = Tracker(np.array([3500.0, 0, -800]), 0.0, sigma_mm / 3000 * 1e6, 1)
    return VirtualRobot(nominal, true, matrix_from_rpy_deg(values[size - 3:]),
                        values[size - 6:size - 3], compliance, gears, tracker, 0.0)


def geometric_free(nominal, q, **params):
    """Which geometric parameters the model identifies from poses ``q``."""
    table = KinematicModel(robot=nominal, **params).fit(q, np.zeros((len(q), 3))).identification_
    size = 4 * nominal.alpha_deg.size + 9
    return np.array([s == "identified" for s in table.status[:size]])


def joint_error(vr, q):
    """The simulated joint error (gear and sag) of every joint, degrees."""
    return vr.actual_joints(q) - q


@pytest.fixture(scope="module")
def exact_fit(sk120):
    q = sk120_poses(sk120, 200, 11)
    params = {"compliance": [2, 3], "joint_harmonics": HARMONICS}
    vr = virtual(sk120, geometric_free(sk120, q, **params))
    return vr, q, KinematicModel(robot=sk120, **params).fit(q, vr.true_positions(q) - sk120.positions(q))


def test_noise_free_identification_reproduces_the_virtual_robot_exactly(sk120, exact_fit):
    vr, q, model = exact_fit
    assert model.identification_.rms_mm < 1e-9
    other = sk120_poses(sk120, 100, 12)
    truth = vr.true_positions(other) - sk120.positions(other)
    assert np.abs(truth).max() > 1.0                                    # mm: there is something to recover
    np.testing.assert_allclose(model.predict(other), truth, rtol=0, atol=1e-8 * np.abs(truth).max())
    dh_only = KinematicModel(robot=sk120).fit(q, vr.true_positions(q) - sk120.positions(q))
    assert dh_only.identification_.rms_mm > 0.05                      # the geometry alone cannot


def test_noise_free_identification_recovers_the_gear_harmonics_exactly(exact_fit):
    """``A sin(k q + phase) = A cos(phase) sin(k q) + A sin(phase) cos(k q)``, for every gear of the virtual
    robot (its joint 2 and 3 gears are second harmonics; first harmonics of those joints share their
    columns with the gravity sag, and are checked through the joint error below)."""
    table = dict(zip(model_names := exact_fit[2].identification_.names, exact_fit[2].identification_.value))
    status = dict(zip(model_names, exact_fit[2].identification_.status))
    for joint, amp, k, phase in GEARS:
        for name, want in ((f"sin{k}[{joint}]", amp * np.cos(np.radians(phase))),
                           (f"cos{k}[{joint}]", amp * np.sin(np.radians(phase)))):
            assert status[name] == "identified"
            assert abs(table[name] - want) <= 1e-8 * amp, (name, table[name], want)


def test_identified_joint_errors_equal_the_simulated_gear_and_sag_up_to_the_joint_offset(sk120, exact_fit):
    vr, q, model = exact_fit
    other = sk120_poses(sk120, 100, 13)
    own = model.identification_.value.copy()
    size = 4 * sk120.alpha_deg.size + 9
    identified = actual_joints(sk120, model.joint_errors_, other, own, np.zeros(len(other)))[0] - other
    simulated = joint_error(vr, other)
    for j in (0, 1, 2, 5):
        change = simulated[:, j] - simulated[:, j].mean()
        assert np.ptp(change) > 0.01                                     # deg
        np.testing.assert_allclose(identified[:, j] - identified[:, j].mean(), change, rtol=0,
                                   atol=1e-8 * np.ptp(change))
    assert own.size > size


def test_two_payloads_identify_the_compliances_and_predict_a_third(sk120):
    """A payload at the flange (tool offset zero: the tool point is frame 8, and joint 6 turns it about
    itself, so its gear error is left out)."""
    nominal = sk120.replace(tool_mm=np.zeros(3))
    q = sk120_poses(sk120, 240, 14)
    loads = np.repeat([0.0, 100.0], 120)
    params = {"compliance": [2, 3], "joint_harmonics": HARMONICS}
    free = geometric_free(nominal, q, **params)
    measured = np.empty((len(q), 3))
    for kg in (0.0, 100.0):
        rows = loads == kg
        measured[rows] = virtual(nominal, free, kg, gears=GEARS[:3]).true_positions(q[rows])
    model = KinematicModel(robot=nominal, **params)
    model.fit(q, measured - nominal.positions(q), payload_kg=loads)
    table = dict(zip(model.identification_.names, model.identification_.value))
    assert abs(table["compliance[2]"] - 1 / 10000) < 1e-8 / 10000
    assert abs(table["compliance[3]"] - 1 / 8000) < 1e-8 / 8000
    other = sk120_poses(sk120, 60, 15)
    truth = virtual(nominal, free, 50.0, gears=GEARS[:3]).true_positions(other) - nominal.positions(other)
    assert np.abs(truth - model.predict(other, payload_kg=0.0)).max() > 0.1      # the payload matters (mm)
    np.testing.assert_allclose(model.predict(other, payload_kg=50.0), truth, rtol=0, atol=1e-8 * np.abs(truth).max())
    # one payload only: the compliance cannot be told from the masses, and is reported so
    single = KinematicModel(robot=nominal, compliance=[2, 3]).fit(q[:120], measured[:120] - nominal.positions(q[:120]))
    assert {"compliance[2]", "compliance[3]"} <= set(single.identification_.unidentifiable())
    assert single.fit_notes() == ["compliance[2], compliance[3] not identifiable (data at one payload show only the "
                                  "sags): the predictions do not change with the payload"]


def test_parameters_lie_within_two_standard_errors_over_twenty_noise_draws(sk120, exact_fit):
    """The identified values of the noise-free fit are the truth of this parametrisation."""
    vr, q, exact = exact_fit
    noisy = dataclasses.replace(vr, tracker=Tracker(np.array([3500.0, 0, -800]), 0.0, 10.0, 1))   # 0.03 mm
    rng = np.random.default_rng(16)
    free = np.array([s == "identified" for s in exact.identification_.status])
    inside = []
    model = KinematicModel(robot=sk120, compliance=[2, 3], joint_harmonics=HARMONICS)
    for _ in range(20):
        table = model.fit(q, noisy.measure(q, rng) - sk120.positions(q)).identification_
        assert [s == "identified" for s in table.status] == free.tolist()
        inside.append(np.abs(table.value - exact.identification_.value)[free] <= 2 * table.std_error[free])
    assert np.mean(inside) >= 0.9, np.mean(inside)


def test_parameter_names_units_and_layout(sk120):
    errors = JointErrors.for_robot(sk120, [2, 3], [1, 0, 0, 0, 0, 2])
    names = errors.names()
    assert names[:2] == [("sin1[1]", "deg"), ("cos1[1]", "deg")]
    assert names[2:6] == [("sin1[6]", "deg"), ("cos1[6]", "deg"), ("sin2[6]", "deg"), ("cos2[6]", "deg")]
    # joint 2 first turns row 3 (q2 - q3), about frame 2: the later frames 3..8, but frame 7 (row 7 has
    # a = d = 0, so frame 7 is frame 6); joint 3 first turns row 2 (q3), about frame 1
    assert names[6:12] == [(f"sag[2,f{f}]", "deg/m") for f in (3, 4, 5, 6, 8)] + [("compliance[2]", "deg/(N m)")]
    assert names[12:] == [(f"sag[3,f{f}]", "deg/m") for f in (2, 3, 4, 5, 6, 8)] + [("compliance[3]", "deg/(N m)")]
    assert errors.size == len(names) == 19 and errors.pivots == (2, 1) and errors.signs == (1.0, 1.0)


@pytest.mark.parametrize("params, message", [
    ({"compliance": [7]}, r"The 'compliance' parameter of KinematicModel must be a list of distinct joint numbers "
                          r"in \[1, 6\]\. Got \[7\] instead\."),
    ({"compliance": [2, 2]}, r"'compliance' .* Got \[2, 2\] instead"),
    ({"joint_harmonics": 9}, r"The 'joint_harmonics' parameter of KinematicModel must be an int in \[0, 8\] or a "
                             r"list of 6 such ints\. Got 9 instead\."),
    ({"joint_harmonics": [1, 2]}, r"'joint_harmonics' .* Got \[1, 2\] instead"),
    ({"payload_kg": -1.0}, r"The 'payload_kg' parameter of KinematicModel must be a real number in \[0\.0, "
                           r"100000\.0\]\. Got -1\.0 instead\."),
])
def test_bad_joint_error_parameters_are_refused(sk120, params, message):
    q = sk120_poses(sk120, 30, 17)
    with pytest.raises(PartcalError, match=message):
        KinematicModel(robot=sk120, **params).fit(q, np.zeros((30, 3)))


def test_a_bad_payload_per_pose_is_refused(sk120, exact_fit):
    q = sk120_poses(sk120, 5, 18)
    with pytest.raises(PartcalError, match=r"Expected payload_kg as one number in \[0, 100000\] or 5 of them"):
        exact_fit[2].predict(q, payload_kg=[1.0, 2.0])
    with pytest.raises(PartcalError, match=r"Expected payload_kg as one number in \[0, 100000\] or 5 of them"):
        exact_fit[2].predict(q, payload_kg=-3.0)
    with pytest.raises(PartcalError, match=r"got 1 values from 1000000000.0 to 1000000000.0"):
        exact_fit[2].predict(q, payload_kg=1e9)


@pytest.mark.parametrize("parametrization, origins", [("dh", False), ("complete", False), ("dh", True)])
def test_the_analytic_jacobian_matches_central_differences(sk120, parametrization, origins):
    """Every column, at a point where every parameter (harmonics of all joints, sags, compliances, a payload
    per pose) is off zero: the lever arms move with the rows (DH or complete; DH rows with further origins,
    as a URDF's chain has), the tool and the harmonics."""
    from partcal.calibration.parameters import geometric_size

    q = sk120_poses(sk120, 30, 19)
    if origins:
        sk120 = sk120.replace(origins=np.random.default_rng(21).normal(0, [20, 20, 20, 5, 5, 5], (8, 6)))
    errors = JointErrors.for_robot(sk120, [2, 3], [1, 2, 2, 1, 1, 1])
    rng = np.random.default_rng(20)
    names = [n for n, _ in parameter_names(sk120, errors, parametrization)]
    values = nominal_values(sk120, errors, parametrization) + rng.normal(size=len(names)) * 0.05
    size = geometric_size(sk120, parametrization)
    values[size:] = rng.normal(size=errors.size) * 0.3
    values[[k for k, n in enumerate(names) if n.startswith("compliance")]] = 1e-4
    payload = rng.uniform(0, 100, len(q))
    jac = model_jacobian(sk120, errors, q, values, payload, parametrization)[1]
    for k in range(values.size):
        step = 1e-5 * max(1.0, abs(values[k]))
        up, down = values.copy(), values.copy()
        up[k] += step
        down[k] -= step
        central = (model_positions(sk120, errors, q, up, payload, parametrization)
                   - model_positions(sk120, errors, q, down, payload, parametrization)).ravel() / (2 * step)
        assert np.linalg.norm(jac[:, k] - central) <= 1e-6 * np.linalg.norm(central), names[k]


RUN = """name: physics
robot: motoman_sk120
seed: 3
cv_folds: 5
data:
  identification: {data}/identification.csv
  tests:
    rectangle: {data}/test_rectangle.csv
verify:
  virtual_robot: {root}/configs/sk120_virtual.yaml
models:
  - {{name: DH, kind: kinematic}}
  - {{name: DH+C+H, kind: kinematic, compliance: [2, 3], joint_harmonics: 2}}
  - {{name: DH+C+H + FDP(AI), kind: kinematic, compliance: [2, 3], joint_harmonics: [1, 2, 2, 0, 0, 1],
      residual: {{inputs: joint, degree: 1, solver: {{method: lstsq}}}}}}
"""


@pytest.fixture(scope="module")
def physics_run(tmp_path_factory):
    from conftest import ROOT

    from partcal.report import render_report
    from partcal.study.config import load_config
    from partcal.study.outputs import write_run
    from partcal.study.runner import run

    tmp = tmp_path_factory.mktemp("physics")
    (tmp / "run.yaml").write_text(RUN.format(data=ROOT / "data" / "sk120", root=ROOT))
    result = run(load_config(tmp / "run.yaml"))
    return result, write_run(result, render_report)


def test_a_run_fits_ranks_saves_compensates_and_reports_the_joint_errors(physics_run):
    import json

    import html5lib

    from partcal import load_predictor

    result, out = physics_run
    doc = json.loads((out / "metrics.json").read_text())
    models = doc["models"]
    assert models["DH+C+H"]["rectangle"]["rms_3d"] < 0.1 < models["DH"]["rectangle"]["rms_3d"]
    assert doc["best"] in ("DH+C+H", "DH+C+H + FDP(AI)")
    spec = {r.spec.name: r for r in result.models}
    for name in ("DH+C+H", "DH+C+H + FDP(AI)"):
        p = load_predictor(out / models[name]["file"])
        assert p.model.joint_errors_.compliance == (2, 3)
        q = spec[name].model.data_bounds_
        np.testing.assert_array_equal(p.predict(joints=q), spec[name].model.predict(q))
        c = spec[name].compensation["rectangle"]
        assert c["converged"] == c["n"] and c["after"]["rms_3d"] < 0.1 * c["before"]["rms_3d"], name
    text = (out / "index.html").read_text()
    tree = html5lib.parse(text, namespaceHTMLElements=False)
    tables = [t for t in tree.iter("table") if t.get("class") == "dh joint-errors"]
    assert len(tables) == 2                          # the hybrid's joint harmonics differ: its own table
    table = json.loads((out / models["DH+C+H"]["file"]).read_text())["model"]["identification"]
    cells = {td.get("data-name"): td for td in tables[0].iter("td") if td.get("data-name")}
    joint = table["names"][41:]
    assert list(cells) == joint and len(joint) == 2 * 2 * 6 + 5 + 1 + 6 + 1
    for name, value, se, status in zip(table["names"][41:], table["value"][41:], table["std_error"][41:],
                                       table["status"][41:]):
        fixed = name.startswith(("sin", "cos"))
        show = (lambda v: f"{v:.4f}") if fixed else (lambda v: f"{v:.4g}")
        expected = show(value) + (f" ± {show(se)}" if status == "identified" else "")
        assert cells[name].text.startswith(expected) and cells[name].get("class") == status, name


def test_a_payload_is_a_prediction_input_only_of_a_compliant_model(physics_run, sk120):
    from partcal import PartcalError, load_predictor

    result, out = physics_run
    doc = __import__("json").loads((out / "metrics.json").read_text())
    q = sk120_poses(sk120, 5, 21)
    q[:, 3:5] = 0.0
    dh = load_predictor(out / doc["models"]["DH"]["file"])
    with pytest.raises(PartcalError, match=r"model 'DH' has no joint that yields under gravity, so a payload "
                                           r"changes nothing it predicts; got payload_kg=10\.0"):
        dh.predict(joints=q, payload_kg=10.0)
    physics = load_predictor(out / doc["models"]["DH+C+H"]["file"])
    heavier = physics.predict(joints=q, payload_kg=50.0) - physics.predict(joints=q)
    # without data at two payloads the compliance is unidentifiable (held at 0): the payload moves nothing
    assert "compliance[2]" in physics.model.identification_.unidentifiable()
    np.testing.assert_array_equal(heavier, 0.0)


@pytest.mark.parametrize("old, new, message", [
    ("compliance: [2, 3], joint_harmonics: 2}", "compliance: [7], joint_harmonics: 2}",
     r"models\[1\]\.compliance \(line {line}\): must be a list of distinct joint numbers in \[1, 6\]; got a list"),
    ("compliance: [2, 3], joint_harmonics: 2}", "compliance: [2, 3], joint_harmonics: two}",
     r"models\[1\]\.joint_harmonics \(line {line}\): must be an int in \[0, 8\] or a list of 6 such ints; "
     r"got 'two'"),
    ("{name: DH, kind: kinematic}", "{name: DH, inputs: joint, compliance: [2]}",
     r"models\[0\]\.compliance \(line {line}\): applies to kind: kinematic only; this entry is kind: series"),
    ("{name: DH, kind: kinematic}", "{name: DH, kind: kinematic, payload_kg: -5}",
     r"models\[0\]\.payload_kg \(line {line}\): must be a real number in \[0\.0, 100000\.0\]; got -5\.0"),
])
def test_joint_error_keys_of_a_run_config_are_checked_with_path_and_line(tmp_path, old, new, message):
    from conftest import ROOT

    from partcal.errors import ConfigError
    from partcal.study.config import load_config

    text = RUN.format(data=ROOT / "data" / "sk120", root=ROOT).replace(old, new, 1)
    line = text[:text.index(new)].count("\n") + 1
    path = tmp_path / "run.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(path)


def test_model_files_round_trip_and_files_without_joint_errors_still_load(tmp_path, sk120, exact_fit):
    import json

    from conftest import ROOT

    from partcal.errors import ModelFileError
    from partcal.study.persist import load_model, model_to_dict, save_model

    _, q, model = exact_fit
    save_model(model, tmp_path / "physics.json", name="DH+C+H", robot=sk120)
    loaded, doc = load_model(tmp_path / "physics.json")
    assert doc["model"]["compliance"] == [2, 3] and doc["model"]["joint_harmonics"] == HARMONICS
    assert np.array_equal(loaded.predict(q), model.predict(q))
    assert model_to_dict(loaded) | {"partcal_version": 0} == model_to_dict(model) | {"partcal_version": 0}
    old, _ = load_model(ROOT / "tests" / "fixtures" / "format2_dh-gp-ai-k-means.json")     # before issue 21
    assert old.joint_errors_.empty and not old.reads_payload and old.payload_kg == 0.0
    # a file whose joint errors disagree with its table is refused, naming the field
    doc["model"]["joint_harmonics"] = [1, 2, 2, 0, 0, 2]
    doc.pop("checksum")
    (tmp_path / "edited.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"edited\.json: field 'model\.identification\.names': expected the "
                                             r"\d+ parameters of motoman_sk120"):
        load_model(tmp_path / "edited.json")


@pytest.fixture(scope="module")
def payload_files(sk120, tmp_path_factory):
    """The two-payload identification set of the test above and a test set at a third payload, written as
    measurement CSVs with a ``payload_kg`` column, and a run config fitting DH with and without compliance."""
    from partcal.data.measurements import Measurements, write_measurements
    from partcal.robot.description import robot_to_dict

    tmp = tmp_path_factory.mktemp("payload")
    nominal = sk120.replace(tool_mm=np.zeros(3))
    free = geometric_free(nominal, sk120_poses(sk120, 240, 14), compliance=[2, 3], joint_harmonics=HARMONICS)
    sets = {"identification": (sk120_poses(sk120, 240, 14), np.repeat([0.0, 100.0], 120)),
            "half_load": (sk120_poses(sk120, 60, 15), np.full(60, 50.0))}
    for name, (q, loads) in sets.items():
        measured = np.empty((len(q), 3))
        for kg in np.unique(loads):
            measured[loads == kg] = virtual(nominal, free, kg, gears=GEARS[:3]).true_positions(q[loads == kg])
        write_measurements(Measurements(q, nominal.positions(q), measured, payload_kg=loads), tmp / f"{name}.csv")
    (tmp / "robot.yaml").write_text(yaml.safe_dump(robot_to_dict(nominal)))
    (tmp / "run.yaml").write_text(f"""name: payload
robot: robot.yaml
output: out
cv_folds: 4
data: {{identification: identification.csv, tests: {{half_load: half_load.csv}}}}
models:
  - {{name: DH, kind: kinematic}}
  - {{name: DH + C, kind: kinematic, compliance: [2, 3], joint_harmonics: {HARMONICS}}}
""")
    return tmp


def test_a_run_reads_the_payload_of_each_pose_from_its_file(payload_files, capsys):
    """The column reaches the identification, every CV fold and the test predictions: noise-free data are
    then reproduced at a payload never measured (to 1e-3 mm: the files keep micro-degrees, and QR pivoting
    on the rounded angles picks other columns of the same rank than the virtual robot's errors use, which
    they absorb to first order); the same files read without it (one payload for all, the model's default
    0 kg) are not."""
    from partcal.data.measurements import read_measurements
    from partcal.study.config import load_config
    from partcal.study.runner import run

    loads = read_measurements(payload_files / "identification.csv").payload_kg
    assert loads.tolist() == [0.0] * 120 + [100.0] * 120
    result = run(load_config(payload_files / "run.yaml"))
    dh, dhc = (next(r for r in result.models if r.spec.name == name) for name in ("DH", "DH + C"))
    assert dhc.metrics["half_load"]["rms_3d"] < 1e-3 and dhc.cv_rms_3d < 1e-3       # mm
    assert dh.metrics["half_load"]["rms_3d"] > 0.1 and dh.cv_rms_3d > 0.1
    assert result.best == "DH + C"
    # the model file predicts the same from the file's payload column (partcal predict)
    from partcal.cli import main
    from partcal.study.persist import save_model

    save_model(dhc.model, payload_files / "dhc.json", name="DH + C", robot=dhc.model.robot_)
    assert main(["predict", str(payload_files / "dhc.json"), str(payload_files / "half_load.csv"),
                 "-o", str(payload_files / "pred.csv")]) == 0
    out = np.genfromtxt(payload_files / "pred.csv", delimiter=",", names=True)
    assert out.dtype.names[6:] == ("payload_kg", "dx", "dy", "dz") and set(out["payload_kg"]) == {50.0}
    np.testing.assert_allclose(np.column_stack([out["dx"], out["dy"], out["dz"]]), dhc.predictions["half_load"],
                               atol=2e-6)
    text = (payload_files / "half_load.csv").read_text().splitlines()
    (payload_files / "bad.csv").write_text("\n".join([text[0], text[1], text[2].rsplit(",", 1)[0] + ",-5"]) + "\n")
    capsys.readouterr()
    assert main(["predict", str(payload_files / "dhc.json"), str(payload_files / "bad.csv"), "-o",
                 str(payload_files / "bad_out.csv")]) == 2
    assert capsys.readouterr().err == (f"partcal: error: {payload_files / 'bad.csv'}:3: column 'payload_kg': "
                                       "expected a payload mass in [0, 100000] kg, got -5\n")
    assert not (payload_files / "bad_out.csv").exists()
    # partcal compensate: each target at its own payload; the identified robot then reaches it (the model's
    # own prediction of the commanded joints, at that payload, lands on the target)
    test = read_measurements(payload_files / "half_load.csv")
    rows = ["x,y,z," + ",".join(f"q{j}" for j in range(1, 7)) + ",payload_kg"]
    rows += [",".join(f"{v:.6f}" for v in (*p, *q, kg)) for p, q, kg in zip(test.nominal_mm[:6], test.q_deg[:6],
                                                                            [0, 0, 0, 80, 80, 80])]
    (payload_files / "targets.csv").write_text("\n".join(rows) + "\n")
    assert main(["compensate", str(payload_files / "dhc.json"), str(payload_files / "targets.csv"), "-o",
                 str(payload_files / "cmd.csv")]) == 0
    cmd = np.genfromtxt(payload_files / "cmd.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert list(cmd["payload_kg"]) == [0, 0, 0, 80, 80, 80]
    q_cmd = np.column_stack([cmd[f"q{j}_cmd"] for j in range(1, 7)])
    reached = dhc.model.robot_.positions(q_cmd) + dhc.model.predict(q_cmd, payload_kg=cmd["payload_kg"])
    np.testing.assert_allclose(reached, test.nominal_mm[:6], atol=1e-3)
    for name in ("identification.csv", "half_load.csv"):        # the same poses, the payload column dropped
        text = (payload_files / name).read_text().splitlines()
        column = text[0].split(",").index("payload_kg")
        (payload_files / name).write_text("\n".join(",".join(c for k, c in enumerate(line.split(",")) if k != column)
                                                    for line in text) + "\n")
    blind = next(r for r in run(load_config(payload_files / "run.yaml")).models if r.spec.name == "DH + C")
    assert blind.metrics["half_load"]["rms_3d"] > 0.1


def test_a_compliance_fitted_at_one_nonzero_payload_is_unidentifiable_and_predicted_there(sk120, tmp_path):
    """5 kg on every pose: compliance x 5 kg is a sag at the tool point like the masses' ones, so the
    compliance is reported unidentifiable (as at 0 kg), the model predicts at 5 kg when given no payload,
    the same at any payload, and warns about a payload it never saw."""
    from partcal import load_predictor
    from partcal.metrics import ExtrapolationWarning
    from partcal.study.persist import save_model

    nominal = sk120.replace(tool_mm=np.zeros(3))
    q = sk120_poses(sk120, 120, 14)
    params = {"compliance": [2, 3], "joint_harmonics": HARMONICS}
    vr = virtual(nominal, geometric_free(nominal, q, **params), 5.0, gears=GEARS[:3])
    model = KinematicModel(robot=nominal, **params).fit(q, vr.true_positions(q) - nominal.positions(q),
                                                         payload_kg=np.full(len(q), 5.0))
    assert {"compliance[2]", "compliance[3]"} <= set(model.identification_.unidentifiable())
    assert model.fit_notes()[0].startswith("compliance[2], compliance[3] not identifiable")
    other = sk120_poses(sk120, 20, 15)
    at_five = model.predict(other, payload_kg=5.0)
    np.testing.assert_array_equal(model.predict(other), at_five)
    for kg in (0.0, 40.0):
        with pytest.warns(ExtrapolationWarning, match=rf"payload {kg:g} to {kg:g} kg lies outside the payloads the "
                                                      r"model was fitted at \(5 kg\): from one payload its compliance"):
            np.testing.assert_allclose(model.predict(other, payload_kg=kg), at_five, rtol=0, atol=1e-12)
    save_model(model, tmp_path / "m.json", name="DH + compliance")
    predictor = load_predictor(tmp_path / "m.json")
    np.testing.assert_array_equal(predictor.predict(joints=other), at_five)
