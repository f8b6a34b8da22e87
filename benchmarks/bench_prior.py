"""Datasheet-like priors on the IPA UR10 (issue 41): geometry only, beside the peers' geometric calibrations.

B 1-1000 identify DH and the complete parametrization (data as configs/ur10_ipa.yaml reads them), without a
prior, with `prior: plausible` at fixed strengths, and with the strength chosen inside the fit by 5-block CV
on B (`prior_strength: [0.1, 0.3, 1, 3, 10]`); scored on held-out B 1001-1495, C (B's frame) and D (its own
frame, after a rigid fit), as the run scores them. 3-D RMS, mm. Choosing the strength by the test series
would be choosing on the answer: only the CV row is a calibration one could ship.
Run: .venv/bin/python benchmarks/bench_prior.py   (a few minutes)
"""

import logging
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402
from bench_update import datasets  # noqa: E402

from partcal.metrics import pooled_rms  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.study.scoring import errors_left  # noqa: E402

STRENGTHS = (0.1, 0.3, 1.0, 3.0, 10.0)
PEERS = ("peers: pybotics 0.550 / 0.923 / 0.713; FIGAROH 0.573 (B) / 1.084-1.323 (C) / 0.614-0.776 (D)")


def main() -> None:
    logging.disable(logging.WARNING)
    data, robot = datasets()
    b, held, c, d = (data[k] for k in ("identification", "joint_configurations", "random_poses", "iso_cubes"))
    rows = []
    for par in ("dh", "complete"):
        for label, kwargs in [("no prior", {}), *((f"plausible, strength {s:g}", {"prior": "plausible",
                                                                                  "prior_strength": s})
                                                  for s in STRENGTHS),
                              ("plausible, strength by 5-block CV", {"prior": "plausible",
                                                                     "prior_strength": STRENGTHS})]:
            m = KinematicModel(robot=robot, parametrization=par, **kwargs).fit(b.q_deg, b.errors_mm)
            chosen = f"{m.prior_strength_:g}" if getattr(m, "prior_cv_", None) is not None else ""
            rows.append([par, label, chosen, f"{pooled_rms(errors_left(held, m.predict(held.q_deg))[0]):.3f}",
                         f"{pooled_rms(errors_left(c, m.predict(c.q_deg))[0]):.3f}",
                         f"{pooled_rms(errors_left(d, m.predict(d.q_deg), own_frame=True)[0]):.3f}",
                         f"{m.identification_.status.count('identified')}/{len(m.identification_.names)}"])
    print_table("IPA UR10, geometry only, identification B 1-1000: 3-D RMS (mm)",
                ["model", "prior", "chosen", "B 1001-1495", "C", "D (rigid fit)", "identified"], rows)
    print(PEERS)


if __name__ == "__main__":
    main()
