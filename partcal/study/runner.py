"""A batch run from end to end: prepare, fit, verify, rank. Writing is :mod:`partcal.study.outputs`.

Every model is fitted on the identification set, evaluated on every data set
and by cross-validation on the identification set, and ranked by its
cross-validated 3-D RMS (``rank_by: cv``: the physical model with the fewest
parameters within one standard error of the lowest, else the lowest) or by
its 3-D RMS on a held-out validation set (``rank_by: validation``); never by
a test set. The stages, each in its module:

1. **prepare** (:mod:`~partcal.study.prepare`): the data read once, the robot
   registered once, the folds drawn, the feasible entries kept
   (``partcal run --check`` stops here);
2. **fit** (:mod:`~partcal.study.fitting`): every entry fitted, cross-validated
   on the shared folds (nested for lists of granularities or prior strengths) and scored;
3. **verify** (:func:`~partcal.study.scoring.verify_compensation`): with a
   virtual robot, the compensated test targets commanded on the simulated
   true robot;
4. **rank** (:func:`~partcal.study.selection.choose_best`), and the ISO 9283 pose figures of every test
   set, uncompensated and after each model (:func:`~partcal.study.iso_figures.run_figures`): predicted,
   and, with a virtual robot, measured on it after compensation.
"""

from __future__ import annotations

import logging
import time
from typing import Callable

import numpy as np

from .config import RunConfig
from .fitting import fit_all
from .iso_figures import run_figures
from .prepare import prepare
from .results import RunResult
from .scoring import Outputs, verify_compensation
from .selection import choose_best

log = logging.getLogger(__name__)


def run(config: RunConfig, progress: Callable[[int, int, str], None] | None = None) -> RunResult:
    """Fit and evaluate every model of ``config``; verify compensation when a virtual robot is given.

    ``progress(done, total, text)`` hears of each finished model (and, with
    ``done = 0``, of the plan); per-fold lines of slow models go to stderr
    unless ``progress`` is None.
    """
    start = time.perf_counter()
    prepared = prepare(config)
    if progress:
        progress(0, len(prepared.plan.models), f"cross-validation: {prepared.plan.cv.describe()}")
    outputs = Outputs.of(config)
    results = fit_all(prepared, outputs, progress)
    data, robot = prepared.datasets, prepared.robot
    attained = {}
    if prepared.virtual is not None:
        for result in results:
            result.compensation, attained[result.spec.name] = verify_compensation(result, data, robot,
                                                                                 prepared.virtual, config.seed)
    own = config.data_options.own_frame
    uncompensated = {name: outputs.evaluate(m, np.zeros_like(outputs.errors(m)), name in own)
                     for name, m in data.items()}
    iso = run_figures(data, {r.spec.name: r.predictions for r in results}, {name: name in own for name in data},
                      attained)
    result = RunResult(config, data, robot, uncompensated, results, choose_best(results, config.rank_by),
                       time.perf_counter() - start, registrations=prepared.registrations, plan=prepared.plan,
                       iso9283=iso)
    for caveat in result.best_caveats:
        log.warning("%s", caveat)
    return result
