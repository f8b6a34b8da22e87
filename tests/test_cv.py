"""Cross-validation that small and repeated data cannot fool (issue 19): grouped folds, the fold rule,
the standard error and the one-standard-error choice, candidates left out, seeds by name, honest GPs."""

import dataclasses

import numpy as np
import pytest
from conftest import ROOT, partcal_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

from partcal import ConfigError, GaussianProcessErrorModel, load_robot, read_measurements
from partcal.data.measurements import Measurements, write_measurements
from partcal.metrics import pooled_rms, pose_groups, repeat_scatter_mm, rms_standard_error
from partcal.study.selection import choose_simplest, fold_rule, grouped_splits, held_out_residuals
from partcal.models import likelihood
from partcal.study.config import load_config
from partcal.study.fitting import model_seed
from partcal.study.prepare import check_run, load_datasets
from partcal.study.runner import run
from partcal.study.selection import CVPlan

DATA = ROOT / "data" / "sk120"
IDENT = read_measurements(DATA / "identification.csv")


def repeated(m: Measurements, poses: int, times: int, scatter: float, seed: int = 0) -> Measurements:
    """The first ``poses`` poses of ``m``, each measured ``times`` times with ``scatter`` mm of noise."""
    rows = np.repeat(np.arange(poses), times)
    noise = np.random.default_rng(seed).normal(0.0, scatter, (len(rows), 3))
    return Measurements(m.q_deg[rows], m.nominal_mm[rows], m.measured_mm[rows] + noise, name="identification")


# ---------------------------------------------------------------------- groups and folds
def test_poses_are_grouped_by_identical_joints_in_order_of_appearance():
    q = np.array([[0.0, 1.0], [2.0, 0.0], [0.0, 1.0], [2.0, 0.0], [5.0, 5.0]])
    assert pose_groups(q).tolist() == [0, 1, 0, 1, 2]
    assert pose_groups(q + np.array([[1e-9, 0]] * 5)).tolist() == [0, 1, 0, 1, 2]     # below a micro-degree


def jittered_repeats(seed: int, jitter_deg: float = 0.001) -> Measurements:
    """The 85 SK120 identification poses and 20 of them again, q4 and q5 (held at 0) read back with jitter."""
    rng = np.random.default_rng(seed)
    rows = np.r_[np.arange(85), rng.choice(85, 20, replace=False)]
    q = IDENT.q_deg[rows].copy()
    q[:, 3:5] += rng.normal(0.0, jitter_deg, (len(rows), 2))
    return Measurements(q, load_robot("motoman_sk120").positions(q), IDENT.measured_mm[rows], name="identification")


@given(seed=st.integers(0, 10_000), jitter=st.floats(0.0, 0.001))
@settings(max_examples=40, deadline=None)
def test_repeats_read_back_with_encoder_jitter_are_one_pose(seed, jitter):
    m = jittered_repeats(seed, jitter)
    rows = np.r_[np.arange(85), np.random.default_rng(seed).choice(85, 20, replace=False)]
    assert pose_groups(m.q_deg).tolist() == rows.tolist()          # each repeat joins its pose, nothing else joins
    apart = m.q_deg.copy()
    apart[85:, 0] += 0.05                                            # five times the stated tolerance: new poses
    assert pose_groups(apart).max() + 1 == 105


def test_run_check_counts_jittered_repeats_as_poses(tmp_path):
    write_measurements(jittered_repeats(0), tmp_path / "jit.csv")
    cfg = config(tmp_path, "  - {name: DH, kind: kinematic}", ident=tmp_path / "jit.csv")
    data, _, _ = load_datasets(cfg)
    assert "over 85 poses" in check_run(cfg, data).cv.describe()


@given(n_groups=st.integers(2, 40), repeats=st.integers(1, 4), folds=st.integers(2, 12), seed=st.integers(0, 99))
@settings(max_examples=60, deadline=None)
def test_grouped_folds_never_split_a_group_outer_or_nested(n_groups, repeats, folds, seed):
    groups = np.random.default_rng(seed).permutation(np.repeat(np.arange(n_groups), repeats))
    groups = np.unique(groups, return_inverse=True)[1]
    m = Measurements(np.column_stack([groups, groups]).astype(float), np.zeros((len(groups), 3)),
                     np.zeros((len(groups), 3)))
    plan = CVPlan(pose_groups(m.q_deg), fold_rule(folds, n_groups), [], seed, "joints")
    plan = CVPlan(plan.groups, plan.rule, grouped_splits(plan.groups, plan.rule, seed), seed, "joints")
    held = np.concatenate([test for _, test in plan.folds])
    assert sorted(held.tolist()) == list(range(len(groups)))                      # every row held out once
    for train, test in plan.folds:
        assert not set(plan.groups[train]) & set(plan.groups[test])                # no pose on both sides
        for inner_train, inner_test in plan.inner(train):
            g = plan.groups[train]
            assert not set(g[inner_train]) & set(g[inner_test])


