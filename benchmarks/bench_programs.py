"""Compensated robot programs: 10,000-target programs in each language (issue 32).

Each row: a program of 10,000 targets written in the vendor's syntax from random joints around a working
pose, a kinematic pose model (DH with base and tool, fitted on 48 noise-free poses of the virtual robot;
the SK120's with gravity compliance and gear harmonics), and the time to read the program, compensate
every target (the intended joints on the target's branch, the full-pose compensation, the configuration
check) and write it back: ``compensate_program`` and the program's bytes, best of 3, wall time. The
last column is the largest predicted residual.

Run: .venv/bin/python benchmarks/bench_programs.py   (about a minute)
"""

import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal.data.programs import read_program  # noqa: E402
from partcal.data.simulate import load_study  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.robot.rotations import kuka_abc_from_matrices, quaternions_from_matrices  # noqa: E402
from partcal.study.persist import model_to_dict  # noqa: E402
from partcal.study.predictor import Predictor  # noqa: E402
from partcal.study.programs import compensate_program  # noqa: E402

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
N = 10_000


def model_of(config, centre, spread, **kwargs):
    virtual = load_study(CONFIGS / config).robot
    nominal = virtual.nominal
    q = np.array(centre) + np.random.default_rng(1).uniform(-spread, spread, (400, 6))
    q = q[nominal.within_limits(q)][:48]
    N_ = nominal.forward(q)
    turn = Rotation.from_matrix(virtual.true_flange(q)[1] @ N_[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
    y = np.hstack([virtual.true_positions(q) - N_[:, :3, 3], 1000 * turn])
    model = KinematicModel(robot=nominal, use_orientation=True, **kwargs).fit(q, y)
    return Predictor(model, model_to_dict(model, name="DH pose", robot=nominal), nominal)


def joints(robot, centre, spread):
    q = np.array(centre) + np.random.default_rng(2).uniform(-spread, spread, (3 * N, 6))
    return q[robot.within_limits(q)][:N]


def urscript(robot, q):
    T = robot.forward(q)
    v = np.hstack([T[:, :3, 3] / 1000, Rotation.from_matrix(T[:, :3, :3]).as_rotvec()])
    body = "".join(f"  movel(p[{', '.join(f'{x:.6f}' for x in row)}], a=1.2, v=0.25)\n" for row in v)
    return f"def run():\n  set_tcp(p[0, 0, {robot.tool_mm[2] / 1000:.6f}, 0, 0, 0])\n{body}end\n"


def krl(robot, q):
    T = robot.flange(q)                      # the targets are the flange's: no tool
    abc = kuka_abc_from_matrices(T[:, :3, :3])
    turn = ((q < 0) * (1 << np.arange(6))).sum(axis=1)
    return "DEFDAT BENCH\r\n" + "".join(
        f"DECL E6POS XP{k}={{X {p[0]:.3f},Y {p[1]:.3f},Z {p[2]:.3f},A {a[0]:.4f},B {a[1]:.4f},C {a[2]:.4f},"
        f"S 2,T {t}}}\r\n" for k, (p, a, t) in enumerate(zip(T[:, :3, 3], abc, turn))) + "ENDDAT\r\n"


def rapid(robot, q):
    T = robot.flange(q)
    quat = quaternions_from_matrices(T[:, :3, :3])
    cf = np.floor(q[:, [0, 3, 5]] / 90).astype(int)
    return "MODULE Bench\r\n" + "".join(
        f"  CONST robtarget p{k}:=[[{p[0]:.2f},{p[1]:.2f},{p[2]:.2f}],[{w[0]:.6f},{w[1]:.6f},{w[2]:.6f},{w[3]:.6f}],"
        f"[{c[0]},{c[1]},{c[2]},0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n"
        for k, (p, w, c) in enumerate(zip(T[:, :3, 3], quat, cf))) + "ENDMODULE\r\n"


def trajectory(robot, q):
    return "t,q1,q2,q3,q4,q5,q6\n" + "".join(f"{k * 0.008:.3f}," + ",".join(f"{x:.4f}" for x in row) + "\n"
                                             for k, row in enumerate(q))


def main():
    ur = model_of("ur10_targets_virtual.yaml", [20, -70, 90, -100, -80, 10], 40)
    sk = model_of("sk120_virtual.yaml", [0, -120, -170, 0, 30, 0], 20, compliance=(2, 3),
                  joint_harmonics=[1, 2, 2, 0, 0, 1])
    sk_centre = [30, -120, -170, 40, 30, 40]       # every axis 15 degrees or more from a KUKA or ABB configuration's edge
    cases = [("URScript movel", "bench.script", urscript, ur, [20, -70, 90, -100, -80, 10], 30),
             ("KRL E6POS", "bench.dat", krl, sk, sk_centre, 15),
             ("RAPID robtarget", "bench.mod", rapid, sk, sk_centre, 15),
             ("joint trajectory CSV", "bench.csv", trajectory, ur, [20, -70, 90, -100, -80, 10], 30)]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, name, write, predictor, centre, spread in cases:
            path = Path(folder) / name
            path.write_bytes(write(predictor.robot, joints(predictor.robot, centre, spread)).encode("latin-1"))
            best, result = np.inf, None
            for _ in range(3):
                start = time.perf_counter()
                program = read_program(path)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result = compensate_program(predictor, program)
                assert result.output is not None, result.failures[:3]
                best = min(best, time.perf_counter() - start)
            done = len(program.targets) - len(result.failures)
            rows.append([label, len(program.targets), done, f"{best:.2f}", f"{len(program.targets) / best:,.0f}",
                         f"{np.nanmax(result.residual_mm):.1e}"])
    print_table(f"{N:,}-target programs: read, compensate, write (best of 3, wall time, 1 process)",
                ["program", "targets", "compensated", "seconds", "targets/s", "residual mm"], rows)


if __name__ == "__main__":
    main()
