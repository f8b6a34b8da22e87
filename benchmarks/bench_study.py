"""How long a real Gaussian-process study takes (issue 19): wall and CPU time of whole runs.

Two runs of ``partcal run``, each a fresh process, as a user runs them:
- the four-model study of issue 19 on the IPA UR10 (../shared/datasets/ipa_ur10): DH, DH + SDP(AI),
  GP(AI), and DH + GP(AI) k-means [2, 4] (nested CV), identified on the first 700 poses of series
  B, tested on the rest of B and on series C; n_jobs: 2;
- configs/ur10_ipa.yaml as shipped (12 models on 1,000 poses, n_jobs: 2).
Targets: at most 60 s wall each on the quiet 2-core machine (before: 3 min 50 s and 147 s). Wall
time on a shared machine swings by 2x and more; the CPU time of the run (its workers included)
is printed beside it. Per model of the study: test 3-D RMS on the rest of B and on C, and the CV
score with its standard error.

Run: .venv/bin/python benchmarks/bench_study.py
"""

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
SERIES_B = "../../shared/datasets/ipa_ur10/Series_B/measurements_joint_configurations.csv"


def study_config(folder: Path) -> Path:
    """The four-model study, written beside a copy of configs/ur10_ipa.yaml's data section."""
    shipped = yaml.safe_load((ROOT / "configs" / "ur10_ipa.yaml").read_text())
    data = shipped["data"]
    base = ROOT / "configs"
    b = str((base / SERIES_B).resolve())
    data["identification"] = {"file": b, "rows": "1-700"}
    data["tests"] = {"rest_of_b": {"file": b, "rows": "701-1495"},
                     "random_poses": str((base / data["tests"]["random_poses"]).resolve())}
    doc = {"name": "study4", "robot": shipped["robot"], "seed": 0, "n_jobs": 2, "cv_folds": 5, "data": data,
           "output": str(folder / "out"),
           "models": [{"name": "DH", "kind": "kinematic"},
                      {"name": "DH + SDP(AI)", "kind": "kinematic",
                       "residual": {"inputs": "joint", "degree": 2, "solver": {"method": "lstsq"}}},
                      {"name": "GP(AI)", "kind": "gaussian_process", "inputs": "joint"},
                      {"name": "DH + GP(AI) k-means", "kind": "kinematic",
                       "residual": {"kind": "gaussian_process", "inputs": "joint",
                                    "partition": {"method": "kmeans", "n_regions": [2, 4]}}}]}
    path = folder / "study4.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def timed_run(config: Path, output: Path) -> tuple[float, float, dict]:
    """Wall and CPU seconds of ``partcal run -q CONFIG`` (its children included), and its metrics.json."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "partcal", "run", "-q", str(config)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads((output / "metrics.json").read_text())


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        wall, cpu, doc = timed_run(study_config(tmp), tmp / "out")
        rows = [[name, f"{m['rest_of_b']['rms_3d']:.3f}", f"{m['random_poses']['rms_3d']:.3f}",
                 f"{m['cv']['rms_3d']:.3f} +- {m['cv']['standard_error']:.3f}", f"{m['fit_seconds']:.1f}",
                 f"{m['cv_seconds']:.1f}"] for name, m in doc["models"].items()]
        print_table(f"Four-model study, 700 UR10 poses: {wall:.0f} s wall, {cpu:.0f} s CPU (target <= 60 s wall; "
                    f"best: {doc['best']})",
                    ["model", "rest of B (mm)", "C (mm)", "CV (mm)", "fit s", "CV s"], rows)
        shipped = yaml.safe_load((ROOT / "configs" / "ur10_ipa.yaml").read_text())
        shipped["output"] = str(tmp / "ur10")
        for entry in shipped["data"]["tests"].values():
            if isinstance(entry, dict):
                entry["file"] = str((ROOT / "configs" / entry["file"]).resolve())
        for key in ("identification",):
            shipped["data"][key]["file"] = str((ROOT / "configs" / shipped["data"][key]["file"]).resolve())
        tests = shipped["data"]["tests"]
        for name, entry in tests.items():
            if isinstance(entry, str):
                tests[name] = str((ROOT / "configs" / entry).resolve())
        path = tmp / "ur10_ipa.yaml"
        path.write_text(yaml.safe_dump(shipped, sort_keys=False))
        wall, cpu, doc = timed_run(path, tmp / "ur10")
        rows = [[name] + [f"{m[s]['rms_3d']:.3f}" for s in ("identification", "joint_configurations",
                                                            "random_poses", "iso_cubes")]
                + [f"{m['cv']['rms_3d']:.3f}"] for name, m in doc["models"].items()]
        print_table(f"configs/ur10_ipa.yaml: {wall:.0f} s wall, {cpu:.0f} s CPU (target <= 60 s wall; best: "
                    f"{doc['best']})", ["model", "ident (mm)", "B rest", "C", "D", "CV"], rows)


if __name__ == "__main__":
    main()
