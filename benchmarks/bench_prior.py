"""Datasheet-like priors on the IPA UR10 (issue 41): geometry only and with compliance, beside the peers.

B 1-1000 identify DH, the complete parametrization, and both with the gravity compliance of joints 2 and 3
(data as configs/ur10_ipa.yaml reads them), without a prior, with `prior: plausible` at fixed strengths,
and with the strength chosen from `prior_strength: auto` (0.1 to 31.6, four to a decade) by the strongest
within one standard error of the lowest CV RMS: on 5 contiguous blocks inside the fit (the Python API's
choice) and on the run's folds (5 shuffled folds of poses, a pose's repeats together: what `partcal run`
chooses, configs/ur10_ipa_prior.yaml); scored on held-out B 1001-1495, C (B's frame) and D (its own frame,
after a rigid fit), as the run scores them. 3-D RMS, mm. Choosing the strength by the test series would be
choosing on the answer: only the CV rows are calibrations one could ship.
Run: .venv/bin/python benchmarks/bench_prior.py   (about five minutes)
"""

import logging
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402
from sklearn.base import clone  # noqa: E402
from bench_update import datasets  # noqa: E402

from partcal.metrics import pooled_rms  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.calibration.prior import strengths_of
from partcal.study.scoring import errors_left  # noqa: E402
from partcal.study.selection import CVPlan, choose_strength, grouped_splits, measured_poses  # noqa: E402

STRENGTHS = (0.3, 1.0, 3.0, 10.0)
PEERS = ("peers, geometric calibration: pybotics 0.550 / 0.923 / 0.713 (issue 30; 0.995 on C in issue 41's "
         "measurement); FIGAROH 0.573 (B) / 1.084-1.323 (C) / 0.614-0.776 (D); with elastic gains FIGAROH 0.495 on B")
MODELS = (("DH", {}), ("complete", {"parametrization": "complete"}), ("DH + compliance", {"compliance": [2, 3]}),
          ("complete + compliance", {"parametrization": "complete", "compliance": [2, 3]}))


def run_choice(model, b):
    """The model fitted with the strength a run chooses on its folds (the run's own functions), and that strength."""
    groups = measured_poses(b)
    cv = CVPlan(groups, 5, grouped_splits(groups, 5, 0), 0, "joint angles")
    strengths = strengths_of("auto")
    candidates = [clone(model).set_params(prior_strength=s) for s in strengths]
    fitted, table, _ = choose_strength(candidates, strengths, b.q_deg, b.errors_mm, cv)
    return fitted, next(row["prior_strength"] for row in table if row["chosen"])


def main() -> None:
    logging.disable(logging.WARNING)
    data, robot = datasets()
    b, held, c, d = (data[k] for k in ("identification", "joint_configurations", "random_poses", "iso_cubes"))
    rows = []
    for name, kwargs in MODELS:
        fits = [("no prior", KinematicModel(robot=robot, **kwargs).fit(b.q_deg, b.errors_mm), "")]
        for s in STRENGTHS:
            m = KinematicModel(robot=robot, prior="plausible", prior_strength=s, **kwargs)
            fits.append((f"strength {s:g}", m.fit(b.q_deg, b.errors_mm), ""))
        m = KinematicModel(robot=robot, prior="plausible", prior_strength="auto", **kwargs).fit(b.q_deg, b.errors_mm)
        fits.append(("auto, 5-block CV in the fit", m, f"{m.prior_strength_:g}"))
        m, chosen = run_choice(KinematicModel(robot=robot, prior="plausible", **kwargs), b)
        fits.append(("auto, the run's CV", m, f"{chosen:g}"))
        for label, m, chosen in fits:
            rows.append([name, label, chosen, f"{pooled_rms(errors_left(held, m.predict(held.q_deg))[0]):.3f}",
                         f"{pooled_rms(errors_left(c, m.predict(c.q_deg))[0]):.3f}",
                         f"{pooled_rms(errors_left(d, m.predict(d.q_deg), own_frame=True)[0]):.3f}"])
    print_table("IPA UR10, identification B 1-1000, plausible prior: 3-D RMS (mm)",
                ["model", "prior", "chosen", "B 1001-1495", "C", "D (rigid fit)"], rows)
    print(PEERS)


if __name__ == "__main__":
    main()