def test_k_folds_of_single_rows_are_scikit_learns_kfold():
    from sklearn.model_selection import KFold

    ours = grouped_splits(np.arange(37), 5, random_state=4)
    theirs = KFold(5, shuffle=True, random_state=4).split(np.zeros((37, 1)))
    for (a, b), (c, d) in zip(ours, theirs):
        assert a.tolist() == c.tolist() and sorted(b.tolist()) == sorted(d.tolist())


def test_the_fold_rule():
    assert fold_rule("auto", 16) == fold_rule("auto", 30) == "leave_one_out"
    assert fold_rule("auto", 31) == 5 and fold_rule(10, 4) == 4 and fold_rule("leave_one_out", 90) == "leave_one_out"


# ---------------------------------------------------------------------- standard error and the choice
def test_standard_error_and_the_choice_against_a_hand_computation():
    # three poses of two rows each; residuals along x only
    resid = np.array([[1.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [0.0, 0, 0], [3.0, 0, 0], [1.0, 0, 0]])
    groups = np.array([0, 0, 1, 1, 2, 2])
    # per pose: s = (2, 4, 10), n = 2 each; MSE = 16 / 6 = 8/3; SE(MSE) = sqrt(sum((s - 2 MSE)^2) / 6) / 2
    mse = 8 / 3
    se_mse = np.sqrt(((2 - 2 * mse) ** 2 + (4 - 2 * mse) ** 2 + (10 - 2 * mse) ** 2) / 6) / 2
    assert pooled_rms(resid) == pytest.approx(np.sqrt(mse), rel=1e-12)
    assert rms_standard_error(resid, groups) == pytest.approx(se_mse / (2 * np.sqrt(mse)), rel=1e-12)
    # lowest 0.50 +- 0.05: 0.54 is within, 0.56 is not; of the physical models within, the fewest parameters wins
    physical = [True, True, True]
    assert choose_simplest([0.50, 0.54, 0.56], [0.05, 0.01, 0.01], [90, 26, 10], physical) == 1
    assert choose_simplest([0.50, 0.54, 0.56], [0.05, 0.01, 0.01], [90, 95, 10], physical) == 0
    assert choose_simplest([0.50, 0.50], [np.nan, np.nan], [5, 4], [True, True]) == 1     # equal scores: the simpler
    # a data-driven model is never "simpler": within one SE the physical model wins whatever its size, and
    # without a physical model within, the lowest score wins (not the fewest parameters)
    assert choose_simplest([0.50, 0.54, 0.52], [0.05, 0.01, 0.01], [90, 26, 1], [False, True, False]) == 1
    assert choose_simplest([0.50, 0.56, 0.52], [0.05, 0.01, 0.01], [90, 26, 1], [False, True, False]) == 0
    assert choose_simplest([np.nan, 0.40, 0.45], [0.1] * 3, [10, 20, 5], [True, False, True]) == 2    # NaN never wins


def test_a_configuration_measured_at_two_payloads_is_two_poses():
    from partcal.study.selection import measured_poses

    q = np.repeat(IDENT.q_deg[:3], 2, axis=0)               # each configuration twice
    twice = Measurements(q, IDENT.nominal_mm[[0, 0, 1, 1, 2, 2]], IDENT.measured_mm[[0, 0, 1, 1, 2, 2]])
    assert measured_poses(twice).tolist() == [0, 0, 1, 1, 2, 2]                  # repeats
    loaded = dataclasses.replace(twice, payload_kg=np.array([0.0, 50.0, 0.0, 50.0, 0.0, 0.0]))
    assert measured_poses(loaded).tolist() == [0, 1, 2, 3, 4, 4]                 # the last pair alone repeats


def test_repeat_scatter_is_the_pooled_standard_deviation():
    m = repeated(IDENT, 12, 6, 0.09, seed=1)
    got = repeat_scatter_mm(m.errors_mm, pose_groups(m.q_deg))
    noise = m.measured_mm - IDENT.measured_mm[np.repeat(np.arange(12), 6)]
    spread = noise - noise.reshape(12, 6, 3).mean(axis=1).repeat(6, axis=0)
    assert got == pytest.approx(np.sqrt(np.sum(spread**2) / (3 * (72 - 12))), rel=1e-12)
    assert 0.07 < got < 0.11 and repeat_scatter_mm(IDENT.errors_mm, pose_groups(IDENT.q_deg)) is None


# ---------------------------------------------------------------------- runs
RUN = f"""name: small
robot: motoman_sk120
seed: 5
@EXTRA@
data:
  identification: @IDENT@
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
models:
@MODELS@
"""


def first_poses(tmp_path, n: int):
    """A measurement file of the first ``n`` identification poses."""
    path = tmp_path / f"first{n}.csv"
    write_measurements(Measurements(IDENT.q_deg[:n], IDENT.nominal_mm[:n], IDENT.measured_mm[:n],
                                    name="identification"), path)
    return path


def config(tmp_path, models: str, ident=DATA / "identification.csv", extra: str = ""):
    path = tmp_path / "configs" / "run.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(RUN.replace("@EXTRA@", extra).replace("@IDENT@", str(ident)).replace("@MODELS@", models))
    return load_config(path)


def test_repeated_poses_are_held_out_together_and_floor_the_gp_noise(tmp_path):
    m = repeated(IDENT, 16, 5, 0.09)
    write_measurements(m, tmp_path / "rep.csv")
    cfg = config(tmp_path, "  - {name: GP(AI), kind: gaussian_process, inputs: joint}\n"
                           "  - {name: DH, kind: kinematic}", ident=tmp_path / "rep.csv")
    data, _, _ = load_datasets(cfg)
    plan = check_run(cfg, data)
    assert plan.cv.rule == "leave_one_out" and len(plan.cv.folds) == 16 and "80 rows" in plan.cv.describe()
    assert plan.repeat_scatter_mm == pytest.approx(repeat_scatter_mm(m.errors_mm, pose_groups(m.q_deg)))
    result = run(cfg)
    gp = next(r for r in result.models if r.spec.name == "GP(AI)")
    # the noise term may not sink below the repeat scatter: a twin in the training folds cannot hide it
    floor = (plan.repeat_scatter_mm / gp.model.y_std_.min()) ** 2
    assert gp.model.noise_ >= floor * (1 - 1e-9) and gp.cv_rms_3d > plan.repeat_scatter_mm


def test_a_granularity_no_fold_supports_is_left_out_and_said(tmp_path):
    models = ("  - {name: FDP(CI), degree: 1, solver: {method: lstsq}}\n"
              "  - name: FDP(CI) k-means\n    degree: 1\n    solver: {method: lstsq}\n"
              "    partition: {method: kmeans, n_regions: [1, 2, 3], min_samples: 12}")
    cfg = config(tmp_path, models, ident=first_poses(tmp_path, 40), extra="cv_folds: 5")
    result = run(cfg)
    # 40 poses, 5 folds: outer training folds of 32, inner ones of 25-26: two regions of 12 fit, three do not
    kept = next(r for r in result.models if r.spec.name == "FDP(CI) k-means")
    assert kept.spec.partition.sizes == (1, 2) and kept.nested
    assert any("granularity 3 left out" in note for note in result.plan.notes)
    from partcal.study.outputs import metrics_document
    assert "granularity 3 left out" in metrics_document(result)["cv"]["left_out"][0]


def test_every_model_that_cannot_be_fitted_is_named_at_once(tmp_path):
    models = ("  - {name: FDP(CI), degree: 1, solver: {method: lstsq}}\n"
              "  - {name: TDP(AI), inputs: joint, degree: 3, solver: {method: lstsq}}\n"
              "  - {name: QDP(CI), degree: 4, solver: {method: lstsq}}")
    cfg = config(tmp_path, models, ident=first_poses(tmp_path, 12))      # 12 poses: training folds of 11, 13 terms
    data, _, _ = load_datasets(cfg)
    with pytest.raises(ConfigError) as caught:
        check_run(cfg, data)
    text = str(caught.value)
    assert text.startswith("2 models cannot be fitted") and "'TDP(AI)'" in text and "'QDP(CI)'" in text
    assert "FDP(CI)" not in text


@given(folds=st.one_of(st.integers(2, 20), st.sampled_from(["auto", "leave_one_out"])), n=st.integers(2, 14),
       sizes=st.sampled_from(["[1, 2]", "[2, 3]", "2"]))
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_any_fold_count_runs_or_is_refused_cleanly(tmp_path, folds, n, sizes):
    """cv_folds: 16 on 16 poses with a granularity list used to crash (inner folds asked of too few poses)."""
    models = ("  - {name: FDP(AI), inputs: joint, degree: 1, solver: {method: lstsq}}\n"
              f"  - {{name: grid, inputs: joint, degree: 1, solver: {{method: lstsq}}, "
              f"partition: {{method: kmeans, n_regions: {sizes}, min_samples: 5}}}}")
    cfg = config(tmp_path, models, ident=first_poses(tmp_path, n), extra=f"cv_folds: {folds}")
    try:
        result = run(cfg)
    except ConfigError as exc:
        assert "needs" in str(exc) or "pose" in str(exc)
        return
    for r in result.models:
        assert np.isfinite(r.cv_rms_3d)


def test_the_same_entry_at_two_places_gives_the_same_numbers(tmp_path):
    gp = "  - {name: GP(AI), kind: gaussian_process, inputs: joint, restarts: 0}\n"
    fdp = "  - {name: FDP(CI), degree: 1, solver: {method: pso, particles: 20, iterations: 40}}\n"
    first = run(config(tmp_path, gp + fdp))
    second = run(config(tmp_path, fdp + gp))
    for name in ("GP(AI)", "FDP(CI)"):
        a = next(r for r in first.models if r.spec.name == name)
        b = next(r for r in second.models if r.spec.name == name)
        assert a.cv_rms_3d == b.cv_rms_3d and a.metrics == b.metrics
    assert model_seed(5, "GP(AI)") != model_seed(5, "FDP(CI)")


# ---------------------------------------------------------------------- honest Gaussian processes
@pytest.mark.parametrize("nu", [None, 1.5, 2.5])
def test_likelihood_and_gradient_are_scikit_learns(nu):
    rng = np.random.default_rng(2)
    X, Y = rng.uniform(-1, 1, (40, 3)), rng.normal(size=(40, 3))
    shape = RBF(np.ones(3)) if nu is None else Matern(np.ones(3), nu=nu)
    reference = GaussianProcessRegressor(ConstantKernel() * shape + WhiteKernel(), optimizer=None).fit(X, Y)
    theta = np.log([0.8, 0.4, 1.5, 0.9, 1e-2])
    want, want_grad = reference.log_marginal_likelihood(theta, eval_gradient=True)
    got, grad = likelihood.log_marginal_likelihood(theta, X, Y, nu)
    assert got == pytest.approx(want, rel=1e-12) and np.allclose(grad, want_grad, rtol=1e-9, atol=1e-9)


def test_a_white_noise_fit_and_an_interpolator_are_named():
    rng = np.random.default_rng(0)
    X = rng.uniform(-500, 500, (30, 3))
    noise = GaussianProcessErrorModel(restarts=0, random_state=0).fit(X, rng.normal(size=(30, 3)))
    assert any("white-noise" in note for note in noise.fit_notes())
    smooth = np.c_[np.sin(X[:, 0] / 300), X[:, 1] / 1000, np.cos(X[:, 2] / 400)]
    exact = GaussianProcessErrorModel(restarts=0, random_state=0).fit(X, smooth)
    assert any("reproduces its training data" in note for note in exact.fit_notes())
    floored = GaussianProcessErrorModel(restarts=0, noise_floor_mm=0.01, random_state=0).fit(X, smooth)
    assert floored.fit_notes() == [] and floored.noise_ >= (0.01 / smooth.std(axis=0).min()) ** 2 * (1 - 1e-9)


def test_a_frozen_gp_only_solves_with_the_hyperparameters_it_learnt():
    q, y = IDENT.q_deg, IDENT.errors_mm
    gp = GaussianProcessErrorModel(inputs="joint", restarts=0, random_state=1)
    frozen = gp.frozen(q[:60], y[:60])
    full = gp.fit(q[:60], y[:60])
    again = frozen.fit(q[:60], y[:60])
    assert np.allclose(again.predict(q), full.predict(q), atol=1e-9)
    fold = frozen.fit(q[:40], y[:40])                          # a subset: no search, the same kernel
    assert np.array_equal(fold.length_scale_, full.length_scale_) and fold.noise_ == full.noise_


def test_partitioned_and_hybrid_gps_freeze_their_shared_search():
    """Nested CV freezes a candidate on each outer training set: fitted there again, it is the same model,
    and on an inner fold it searches nothing (its regions reuse the kernel learnt on the outer rows)."""
    from partcal import KinematicModel, KMeansPartition, PartitionedErrorModel

    q, y = IDENT.q_deg, IDENT.errors_mm
    part = PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(inputs="joint",
                                                                                              restarts=0),
                                 random_state=2)
    hybrid = KinematicModel(robot="motoman_sk120", residual=part, random_state=4)
    for model in (part, hybrid):
        frozen = model.frozen(q, y)
        assert np.allclose(frozen.fit(q, y).predict(q), model.fit(q, y).predict(q), atol=1e-8)
        gp = frozen.residual.local if model is hybrid else frozen.local
        assert gp.fixed_kernel is not None
        inner = frozen.fit(q[:60], y[:60])
        regions = inner.residual_.models_ if model is hybrid else inner.models_
        assert all(np.array_equal(r.length_scale_, gp.fixed_kernel["length_scale"]) for r in regions)


