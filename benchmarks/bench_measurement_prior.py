"""What the datasheet-like prior (``prior: plausible``) buys a calibration from few touches or nest visits.

The virtual UR10 of configs/ur10_tilts_virtual.yaml and its measurements as benchmarks/bench_measures.py makes
them (the true robot's tip on a 200 mm step block, 0.01 mm along the normal; nests of 0.01 mm per axis, two
of them 1 m apart on a bar of known length). Each data set is identified with the complete parametrization
(base and tool identified) by ``KinematicModel(parametrization="complete").fit(..., measures=...)``, without a
prior, with ``prior: plausible`` at fixed strengths, and with the strength chosen by the model's own 5 random
folds of the rows (the one-standard-error rule, :mod:`partcal.calibration.cv`) among ``CHOICE``. Every model is
scored by the 3-D RMS of its tool positions against the truth on 2,000 random poses of the study's ranges
after a rigid fit (touches and nests fix no frame), the median of DRAWS draws of poses and noise.

The rows "planes all unknown" are the case where nothing measures a length (the three planes all unknown):
without a prior the rank rule holds one length nominal (bench_measures.py: 0.54 mm on 800 touches); with the
prior every length is held about its nominal value with its plausible error, against the pull of the noise (a
residual is a length: a smaller robot leaves smaller ones). ``fit`` refuses a list of strengths there; the CV
column shows what the model's choice (``strength_table`` on its 5 folds) would have taken.

Run (from the repository root): ``PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_measurement_prior.py``
(about 6 minutes on a shared 2-core machine; BLAS kept to one thread).
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402
from bench_measures import BAR, TIED, Bench, logging_off, rows_of  # noqa: E402

from partcal.errors import PartcalError  # noqa: E402
from partcal.models.base import seed_from  # noqa: E402
from partcal.calibration.cv import fold_rows, FOLDS, strength_table
from partcal.models.kinematic import KinematicModel  # noqa: E402

DRAWS = 5
FIXED = (0.01, 0.03, 0.1, 1.0)
CHOICE = [0.003, 0.01, 0.03, 0.1, 0.3, 1.0]
AUTO_ROWS = 80          # ``auto`` (the 11 strengths of STRENGTH_GRID) is scored on the small sets only (time)
LOOSE = {"planes": {"top": {}, "step": {}, "side": {}}}


def scored(b: Bench, rows, cell, seed: int) -> list[tuple[float, float | None]]:
    """(3-D RMS after a rigid fit against the truth, the strength) of: no prior, each of FIXED, the CV choice among
    CHOICE, and (on at most AUTO_ROWS rows) ``auto``."""
    out = []
    for strength in (None, *FIXED, CHOICE, *(["auto"] if len(rows) <= AUTO_ROWS else [])):
        params = {} if strength is None else {"prior": "plausible", "prior_strength": strength}
        model = KinematicModel(robot=b.nominal, parametrization="complete", random_state=seed, **params)
        try:
            model.fit(rows.q_deg, None, rows=rows, cell=cell)
        except PartcalError:            # refused where nothing measures a length: what the choice would have been
            model.set_params(prior_strength=unguarded_choice(b, model, rows, cell, seed))
            model.fit(rows.q_deg, None, rows=rows, cell=cell)
        predicted = b.nominal.positions(b.q_test) + model.predict(b.q_test)
        out.append((b.score(predicted, rigid=True), getattr(model, "prior_strength_", None)))
    return out


def unguarded_choice(b: Bench, model: KinematicModel, rows, cell, seed: int) -> float:
    """The strength the model's own choice (5 random folds, one-standard-error rule) would take on rows that leave
    the scale free, which ``fit`` refuses (``SCALE_CHOICE``): to show why."""
    def identified_at(strength, train):
        part = KinematicModel(robot=b.nominal, parametrization="complete", prior="plausible",
                              prior_strength=float(strength))
        return part.fit(train.q_deg, None, rows=train, cell=cell).identification_

    folds = fold_rows(rows, seed_from(seed), FOLDS)
    best, _ = strength_table(identified_at, CHOICE, b.nominal, rows, cell, folds, parametrization="complete")
    return CHOICE[best]


def one_draw(b: Bench, seed: int) -> dict:
    b.rng = np.random.default_rng([39, 41, seed])
    out = {}
    for n in (40, 80, 160):
        q, names = b.touches(n)
        rows = rows_of(q, ["plane"] * n, texts={"feature": tuple(names)})
        out[f"step block, {n} touches"] = scored(b, rows, TIED, seed)
        if n == 160:
            out[f"planes all unknown, {n} touches"] = scored(b, rows, LOOSE, seed)
    for per in (5, 10):
        q, names = b.visits(per)
        rows = rows_of(q, ["fixed"] * len(q), texts={"feature": tuple(names)})
        out[f"4 nests, 1 m bar, {4 * per} visits"] = scored(b, rows, BAR, seed)
    q, names = b.touches(800)
    rows = rows_of(q, ["plane"] * 800, texts={"feature": tuple(names)})
    out["planes all unknown, 800 touches"] = scored(b, rows, LOOSE, seed)
    return out


def main() -> None:
    wall = time.perf_counter()
    logging_off()
    b = Bench()
    draws = [one_draw(b, k) for k in range(DRAWS)]
    rows = []
    choice = 1 + len(FIXED)
    for label in draws[0]:
        figures = np.array([[f for f, _ in d[label]] for d in draws])          # (draws, cases)
        med = np.median(figures, axis=0)
        chosen = [d[label][choice][1] for d in draws]
        wins = int(np.sum(figures[:, choice] < figures[:, 0]))
        auto = (f"{med[-1]:.4f} ({', '.join(f'{d[label][-1][1]:g}' for d in draws)})"
                if figures.shape[1] > choice + 1 else "")
        rows.append([label, *(f"{v:.4f}" for v in med[:choice + 1]), ", ".join(f"{s:g}" for s in chosen),
                     f"{wins}/{DRAWS}", auto])
    print_table(f"Virtual UR10 (tilted parallel axes), complete model: 3-D RMS against the truth on 2,000 poses after "
                f"a rigid fit, mm (median of {DRAWS} draws)",
                ["data", "no prior", *(f"plausible {s:g}" for s in FIXED), "CV choice", "strengths chosen",
                 "CV beats none", "auto (chosen)"], rows)
    print(f"CV choice: the strongest of {CHOICE} within one standard error of the lowest weighted RMS on 5 random "
          "folds of the rows (KinematicModel's own choice; a run chooses on its own folds the same way); auto: the "
          f"same among STRENGTH_GRID (0.1 to 31.6), on sets of at most {AUTO_ROWS} rows. A strength s prices one "
          "plausible error (1 mm, 0.1 deg) as a weighted residual of s mm: the touches' and visits' weighted "
          "residuals read 0.02 mm (0.01 mm of noise times 0.02 / 0.01), so s = 0.02 is a prior of one plausible "
          "error.")
    print(f"total wall time {time.perf_counter() - wall:.0f} s")


if __name__ == "__main__":
    main()
