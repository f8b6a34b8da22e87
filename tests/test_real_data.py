"""A real robot end to end: the IPA UR10's laser-tracker data, read as exported, registered, modelled.

The data (Landgraf et al., CASE 2021; MIT) stay in ``../shared/datasets/ipa_ur10`` and are read
from there; the test builds a small version of ``configs/ur10_ipa.yaml`` (a few hundred poses per
series, least-squares models) so that it runs in seconds.
"""

import json

import pytest
from conftest import ROOT, SHARED

from partcal.study.config import load_config
from partcal.study.outputs import write_run
from partcal.study.runner import run

UR10 = SHARED / "datasets" / "ipa_ur10"
pytestmark = pytest.mark.skipif(not (UR10 / "PROVENANCE.md").is_file(),
                                reason=f"the shared IPA UR10 data set is not at {UR10}")
SHIPPED = (ROOT / "configs" / "ur10_ipa.yaml").read_text()
FAST = {
    'identification:                # series B (sampled joint configurations): the first 1000 poses\n'
    '    file: ../../shared/datasets/ipa_ur10/Series_B/measurements_joint_configurations.csv\n'
    '    rows: "1-1000"\n':
    'identification:\n'
    '    file: ../../shared/datasets/ipa_ur10/Series_B/measurements_joint_configurations.csv\n'
    '    rows: "1-1000"\n    every: 3\n',
    '      rows: "1001-1495"\n': '      rows: "1001-1495"\n      every: 2\n',
    'random_poses: ../../shared/datasets/ipa_ur10/Series_C/measurements_random_poses.csv':
    'random_poses: {file: ../../shared/datasets/ipa_ur10/Series_C/measurements_random_poses.csv, rows: "1-600", '
    'every: 2}',
    '      registration: own\n': '      registration: own\n      every: 3\n',
}
MODELS = """models:
  - {name: FDP(CI), inputs: cartesian, degree: 1, solver: {method: lstsq}}
  - {name: FDP(AI), inputs: joint, degree: 1, solver: {method: lstsq}}
  - {name: Fourier(AI), inputs: joint, basis: fourier, harmonics: 1, solver: {method: lstsq}}
  - {name: DH, kind: kinematic}
  - {name: DH + GP(AI), kind: kinematic, residual: {kind: gaussian_process, inputs: joint, restarts: 0}}
"""


