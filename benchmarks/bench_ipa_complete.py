"""The IPA UR10 (real data) with the complete parametrization beside DH, from the built-in YAML and from
example-robot-data's URDF (issue 30).

The run of configs/ur10_ipa_complete.yaml (identification: series B 1-1000; tests: B 1001-1495, C, D
with its own registration, as configs/ur10_ipa.yaml), repeated with the robot taken from
example-robot-data's ur10_robot.urdf (base_link to tool0; the older UR10 figures, d1 = 127.3 mm), and
with the gravity compliance of joints 2 and 3 (not geometry: what an exported file cannot carry) and
with variants of the complete model that prune harder (rcond). 3-D RMS, mm,
as the run's metrics.json. Run: .venv/bin/python benchmarks/bench_ipa_complete.py   (about a minute)
"""

import os
import sys
import tempfile
from importlib.metadata import distribution
from pathlib import Path

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal.study.config import load_config  # noqa: E402
from partcal.study.runner import run  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "ur10_ipa_complete.yaml"
SETS = ("identification", "joint_configurations", "random_poses", "iso_cubes")
VARIANTS = """  - {name: DH + compliance, kind: kinematic, parametrization: dh, compliance: [2, 3]}
  - {name: complete + compliance, kind: kinematic, parametrization: complete, compliance: [2, 3]}
  - {name: complete rcond 1e-4, kind: kinematic, parametrization: complete, rcond: 1.0e-4}
  - {name: complete rcond 1e-3, kind: kinematic, parametrization: complete, rcond: 1.0e-3}
  - {name: complete rcond 1e-2, kind: kinematic, parametrization: complete, rcond: 1.0e-2}
"""


def urdf_path() -> Path:
    return Path(distribution("example-robot-data").locate_file(
        "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur10_robot.urdf"))


def runs():
    text = CONFIG.read_text() + VARIANTS
    urdf = f"robot: {{urdf: {urdf_path()}, base: base_link, tip: tool0}}"
    for label, body in (("built-in YAML", text), ("example-robot-data URDF", text.replace(
            "robot: universal_robots_ur10", urdf))):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / CONFIG.name
            path.write_text(body.replace("../../shared", str(ROOT.parents[1] / "shared")
                                         if (ROOT.parents[1] / "shared").is_dir() else str(ROOT.parent / "shared")))
            yield label, run(load_config(path))


def main() -> None:
    rows = []
    for label, result in runs():
        for m in result.models:
            table = m.model.identification_
            rows.append([label, m.spec.name, *(f"{m.metrics[s]['rms_3d']:.3f}" for s in SETS), f"{m.cv_rms_3d:.3f}",
                         f"{table.status.count('identified')}/{len(table.names)}", f"{table.condition:.3g}"])
    print_table("IPA UR10, identification B 1-1000: 3-D RMS (mm)",
                ["robot", "model", "B 1-1000", "B 1001-1495", "C", "D", "CV", "identified", "condition"], rows)
    print("peers (issue 30, geometric calibration): pybotics B 0.550, C 0.923, D 0.713; FIGAROH C 1.084-1.323, "
          "D 0.614-0.776; robotkinecal C 1.328")


if __name__ == "__main__":
    main()
