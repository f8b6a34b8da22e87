"""A large kinematic run: DH + compliance on 100,000 virtual SK120 poses, fit and cross-validation times.

The data: ``partcal simulate`` of the virtual SK120 (configs/sk120_virtual.yaml's errors: DH, base,
tool, compliance of joints 2 and 3, gear harmonics, tracker) with all six joints moving (the wrist in
+-30 degrees), one identification set of ``--poses`` poses (Sobol sampling above 2,000). The run:
one model, ``{kind: kinematic, compliance: [2, 3]}``, 5-fold CV, ``n_jobs`` 1 and 2, each a fresh
``partcal run -q`` process as a user runs it. The table gives, per code tree and ``n_jobs``: the final
fit's seconds and the cross-validation's (metrics.json's ``fit_seconds``, ``cv_seconds``), the run's
wall and CPU seconds (its workers included), its peak memory and the CV score (which must not
change with ``n_jobs``, nor between the code trees).

``--before DIR`` times another partcal source tree in the same session (the ratio is what counts on
a shared machine: wall time swings by 2x and more), e.g. the commit before a change:
``git archive COMMIT partcal | tar -x -C /tmp/before``.

Measured on the shared 2-core machine (2026-11-25, load 4 to 9 from other jobs), 100,000 poses, before
(commit 4aa4c2c) and after the scale changes of issue 31: n_jobs 1: fit 51.8 -> 19.1 s, CV 329 -> 105 s,
wall 400 -> 136 s, CPU 193 -> 101 s; n_jobs 2: fit 60.8 -> 41.6 s (beside the folds), CV 188 -> 62 s,
wall 286 -> 117 s; the CV score the same for n_jobs 1 and 2. The table, and what it shows and does
not: docs/models.md, "Scale".

Run: .venv/bin/python benchmarks/bench_scale.py [--poses 100000] [--before DIR] [--jobs 1,2]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def simulate(folder: Path, poses: int) -> Path:
    """Write the virtual SK120's identification set of ``poses`` poses into ``folder``; return its CSV."""
    doc = yaml.safe_load((ROOT / "configs" / "sk120_virtual.yaml").read_text())
    doc["output"] = str(folder / "data")
    doc["datasets"] = {"identification": {"sample": poses}}
    doc["sampling"]["ranges_deg"].update({"q4": [-30, 30], "q5": [-30, 30]})
    doc["sampling"].pop("fixed_deg", None)
    config = folder / "simulate.yaml"
    config.write_text(yaml.safe_dump(doc, sort_keys=False))
    subprocess.run([sys.executable, "-m", "partcal", "simulate", str(config)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)
    return folder / "data" / "identification.csv"


def run_config(folder: Path, data: Path, n_jobs: int, tag: str) -> Path:
    doc = {"name": f"scale_{tag}_{n_jobs}", "robot": "motoman_sk120", "seed": 0, "n_jobs": n_jobs,
           "data": {"identification": str(data)},
           "models": [{"name": "DH + compliance", "kind": "kinematic", "compliance": [2, 3]}],
           "output": str(folder / f"out_{tag}_{n_jobs}")}
    path = folder / f"run_{tag}_{n_jobs}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def timed_run(config: Path, code: Path) -> dict:
    """Fit and CV seconds, wall and CPU seconds, peak memory (MB) and CV score of ``partcal run -q CONFIG``."""
    env = dict(os.environ, PYTHONPATH=str(code))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "partcal", "run", "-q", str(config)], check=True, cwd=code, env=env,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = yaml.safe_load(config.read_text())["output"]
    doc = json.loads((Path(out) / "metrics.json").read_text())
    model = doc["models"]["DH + compliance"]
    return {"fit": model["fit_seconds"], "cv": model["cv_seconds"], "wall": wall,
            "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "peak_mb": after.ru_maxrss / 1024.0, "score": model["cv"]["rms_3d"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100_000)
    parser.add_argument("--before", type=Path, help="another partcal source tree to time (the code before a change)")
    parser.add_argument("--jobs", default="1,2", help="n_jobs values (default 1,2)")
    parser.add_argument("--data", type=Path, help="an identification CSV to use instead of simulating one")
    args = parser.parse_args()
    trees = ([("before", args.before.resolve())] if args.before else []) + [("this tree", ROOT)]
    jobs = [int(j) for j in args.jobs.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = args.data.resolve() if args.data else simulate(tmp, args.poses)
        rows = []
        for tag, code in trees:
            for n_jobs in jobs:
                r = timed_run(run_config(tmp, data, n_jobs, tag.replace(" ", "_")), code)
                rows.append([tag, n_jobs, f"{r['fit']:.1f}", f"{r['cv']:.1f}", f"{r['wall']:.0f}", f"{r['cpu']:.0f}",
                             f"{r['peak_mb']:.0f}", f"{r['score']:.6f}"])
                print(" ".join(str(c) for c in rows[-1]), flush=True)
    print_table(f"DH + compliance on {args.poses:,} virtual SK120 poses, 5-fold CV (seconds; peak MB is the "
                "largest process so far)",
                ["code", "n_jobs", "fit s", "CV s", "wall s", "CPU s", "peak MB", "CV 3-D RMS (mm)"], rows)


if __name__ == "__main__":
    main()
