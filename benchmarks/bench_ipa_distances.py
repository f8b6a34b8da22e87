"""The IPA UR10 (real data) calibrated from distances alone, beside the same DH model from the points (issue 39).

A laser tracker without its frame still measures distances: between the measured points of two poses,
whatever the tracker's place. Here DH (parametrization "dh", the tool identified, the base held: distances
cannot see it) is identified from the distances between the measured T-Mac points of series B rows
1-1000 alone, with no registration and no tracker frame (``identify_measurements`` over ``pose`` rows and
one ``distance`` row per pair, the tool started at the nominal robot's zero), from

- every pair of the 1000 poses (499,500 distances),
- 20,000 random pairs,
- the 999 consecutive pairs (for the record),

less the one pair of B whose two readings are identical (rows 532 and 533: the same flange position in
two elbow configurations, read once and repeated: a stale tracker reading; a distance of 0 is refused),

and beside it the same DH model identified from the points as partcal does it (``register_tracker`` on
B 1-1000, then ``KinematicModel(parametrization="dh")`` on the registered points). Every model is scored
on B 1-1000, B 1001-1495, C and D by the 3-D RMS of its positions against the measured points after a
rigid fit (``kabsch`` of the model's positions to the measured ones, per set). Target: the distances
within 10 % of the points on every test set. Each identification runs in a child process of its own:
its CPU time and its peak resident memory (``resource.getrusage``; the process starts at the parent's
size, printed as "baseline").

Data: Landgraf et al., CASE 2021, MIT licence, read from ../shared/datasets/ipa_ur10 (PROVENANCE.md).
Run (from the repository root): ``PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_ipa_distances.py``
(about 2 minutes of one core, peak about 2 GB for all pairs; BLAS kept to one thread).
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import logging  # noqa: E402
import multiprocessing  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from _ipa import FORMAT, SHARED, SPLIT as SETS  # noqa: E402

from partcal import load_robot  # noqa: E402
from partcal.data.formats import RowSelection  # noqa: E402
from partcal.data.measurements import read_measurements  # noqa: E402
from partcal.data.registration import register_tracker  # noqa: E402
from partcal.calibration.parameters import nominal_values, robot_with
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.calibration.measurement import MeasurementRows
from partcal.calibration.stacked import identify_measurements
from partcal.robot.frames import kabsch  # noqa: E402

TESTS = ("B 1001-1495", "C", "D")
SEED = 39
RANDOM_PAIRS = 20000
ROBOT = load_robot("universal_robots_ur10")


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.sum(a**2, axis=1))))


def read_sets() -> dict:
    out = {}
    for name, (path, rows) in SETS.items():
        m = read_measurements(SHARED / path, ROBOT, fmt=FORMAT, frame="tracker",
                              rows=RowSelection.parse(rows) if rows else None)
        out[name] = (m.q_deg, m.measured_mm)
    return out


def rigid_rms(predicted, measured) -> float:
    rot, t = kabsch(predicted, measured)
    return rms(predicted @ rot.T + t - measured)


def distance_rows(q, points, i, j) -> MeasurementRows:
    """``pose`` rows for the poses, then one ``distance`` row per pair ``(i, j)``: the first end's joints,
    ``to`` the second end's pose row, the distance between their measured points."""
    n, m = len(q), i.size
    measured = np.linalg.norm(points[i] - points[j], axis=1)
    return MeasurementRows(np.vstack([q, q[i]]), ("pose",) * n + ("distance",) * m, tuple(str(k + 1) for k in range(n + m)),
                tuple(range(2, n + m + 2)), "B 1-1000 distances",
                {"distance_mm": np.concatenate([np.full(n, np.nan), measured])},
                {"to": ("",) * n + tuple(str(k + 1) for k in j)})