@pytest.mark.parametrize("n, models", [
    (5, "  - {name: DH, kind: kinematic}"),
    (10, "  - {name: DH + compliance + harmonics, kind: kinematic, compliance: [2, 3], joint_harmonics: 2}"),
])
def test_kinematic_models_on_a_handful_of_poses_are_fitted_and_reported(tmp_path, n, models):
    config(tmp_path, models, ident=first_poses(tmp_path, n))
    run_yaml = tmp_path / "configs" / "run.yaml"
    assert partcal_cli("run", "--check", str(run_yaml)).returncode == 0
    res = partcal_cli("run", "-q", str(run_yaml))
    assert res.returncode == 0 and "internal error" not in res.stderr, res.stderr
    metrics = __import__("json").loads((tmp_path / "reports" / "small" / "metrics.json").read_text())
    model = next(iter(metrics["models"].values()))
    assert np.isfinite(model["cv"]["rms_3d"]) and (tmp_path / "reports" / "small" / "index.html").is_file()


def test_printed_tables_show_whole_model_names(tmp_path):
    from partcal.study.tables import results_table

    long = ["DH + compliance + harmonics, wrist", "DH + compliance + harmonics, elbow"]
    cfg = config(tmp_path, "".join(f"  - {{name: {name!r}, kind: kinematic, compliance: [2]}}\n" for name in long),
                 ident=first_poses(tmp_path, 30))
    table = results_table(run(cfg))
    for name in long:
        row = next(line for line in table.splitlines() if line.startswith(name))
        assert row[len(name):].lstrip("*")[0] == " "      # the name whole (a mark of notes), a gap, the numbers


