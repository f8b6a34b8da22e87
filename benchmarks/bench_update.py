"""`partcal update` on the IPA UR10 (issue 41): B's DH model updated with 20 poses of series D.

Data as configs/ur10_ipa.yaml reads them: B 1-1000 identify DH (the tracker frame and the T-Mac
registered on them); D, measured months later from another tracker position, is registered in its own
frame on the nominal model. Twenty poses of D update B's model (its covariance inflated K times as the
prior, the base frame identified afresh: partcal/study/update.py); every model is scored on the other
poses of D after a rigid fit (as the run scores D), beside B's model alone and a fresh DH fit on the 20
poses. Twenty poses drawn at random (5 draws, seeds 0-4: the median), and D's first 20 rows (a compact
patch, joint 6 still). 3-D RMS, mm. Run: .venv/bin/python benchmarks/bench_update.py   (about 10 seconds)
"""

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal.metrics import pooled_rms  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.study.config import load_config  # noqa: E402
from partcal.study.prepare import load_datasets  # noqa: E402
from partcal.study.scoring import errors_left  # noqa: E402
from partcal.study.update import update_model  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "ur10_ipa.yaml"
INFLATE = (1.0, 10.0, 30.0, 100.0, 1000.0)      # the default: 30
N_NEW, DRAWS = 20, 5


def datasets():
    shared = ROOT.parent / "shared" if (ROOT.parent / "shared").is_dir() else ROOT.parents[1] / "shared"
    text = CONFIG.read_text().replace("../../shared", str(shared))
    text = text[:text.index("models:")] + "models:\n  - {name: DH, kind: kinematic}\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / CONFIG.name
        path.write_text(text)
        data, robot, _ = load_datasets(load_config(path))
    return data, robot


def scored(model, d, rest) -> float:
    """3-D RMS the model leaves on the rows ``rest`` of D after a rigid fit (as a run scores a set in its own frame)."""
    part = d.take(rest)
    return pooled_rms(errors_left(part, model.predict(part.q_deg) if model is not None else
                                  np.zeros((len(part), 3)), own_frame=True)[0])


def one_split(b_model, robot, d, new):
    rest = np.setdiff1d(np.arange(len(d)), new)
    part = d.take(new)
    row = {"uncompensated": scored(None, d, rest), "B alone": scored(b_model, d, rest),
           "fresh fit": scored(KinematicModel(robot=robot).fit(part.q_deg, part.errors_mm), d, rest)}
    for k in INFLATE:
        done = update_model(b_model, part, k)
        row[f"update x{k:g}"] = scored(done.model, d, rest)
        row["kept"], row["determined"] = done.kept_prior, done.shares.sum()     # the same for every K
    return row


def main() -> None:
    data, robot = datasets()
    b = data["identification"]
    d = data["iso_cubes"]
    b_model = KinematicModel(robot=robot).fit(b.q_deg, b.errors_mm)
    splits = [(f"random draw {seed}", np.sort(np.random.default_rng(seed).choice(len(d), N_NEW, replace=False)))
              for seed in range(DRAWS)] + [("first 20 rows", np.arange(N_NEW))]
    results = [(label, one_split(b_model, robot, d, new)) for label, new in splits]
    keys = ["uncompensated", "B alone", "fresh fit", *(f"update x{k:g}" for k in INFLATE)]
    rows = [[label, *(f"{r[k]:.3f}" for k in keys), f"{r['determined']:.1f}", "prior kept" if r["kept"] else ""]
            for label, r in results]
    rows.append(["median of the random draws", *(f"{np.median([r[k] for _, r in results[:DRAWS]]):.3f}"
                                                  for k in keys), "", ""])
    print_table(f"IPA UR10: B's DH model updated with {N_NEW} poses of D, scored on the rest of D after a rigid "
                "fit, 3-D RMS (mm)", ["poses", *keys, "directions determined", ""], rows)


if __name__ == "__main__":
    main()
