"""Weighted and robust kinematic identification (issue 41): each against values computed independently."""

import numpy as np
import pytest
from conftest import ROOT
from scipy.optimize import least_squares

from partcal import KinematicModel, PartcalError
from partcal.data.simulate import load_study
from partcal.study.persist import load_model, save_model
from partcal.metrics import loss_weights
from partcal.models.identification import identify, robot_with


@pytest.fixture(scope="module")
def ur10():
    """The virtual UR10 with tilted axes, 120 random poses and their true positions."""
    study = load_study(ROOT / "configs" / "ur10_tilts_virtual.yaml")
    rng = np.random.default_rng(4)
    limits = study.robot.nominal.limits_deg.copy()
    for joint, (lo, hi) in study.ranges_deg.items():
        limits[joint - 1] = lo, hi
    q = rng.uniform(limits[:, 0], limits[:, 1], (120, 6))
    return study.robot, q, study.robot.true_positions(q), rng


def test_weighted_fit_minimises_the_residuals_divided_by_their_std(ur10):
    vr, q, true, rng = ur10
    std = np.repeat(rng.uniform(0.005, 0.05, (len(q), 1)), 3, axis=1)
    std[:, 2] *= 2.0                                  # per coordinate too
    measured = true + rng.standard_normal(true.shape) * std
    table = identify(vr.nominal, q, measured, std_mm=std)         # DH: the tilts stay unmodelled, as may happen
    free = np.flatnonzero(np.array(table.status) == "identified")

    def scaled(x):                                    # the rows divided by their std by hand, plain least squares
        v = table.nominal.copy()
        v[free] = x
        return ((robot_with(vr.nominal, v).positions(q) - measured) / std).ravel()
    by_hand = least_squares(scaled, table.nominal[free], method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15).x
    np.testing.assert_allclose(table.value[free], by_hand, atol=1e-5)     # by_hand: finite-difference Jacobian
    assert np.sum(scaled(table.value[free]) ** 2) <= np.sum(scaled(by_hand) ** 2) * (1 + 1e-9)
    plain = identify(vr.nominal, q, measured)
    assert np.max(np.abs(plain.value[free] - by_hand)) > 1e-4          # the weights change the answer
    ref = np.sqrt(np.mean(std**2))
    assert table.sigma_mm == pytest.approx(ref * np.sqrt(np.sum(scaled(table.value[free]) ** 2) /
                                                         (scaled(by_hand).size - free.size)), rel=1e-6)
    assert table.rms_mm == pytest.approx(np.sqrt(np.mean(np.sum((robot_with(vr.nominal, table.value).positions(q)
                                                                 - measured) ** 2, axis=1))), rel=1e-9)


def test_equal_std_gives_the_unweighted_fit(ur10):
    vr, q, true, rng = ur10
    measured = true + rng.normal(0.0, 0.02, true.shape)
    weighted = identify(vr.nominal, q, measured, std_mm=np.full(true.shape, 0.02))
    plain = identify(vr.nominal, q, measured)
    np.testing.assert_allclose(weighted.value, plain.value, atol=1e-9)
    np.testing.assert_allclose(weighted.covariance, plain.covariance, rtol=1e-6, atol=1e-15)


@pytest.mark.parametrize("std", [np.zeros((120, 3)), np.full((120, 2), 0.01), np.full((119, 3), 0.01)])
def test_bad_std_is_refused(ur10, std):
    vr, q, true, _ = ur10
    with pytest.raises(PartcalError, match="std_mm"):
        identify(vr.nominal, q, true, std_mm=std)


def test_robust_loss_names_the_corrupted_rows_and_ignores_them(ur10):
    vr, q, true, rng = ur10
    clean = true + rng.normal(0.0, 0.01, true.shape)
    bad = np.array([7, 50, 93])
    shifted = clean.copy()
    shifted[bad] += [[2.0, 0.0, 0.0], [0.0, -1.5, 0.0], [1.0, 1.0, 3.0]]
    nominal = vr.nominal.positions(q)
    q_test = q + rng.normal(0.0, 20.0, q.shape)
    truth = vr.true_positions(q_test) - vr.nominal.positions(q_test)

    def error(model):
        return np.sqrt(np.mean(np.sum((model.predict(q_test) - truth) ** 2, axis=1)))
    clean_fit = KinematicModel(robot=vr.nominal, parametrization="complete").fit(q, clean - nominal)
    robust = KinematicModel(robot=vr.nominal, parametrization="complete", loss="cauchy", loss_scale=5.0).fit(
        q, shifted - nominal)
    plain = KinematicModel(robot=vr.nominal, parametrization="complete").fit(q, shifted - nominal)
    named = robust.identification_.robust["downweighted"]
    assert [d["row"] for d in named] == bad.tolist()
    np.testing.assert_allclose([d["residual_mm"] for d in named], np.linalg.norm(shifted[bad] - clean[bad], axis=1),
                               rtol=0.05)
    assert error(robust) < 1.1 * error(clean_fit) < 0.2 * error(plain)
    assert robust.identification_.robust["scale_mm"] == pytest.approx(5 * 0.01, rel=0.3)


def test_robust_model_file_keeps_the_loss_and_the_named_rows(ur10, tmp_path):
    vr, q, true, rng = ur10
    measured = true + rng.normal(0.0, 0.01, true.shape)
    measured[3] += 4.0
    model = KinematicModel(robot=vr.nominal, parametrization="complete", loss="huber").fit(q, measured - vr.nominal.positions(q))
    path = tmp_path / "m.json"
    save_model(model, path)
    back = load_model(path)[0]
    assert back.loss == "huber" and back.loss_scale == 3.0
    assert back.identification_.robust == model.identification_.robust
    assert [d["row"] for d in model.identification_.robust["downweighted"]] == [3]


def test_loss_weights_are_the_derivative_of_scipys_losses():
    z = np.array([0.1, 0.9, 1.5, 4.0])
    from scipy.optimize._lsq.least_squares import IMPLEMENTED_LOSSES
    for loss in ("huber", "soft_l1", "cauchy"):
        rho = np.empty((3, z.size))
        IMPLEMENTED_LOSSES[loss](z**2, rho, cost_only=False)
        np.testing.assert_allclose(loss_weights(z, loss), rho[1], rtol=1e-12)