def test_folds_fitted_side_by_side_are_the_sequential_folds():
    from partcal.models.kinematic import KinematicModel
    from partcal.study.selection import fits_on_folds, grouped_splits

    model = KinematicModel(robot="motoman_sk120", compliance=[2, 3], random_state=0)
    folds = grouped_splits(np.arange(len(IDENT)), 5, 0)
    runs = []
    for n_jobs in (1, 2):
        fitted, said, finals = [], [], []
        resid, final, seconds = fits_on_folds(model, IDENT.q_deg, IDENT.errors_mm, folds, fitted=fitted, n_jobs=n_jobs,
                                              final=True, progress=lambda done, total: said.append((done, total)),
                                              on_final=finals.append)
        assert said == [(k, 5) for k in range(1, 6)] and len(finals) == 1 and seconds == finals[0] > 0
        runs.append((resid, final, fitted))
    (r1, f1, m1), (r2, f2, m2) = runs
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(f1.predict(IDENT.q_deg), f2.predict(IDENT.q_deg))
    for a, b in zip(m1, m2):          # each fold's model in its place
        np.testing.assert_array_equal(a.identification_.value, b.identification_.value)
    alone = held_out_residuals(model, IDENT.q_deg, IDENT.errors_mm, folds)
    np.testing.assert_array_equal(alone, r1)