def layout(tmp_path, text):
    """The shipped layout in a temporary folder: repo/configs/<config>, and shared/ beside repo/."""
    (tmp_path / "repo" / "configs").mkdir(parents=True)
    (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    path = tmp_path / "repo" / "configs" / "ur10_ipa.yaml"
    path.write_text(text)
    return path


def fast_config(tmp_path):
    text = SHIPPED
    for old, new in FAST.items():
        assert old in text, old
        text = text.replace(old, new)
    return layout(tmp_path, text[:text.index("models:")] + MODELS)


@pytest.fixture(scope="module")
def ur10_run(tmp_path_factory):
    path = fast_config(tmp_path_factory.mktemp("ur10"))
    result = run(load_config(path))
    return result, write_run(result)


def test_the_shipped_config_reads_the_shared_files_by_their_relative_path(tmp_path):
    cfg = load_config(layout(tmp_path, SHIPPED))
    assert cfg.identification.resolve() == (UR10 / "Series_B" / "measurements_joint_configurations.csv").resolve()
    assert cfg.data_options.frame == "tracker" and cfg.data_options.own_frame == ("iso_cubes",)
    assert cfg.data_options.rows["identification"].text == "1-1000" and cfg.robot == "universal_robots_ur10"
    for folder in ("configs", "data", "tests", "partcal"):     # the data are never copied into the repository
        assert not list((ROOT / folder).rglob("measurements_*.csv")), folder


def test_registration_of_the_real_tracker_data(ur10_run):
    result, out = ur10_run
    doc = json.loads((out / "metrics.json").read_text())
    reg = doc["registration"]
    assert doc["datasets"] == {"identification": {"n": 334}, "joint_configurations": {"n": 248},
                               "random_poses": {"n": 300}, "iso_cubes": {"n": 211}}
    # a UR10 within its published kinematics: sub-millimetre residual after the rigid fit, and the T-Mac
    # about 93 mm out along the flange axis (the data set's own initial guess says 109 mm to its mount)
    assert 0.3 < reg["rms_3d"] < 1.0 and reg["max_3d"] < 3.0 and reg["condition"] < 50
    assert abs(reg["tool_mm"][2] - 93) < 3 and max(abs(reg["tool_mm"][0]), abs(reg["tool_mm"][1])) < 2
    assert reg["shared_by"] == ["identification", "joint_configurations", "random_poses"]
    own = reg["own"]["iso_cubes"]
    assert 0.3 < own["rms_3d"] < 1.0 and own["tool_mm"] == reg["tool_mm"] and not own["fit_tool"]
    # the shared transform carries series C: errors of a millimetre, not the metres of a wrong frame
    assert 0.7 < doc["uncompensated"]["random_poses"]["rms_3d"] < 1.6
    assert 0.3 < doc["uncompensated"]["joint_configurations"]["rms_3d"] < 1.0
    assert sorted(p.name for p in (out / "data").iterdir()) == [
        "identification.csv", "iso_cubes.csv", "joint_configurations.csv", "random_poses.csv"]


def test_the_best_model_improves_every_test_series(ur10_run):
    """Held-out B, C (random poses) and D (ISO cubes, scored up to a rigid transform in its own frame)."""
    result, out = ur10_run
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["best"].startswith("DH")            # the geometric identification carries the real robot
    best = doc["models"][doc["best"]]
    # measured here (334 training poses): C 1.12 -> 0.87 mm, D 0.64 -> 0.54 mm, held-out B 0.60 -> 0.58 mm
    for series, cut in (("random_poses", 0.85), ("iso_cubes", 0.9), ("joint_configurations", 1.0)):
        before = doc["uncompensated"][series]["rms_3d"]
        assert best[series]["rms_3d"] < cut * before, (doc["best"], series, best[series]["rms_3d"], before)
    assert best["cv"]["rms_3d"] < 0.85 * doc["uncompensated"]["identification"]["rms_3d"]
    # the series models of the paper extrapolate badly outside series B's joint space (C, D): DH does not
    for series in ("random_poses", "iso_cubes"):
        assert doc["models"]["DH"][series]["rms_3d"] < doc["models"]["FDP(AI)"][series]["rms_3d"]


def test_a_pose_run_says_when_its_best_model_leaves_the_orientation_worse_than_doing_nothing(tmp_path, caplog):
    """Ranked on the position, DH (identified from positions alone) wins on 200 poses of series B, and its
    orientation on the next 200 is worse than uncompensated (1.469 against 1.393 mrad): said, not hidden."""
    text = (ROOT / "configs" / "ur10_ipa_pose.yaml").read_text()
    text = text.replace('rows: "1-1000"', 'rows: "1-200"').replace('rows: "1001-1495"', 'rows: "1001-1200"')
    text = text[:text.index("    random_poses:")] + """models:
  - {name: SDP(AI), inputs: joint, degree: 2, solver: {method: lstsq}}
  - {name: DH, kind: kinematic}
"""
    with caplog.at_level("WARNING", logger="partcal.study.runner"):
        result = run(load_config(layout(tmp_path, text.replace("n_jobs: 2", "n_jobs: 1"))))
    best = next(r for r in result.models if r.spec.name == result.best)
    before = result.uncompensated["joint_configurations"]["orientation"]["rms_angle"]
    after = best.metrics["joint_configurations"]["orientation"]["rms_angle"]
    assert result.best == "DH" and after > before
    words = (f"the best model, 'DH', leaves the orientation of joint_configurations worse than doing nothing: "
             f"{after:.3f} mrad RMS against {before:.3f} uncompensated")
    assert any(c.startswith(words) for c in result.best_caveats) and words in caplog.text
    out = write_run(result, lambda res, folder: None)
    assert any(c.startswith(words) for c in json.loads((out / "metrics.json").read_text())["best_caveats"])