def from_distances(q, points, pairs):
    """DH from the distances of ``pairs``: a function of the test joints giving the model's positions. A pair
    whose two readings are the same to the last digit is left out (no instrument reads a distance of 0)."""
    i, j = pairs
    live = np.linalg.norm(points[i] - points[j], axis=1) > 0
    i, j = i[live], j[live]
    table, notes = identify_measurements(ROBOT, distance_rows(q, points, i, j), {}, parametrization="dh")
    own = nominal_values(ROBOT, None, "dh").size
    robot = robot_with(ROBOT, table.value[:own], "dh")
    info = (f"{i.size} distances, {table.status.count('identified')}/{own} identified, tool "
            f"{np.round(robot.tool_mm, 2).tolist()}, distance RMS {table.target_rms_mm['distance']:.4f}")
    return robot.positions, info


def from_points(q, points):
    """DH from the registered points, as partcal's study does (tracker frame and T-Mac offset registered)."""
    reg = register_tracker(ROBOT, q, points)
    nominal = ROBOT.replace(tool_mm=reg.tool_mm.copy())
    model = KinematicModel(robot=nominal, parametrization="dh").fit(q, reg.to_base(points) - nominal.positions(q))
    table = model.identification_
    info = (f"{table.status.count('identified')}/{len(table.names)} identified, tool "
            f"{np.round(nominal.tool_mm, 2).tolist()} (registered), registration RMS {reg.rms_3d:.3f}")
    return (lambda qq: nominal.positions(qq) + model.predict(qq)), info


def child(conn, job, data):
    """One identification in a process of its own: its scores, CPU time, baseline and peak memory."""
    logging.getLogger("partcal").setLevel(logging.ERROR)
    baseline = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    q, points = data["B 1-1000"]
    start = time.process_time()
    predict, info = job(q, points)
    cpu = time.process_time() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    scores = {name: rigid_rms(predict(qq), pp) for name, (qq, pp) in data.items()}
    conn.send((scores, cpu, baseline, peak, info))
    conn.close()


def run_apart(job, data):
    ctx = multiprocessing.get_context("fork")
    parent, end = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=child, args=(end, job, data))
    proc.start()
    end.close()
    out = parent.recv()
    proc.join()
    return out


def main() -> None:
    wall = time.perf_counter()
    data = read_sets()
    n = len(data["B 1-1000"][0])
    rng = np.random.default_rng(SEED)
    every = np.triu_indices(n, 1)
    chosen = np.sort(rng.choice(every[0].size, RANDOM_PAIRS, replace=False))
    jobs = {
        "points (registered)": from_points,
        f"distances, consecutive pairs ({n - 1})": lambda q, p: from_distances(q, p, (np.arange(n - 1),
                                                                                      np.arange(1, n))),
        f"distances, random pairs ({RANDOM_PAIRS})": lambda q, p: from_distances(
            q, p, (every[0][chosen], every[1][chosen])),
        f"distances, all pairs ({every[0].size})": lambda q, p: from_distances(q, p, every),
    }
    results = {label: run_apart(job, data) for label, job in jobs.items()}
    reference = results["points (registered)"][0]
    rows, infos = [], []
    for label, (scores, cpu, baseline, peak, info) in results.items():
        ratios = [scores[s] / reference[s] for s in TESTS]
        verdict = "" if label.startswith("points") or "consecutive" in label else (
            "met" if max(abs(r - 1) for r in ratios) <= 0.10 else "MISSED")
        rows.append([label, *(f"{scores[s]:.3f}" for s in SETS), " / ".join(f"{r:.3f}" for r in ratios), verdict,
                     f"{cpu:.1f}", f"{baseline:.0f}", f"{peak:.0f}"])
        infos.append(f"  {label}: {info}")
    print_table("IPA UR10, DH identified on series B 1-1000: 3-D RMS after a rigid fit per set, mm",
                ["identified from", *SETS, "ratio to points (tests)", "within 10 %", "CPU s", "baseline MB",
                 "peak MB"], rows)
    print("\n".join(infos))
    print("independent study: distances 0.447-0.450 / 0.566-0.572 / 0.595-0.624 against points 0.442 / 0.570 / "
          "0.592 (B 1001-1495 / C / D); consecutive pairs alone: D 1.42")
    print(f"total wall time {time.perf_counter() - wall:.0f} s")


if __name__ == "__main__":
    main()
