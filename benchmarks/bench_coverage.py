"""How far to trust a prediction: coverage of the 95% intervals ``mean +- 1.96 std`` of every model kind (issue 33).

Each model is fitted on an identification set and predicts, with its standard
deviation (``predict_with_std``), the errors of test sets. The coverage is the
share of the test coordinates (x, y, z of every pose) whose measured error
lies within ``1.96 std`` of the prediction; the width is the mean ``std``
(mm). A calibrated spread covers about 95% on data like the training data and
should be wider where the model extrapolates. The last column is seconds: the
fit for the ``own`` row, the calibration's added fits for the others.

- the IPA UR10 (``configs/ur10_ipa.yaml``: registered as the run registers
  it): fitted on series B 1-1000, tested on B 1001-1495 (like the training
  data), series C (the other shoulder configuration) and series D (ISO cubes,
  its own tracker frame: scored up to a rigid transform, as a run scores it);
- the virtual SK120 (``data/sk120``): fitted on the 85 identification poses,
  tested on the paper's three paths, on 1000 new poses drawn as the identification
  poses were (like the training data), and where its wrist (held at q4 = q5 = 0
  in the identification poses) turns: the ISO 9283 cube and 300 poses with
  q4, q5 across +-90, +-60 degrees, measured on the virtual robot (the
  unidentified wrist parameters must widen the kinematic spread there).

    .venv/bin/python benchmarks/bench_coverage.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

from partcal import read_measurements  # noqa: E402
from partcal.data.measurements import Measurements  # noqa: E402
from partcal.data.simulate import load_study, sample_configurations  # noqa: E402
from partcal.robot.iso_cube import largest_cube  # noqa: E402
from partcal.models.gp import GaussianProcessErrorModel  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.models.partition import KMeansPartition  # noqa: E402
from partcal.models.partitioned import PartitionedErrorModel  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402
from partcal.study.config import SpreadOptions  # noqa: E402
from partcal.study.selection import grouped_splits, measured_poses  # noqa: E402
from partcal.study.spread import CalibratedSpread, run_spread  # noqa: E402
from partcal.robot.description import load_robot  # noqa: E402
from partcal.study.config import load_config  # noqa: E402
from partcal.study.prepare import load_datasets  # noqa: E402
from partcal.study.scoring import errors_left  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
Z95 = 1.959963984540054
CALIBRATIONS = ("contiguous", "forward", "folds", "contiguous+depth", "forward+depth", "folds+depth")


def models(robot, quick: bool, only: list[str] | None = None) -> dict:
    """The models compared (unfitted), by name: one or more of every kind."""
    gp = GaussianProcessErrorModel(inputs="joint", restarts=0, random_state=0)
    out = {"FDP(CI)": ErrorModel(inputs="cartesian", degree=1, solver="lstsq"),
           "SDP(AI)": ErrorModel(inputs="joint", degree=2, solver="lstsq"),
           "FDP(AI) k-means 4": PartitionedErrorModel(partition=KMeansPartition(n_regions=4),
                                                      local=ErrorModel(inputs="joint", degree=1, solver="lstsq"),
                                                      random_state=0),
           "DH": KinematicModel(robot=robot),
           "DH + compliance": KinematicModel(robot=robot, compliance=(2, 3)),
           "GP(AI)": gp,
           "DH + GP(AI)": KinematicModel(robot=robot, residual=gp, random_state=0)}
    if quick:
        out.pop("GP(AI)")
    return {name: model for name, model in out.items() if not only or name in only}


def inputs_of(model, m):
    """What the model reads: positions (mm) for Cartesian series, joints (deg) for the rest."""
    return m.nominal_mm if getattr(model, "inputs", "joint") == "cartesian" else m.q_deg


def coverage(model, m, own_frame: bool) -> tuple[float, float]:
    """``(share within 1.96 std, mean std)`` on data set ``m``."""
    mean, std = model.predict_with_std(inputs_of(model, m))
    left, _ = errors_left(m, mean, own_frame)
    return float(np.mean(np.abs(left) <= Z95 * std)), float(std.mean())


def table(title: str, train, tests: dict, robot, quick: bool, only: list[str] | None = None,
          calibrations: tuple = CALIBRATIONS) -> None:
    """Coverage and width of every model on every test set: its own spread, then calibrated as a run calibrates
    it (:func:`partcal.study.spread.run_spread`): ``contiguous`` (5 blocks, each from the others), ``forward``
    (each later block from the earlier ones) and ``folds`` (the run's 5 cross-validation folds: shuffled poses,
    seed 0), each with a scale the same everywhere and (``+depth``) growing with the inputs' depth as the
    held-out residuals show (a run's default: ``forward+depth``)."""
    rows = []
    cv_folds = grouped_splits(measured_poses(train), 5, 0)
    for name, model in models(robot, quick, only).items():
        X = inputs_of(model, train)
        start = time.perf_counter()
        model.fit(X, train.errors_mm)
        for how in ("own", *calibrations):
            lap = time.perf_counter()
            calibrated = None if how == "own" else run_spread(
                SpreadOptions(calibration=how.split("+")[0], depth=how.endswith("+depth")), model, X, train.errors_mm,
                cv_folds=cv_folds)
            (calibrated or CalibratedSpread(None)).apply(model)
            cells = [name if how == "own" else "", how]
            for m, own in tests.values():
                share, width = coverage(model, m, own)
                cells += [f"{100 * share:.1f}%", f"{width:.3f}"]
            rows.append(cells + [f"{time.perf_counter() - (start if how == 'own' else lap):.1f}"])
    header = ["model", "spread"] + [h for t in tests for h in (f"{t} cover", "std mm")] + ["s"]
    print_table(title, header, rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="leave out the global GP (its fit takes longest)")
    parser.add_argument("--only", nargs="+", metavar="MODEL", help="only these models (their names in the table)")
    parser.add_argument("--calibrations", nargs="+", default=CALIBRATIONS, choices=CALIBRATIONS,
                        help="the calibrated rows (default: all)")
    parser.add_argument("--sk120-only", action="store_true", help="only the virtual SK120's table")
    args = parser.parse_args()
    if not args.sk120_only:
        data, robot, registrations = load_datasets(load_config(ROOT / "configs" / "ur10_ipa.yaml"))
        own = {name: reg is not registrations["identification"] for name, reg in registrations.items()}
        table("IPA UR10: fitted on series B 1-1000", data["identification"],
              {"B 1001-1495": (data["joint_configurations"], own["joint_configurations"]),
               "C": (data["random_poses"], own["random_poses"]), "D": (data["iso_cubes"], own["iso_cubes"])},
              robot, args.quick, args.only, tuple(args.calibrations))
    sk120 = ROOT / "data" / "sk120"
    tests = {p: (read_measurements(sk120 / f"test_{p}.csv"), False) for p in ("rectangle", "spiral_xy", "spiral_yz")}
    tests["1000 like ident"] = (like_identification(1000), False)
    table("virtual SK120: fitted on the 85 identification poses", read_measurements(sk120 / "identification.csv"),
          tests, load_robot("motoman_sk120"), args.quick, args.only, tuple(args.calibrations))
    turned_wrist(args.quick, args.only, tuple(args.calibrations))


def turned_wrist(quick: bool, only: list[str] | None, calibrations: tuple) -> None:
    """The SK120 fitted on the paper's poses (wrist held at q4 = q5 = 0), tested where the wrist turns: the
    ISO 9283 cube (its P1..P5, 10 cycles) and 300 poses with q4, q5 across +-90, +-60 degrees, measured on
    the virtual robot (``configs/sk120_virtual.yaml``)."""
    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")
    virtual, rng = study.robot, np.random.default_rng(2006)
    cube = np.tile(largest_cube(virtual.nominal, random_state=rng).q_deg, (10, 1))
    turned = sample_configurations(virtual.nominal, 300, {**study.ranges_deg, 4: (-90, 90), 5: (-60, 60)}, {}, rng)
    tests = {name: (measured(virtual, q, rng), False) for name, q in (("ISO cube", cube), ("wrist turned", turned))}
    table("virtual SK120: fitted on the 85 identification poses (q4 = q5 = 0), the wrist turned",
          read_measurements(ROOT / "data" / "sk120" / "identification.csv"), tests, virtual.nominal, quick, only,
          calibrations)


def like_identification(n: int) -> Measurements:
    """``n`` new poses drawn as the identification poses were (the same ranges, q4 = q5 = 0) and measured on the
    same virtual robot: data like the training data, which the paper's paths, in the middle of the workspace
    where every model fits better than at the joint limits, are not."""
    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")
    rng = np.random.default_rng(2007)
    q = sample_configurations(study.robot.nominal, n, study.ranges_deg, study.fixed_deg, rng)
    return measured(study.robot, q, rng)


def measured(virtual, q, rng) -> Measurements:
    """What the virtual robot's tracker measures at joints ``q`` (deg), as a data set."""
    return Measurements(q, virtual.nominal.positions(q), virtual.measure(q, rng))


if __name__ == "__main__":
    main()
