"""The run's scoring: the compensation check on a virtual robot names the model, the data set and each reason."""

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT

from partcal.data.measurements import Measurements
from partcal.data.simulate import load_study
from partcal.models.series import ErrorModel
from partcal.robot.compensation import CompensationWarning
from partcal.study.results import ModelResult
from partcal.study.scoring import verify_compensation


def test_verify_compensation_warns_naming_the_model_the_data_set_and_each_reason():
    """The virtual SK120 and a Cartesian model of its errors; the test set's first target lies 5 m out, beyond the
    arm's reach. Its false target converges (the model alone would hit it, a miss far inside the tolerance), but
    the arm cannot take it: the warning names the model and the data set and says 'out of reach' for it."""
    virtual = load_study(ROOT / "configs" / "sk120_virtual.yaml").robot
    robot = virtual.nominal
    rng = np.random.default_rng(0)
    q = robot.home_deg + rng.uniform(-20, 20, (60, robot.n_joints))
    q = q[robot.within_limits(q)][:40]
    nominal = robot.positions(q)
    measured = virtual.measure(q, rng)
    model = ErrorModel(degree=1, solver="lstsq").fit(nominal, measured - nominal)
    far = nominal.copy()
    far[0] = [5000.0, 0.0, 500.0]
    test = Measurements(q, far, measured - nominal + far)
    result = ModelResult(spec=SimpleNamespace(name="FDP(CI)", inputs="cartesian"), model=model, fit_seconds=0.0,
                         cv_rms_3d=0.0, metrics={}, predictions={"test": model.predict(far)})
    with pytest.warns(CompensationWarning, match=r"^verifying compensation: model 'FDP\(CI\)' on data set 'test': 1 "
                                                 r"of 40 targets did not converge to 0.0001 mm: #0 \(\S+ mm: out of "
                                                 r"reach\)$"):
        out, attained = verify_compensation(result, {"test": test}, robot, virtual, seed=0)
    assert out["test"]["converged"] == 39 and out["test"]["n"] == 40
    reached, sent, turned = attained["test"]
    assert reached.shape == (40, 3) and sent.tolist() == [False] + [True] * 39 and turned is None
