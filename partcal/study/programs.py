"""Compensated robot programs: every target of a program rewritten so that the real robot lands on it.

A program's pose targets are the tool centre point (TCP) in a frame (UR feature, KUKA base, ABB work
object) with a tool (UR TCP, KUKA tool, ABB tooldata). Each is carried to the pose of the model's own
tool point in the robot base: ``W = F P T^-1 Tm`` (``F`` the frame, ``P`` the target, ``T`` the tool,
``Tm`` the model robot's tool offset); a joint target ``q`` is the pose the nominal robot has there,
``W = FK(q)``. Then, for all targets at once:

1. the intended joints ``q0``: the joints themselves, or the pose IK of ``W`` on the branch the target names
   (KUKA ``T``, ABB ``cf1 cf4 cf6``), from the joint target before it in the file (else the home pose),
   then from further seeds until the branch matches; a straight wrist's shared turn split nearest the seed
   (:mod:`partcal.robot.wrist`);
2. the compensation (:meth:`Predictor.compensate_poses`, seeded with ``q0``): the full pose for a pose
   model, the position with the orientation kept for a position model; a Cartesian model's command is
   then solved by the robot's IK from ``q0``, as the controller would;
3. the configuration kept: the compensated joints ``q1`` have the Jacobian's determinant of the sign of
   ``q0``'s (no shoulder, elbow or wrist flip; the UR's joint branch) and the configuration written with
   the target, if any (:mod:`partcal.study.program_configuration`);
4. the commanded pose carried back, ``P' = F^-1 C Tm^-1 T``, written in the vendor's units (joints: ``q1``)
   and in the style of the old numbers; a target whose correction is within the tolerance keeps its text.

A target that fails 1, 2 or 3 is not compensated: it is reported by file, line and name, and the
program is not written unless ``keep_unconverged`` (then it keeps its original numbers and a comment).
A target with an external axis off 0 (a track) is refused before. Each compensated target's distance
from the model's data is kept (``ProgramResult.far``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..data.program_text import Program, Target, UnknownFrameError
from ..errors import DataError
from ..robot.ik_refine import conditioning, refine_pose
from ..robot.kinematics import checked_poses, ik_settings, pose_errors
from ..robot.rotations import inverse_poses, poses_from
from ..robot.wrist import nearest_split, shared_turns
from .predictor import EXTRAPOLATION_LIMIT, Predictor
from .program_configuration import configuration_kept, configuration_of, configurations_text, written_ranges

EXACT_MM, EXACT_DEG = 1e-6, 1e-6
IK_TOL_MM, IK_TOL_DEG = 1e-4, 1e-5
"""How closely the joints of a target's pose must be solved: they are solved to :data:`EXACT_MM` and
:data:`EXACT_DEG` (so that a zero model writes every digit back), and where that stalls, what a controller's 32-bit
reals carry (about 1e-4 mm at a metre) is enough. At a singular wrist (axes 4 and 5 at 0, the paper's
rectangle) the solve stalls near 4e-5 mm and 3e-6 degrees: 1e-6 alone refused 6 of 10 such targets."""
SEED_TRIES = 40            # seeds for a pose target's intended joints: the one before it, then spread ones
SPLIT_TOL_DEG = 0.02
"""How far the intended joints of a target whose wrist is within 0.01 degrees of straight may turn its tool when
the turn its wrist axes share is split nearest the seed (:func:`~partcal.robot.wrist.nearest_split`): twice the
bend (its tool point moves by that turn times its distance from the wrist's axis). A program writes such a wrist straight only to its printed precision (KUKA's A B C to 1e-4 degrees), and
the intended joints only seed the compensation and name its configuration: the compensation solves the pose
itself."""


@dataclass(frozen=True)
class ProgramFrames:
    """Frames and tools given by the user: name -> pose (4, 4) mm; the name None is the default (targets
    that name none). Frames and tools the program defines itself are used where these name none."""

    frames: dict = field(default_factory=dict)
    tools: dict = field(default_factory=dict)

    def __post_init__(self):
        for what in ("frames", "tools"):
            clean = {}
            for name, pose in getattr(self, what).items():
                try:
                    clean[name] = checked_poses(np.asarray(pose, dtype=float)[None])[0]
                except (DataError, ValueError, TypeError) as exc:
                    raise DataError(f"ProgramFrames {what}[{name!r}]: expected a pose (4, 4) mm, a rotation and a "
                                    f"position; {exc}") from None
            object.__setattr__(self, what, clean)


@dataclass(frozen=True)
class ProgramResult:
    """A compensated program.

    Attributes
    ----------
    program : Program
    output : bytes or None
        The rewritten program; None when a target failed and ``keep_unconverged`` was not asked.
    failures : list of (Target, str)
        The targets not compensated and why.
    correction_mm, correction_deg : ndarray, shape (n,)
        How far each target moved (its TCP; a joint target's tool point), mm and degrees (0 where failed).
    residual_mm, residual_deg : ndarray, shape (n,)
        The model's predicted miss after compensation (NaN where failed).
    orientation : "model" or "kept"
    distance_to_data : ndarray, shape (n,)
        How far each compensated target's model input (its commanded tool point, mm, for a Cartesian model;
        its joints, degrees, for a joint model) lies from the data the model was fitted on (NaN where failed).
    input_unit : "mm" or "deg"
    """

    program: Program
    output: bytes | None
    failures: list
    correction_mm: NDArray[np.float64]
    correction_deg: NDArray[np.float64]
    residual_mm: NDArray[np.float64]
    residual_deg: NDArray[np.float64]
    orientation: str
    distance_to_data: NDArray[np.float64] | None = None
    input_unit: str = "mm"

    def far(self) -> list[tuple[Target, float]]:
        """The compensated targets whose model input lies more than :data:`EXTRAPOLATION_LIMIT` (mm or degrees)
        from the data the model was fitted on, with that distance: their correction is the model extrapolated."""
        if self.distance_to_data is None:
            return []
        return [(t, float(d)) for t, d in zip(self.program.targets, self.distance_to_data) if d > EXTRAPOLATION_LIMIT]

    def summary(self, model: str = "") -> dict:
        """The summary written beside the output (JSON values): counts, the largest move and turn of a target
        (with its name and line), the largest predicted residual, the targets not compensated, the poses the
        program reader left as written (with their reasons), and the targets far from the model's data."""
        n, bad = len(self.program.targets), len(self.failures)
        ok = np.isfinite(self.residual_mm)

        def largest(values, unit):
            if not ok.any():
                return None
            k = int(np.argmax(np.where(ok, values, -1.0)))
            return {unit: float(values[k]), "target": self.program.targets[k].name,
                    "line": self.program.targets[k].line}

        return {
            "program": self.program.path, "dialect": self.program.dialect.name, "model": model,
            "targets": n, "compensated": n - bad, "orientation": self.orientation,
            "largest_correction": largest(self.correction_mm, "mm"),
            "largest_turn": largest(self.correction_deg, "deg"),
            "predicted_residual": None if not ok.any() else {
                "max_mm": float(self.residual_mm[ok].max()), "max_deg": float(self.residual_deg[ok].max())},
            "not_compensated": [{"line": t.line, "column": t.column, "target": t.name, "reason": why}
                                for t, why in self.failures],
            "left_as_written": [{"line": x.line, "column": x.column, "target": x.name, "reason": x.reason}
                                for x in self.program.left],
            "far_from_data": [{"line": t.line, "column": t.column, "target": t.name, "distance": d,
                               "unit": self.input_unit} for t, d in self.far()],
            "written": self.output is not None,
        }


def compensate_program(predictor: Predictor, program: Program, frames: ProgramFrames | None = None, *,
                       keep_unconverged: bool = False, tol_mm: float = 1e-4, tol_deg: float = 1e-5
                       ) -> ProgramResult:
    """Rewrite every target of ``program`` to the false target that makes the robot reach it.

    Parameters
    ----------
    predictor : Predictor
        A model whose file carries its robot (the frames, the joint targets and the configuration check
        need the kinematics).
    program : Program
        From :func:`partcal.data.programs.read_program`.
    frames : ProgramFrames, optional
        Frames and tools the targets name (or the defaults), beyond those the program defines.
    keep_unconverged : bool
        Write the program even when targets failed: they keep their numbers, with a comment.
    tol_mm, tol_deg : float
        Convergence of the compensation (predicted miss).

    Raises
    ------
    UnknownFrameError
        A target names a frame or tool that is neither given nor defined in the program.
    """
    robot, joints = _robot_for(predictor, program)
    frame, tool = _frames(program, frames or ProgramFrames())
    tool_model = poses_from(robot.tool_mm, np.eye(3))
    wanted, q_given = _wanted(robot, program, joints, frame, tool, tool_model)
    failures: dict[int, str] = {}
    q0 = _intended_joints(robot, program, wanted, q_given, joints, failures)
    orientation = "model" if predictor.predicts_pose else "kept"
    q1, commanded, residual_mm, residual_deg = _solved(predictor, program, wanted, q0, failures, orientation,
                                                       tol_mm, tol_deg)
    result = _result(program, program.targets, frame, tool, tool_model, wanted, commanded, q1, failures,
                     residual_mm, residual_deg, orientation, keep_unconverged, (tol_mm, tol_deg))
    distance, cartesian = np.full(len(wanted), np.nan), predictor.inputs == "cartesian"
    done = np.array([k not in failures for k in range(len(wanted))], dtype=bool)
    if done.any():                      # the model's input at each solution: its tool point or the joints
        distance[done] = predictor.distance_to_data(**({"positions": commanded[done, :3, 3]} if cartesian else
                                                       {"joints": q1[done]}))
    return dataclasses.replace(result, distance_to_data=distance, input_unit="mm" if cartesian else "deg")


def _robot_for(predictor: Predictor, program: Program):
    """The model's robot, checked against the program's targets, and which targets are joint targets."""
    robot = predictor.robot
    if robot is None:
        raise DataError(f"model {predictor.name!r}: its file names no robot; compensating a program needs the "
                        "robot's kinematics (frames, joint targets, configurations)")
    joints = np.array([t.kind == "joints" for t in program.targets], dtype=bool)
    for t in program.targets:
        if t.kind == "joints" and len(t.joints_deg) != robot.n_joints:
            raise DataError(f"{t.where(program.path)}: {len(t.joints_deg)} joints, but robot {robot.name} has "
                            f"{robot.n_joints}")
    if robot.n_joints != 6 and not joints.all():
        raise DataError(f"{program.path}: pose targets need a six-joint robot; {robot.name} has {robot.n_joints}")
    moved = [(t, axis, value) for t in program.targets for axis, value in t.external if value != 0.0]
    if moved:
        t, axis, value = moved[0]
        raise DataError(f"{t.where(program.path)}: its external axis {axis} is at {value:g} (a linear track carrying "
                        "the robot, or a positioner carrying the work): the pose is not in the robot's own frame "
                        f"there, and the model's robot {robot.name} has no axis {axis}. partcal compensates poses in "
                        "the robot's frame: give this station's targets relative to the robot's base (its travel "
                        f"taken off, {axis} at 0), or as joint targets; "
                        + (f"{len(moved) - 1} more targets with external axes off 0; " if len(moved) > 1 else "")
                        + "nothing written")
    return robot, joints


def _wanted(robot, program: Program, joints, frame, tool, tool_model) -> tuple:
    """The model's tool-point pose (n, 4, 4) mm each target wants, and the joint targets' joints (n, N) deg."""
    n = len(joints)
    wanted, q_given = np.zeros((n, 4, 4)), np.zeros((n, robot.n_joints))
    if joints.any():
        q_given[joints] = np.array([t.joints_deg for t in program.targets if t.kind == "joints"])
        wanted[joints] = robot.forward(q_given[joints])
    if (~joints).any():
        P = poses_from([t.position_mm for t in program.targets if t.kind == "pose"],
                       [t.rotation for t in program.targets if t.kind == "pose"])
        wanted[~joints] = frame[~joints] @ P @ inverse_poses(tool[~joints]) @ tool_model
    return wanted, q_given


def _solved(predictor: Predictor, program: Program, wanted, q0, failures: dict, orientation: str, tol_mm: float,
            tol_deg: float) -> tuple:
    """The compensation of every target not failed yet: the joints (n, N) degrees, the commanded tool-point
    poses (n, 4, 4) mm and the predicted misses (NaN where not solved); ``failures`` gets the new ones."""
    robot, n = predictor.robot, len(wanted)
    q1, commanded = q0.copy(), wanted.copy()
    residual_mm, residual_deg = np.full(n, np.nan), np.full(n, np.nan)
    idx = np.array([k for k in range(n) if k not in failures], dtype=np.intp)
    if idx.size == 0:
        return q1, commanded, residual_mm, residual_deg
    r = predictor.compensate_poses(wanted[idx], q0[idx], tol_mm=tol_mm, tol_deg=tol_deg,
                                   orientation_kept=orientation == "kept")
    commanded[idx] = poses_from(r.commanded_mm, r.commanded_rotation)
    residual_mm[idx], residual_deg[idx] = r.residual_mm, r.residual_deg
    converged = r.converged.copy()
    if r.joints_deg is not None:
        q1[idx] = r.joints_deg
    else:                        # the controller solves the command on the target's branch
        ik = _inverse_pose(robot, commanded[idx], q0[idx], min(tol_mm, IK_TOL_MM), min(tol_deg, IK_TOL_DEG))
        low, high = written_ranges(program, [program.targets[k] for k in idx], robot.n_joints)
        q1[idx] = nearest_split(robot, ik.q_deg, q0[idx], low, high, tol_mm=IK_TOL_MM, tol_deg=IK_TOL_DEG)
        converged &= ik.success
    singular = r.singular if r.singular is not None else np.zeros(len(idx), dtype=bool)
    for k, ok, miss_mm, miss_deg, at_singularity in zip(idx, converged, r.residual_mm, r.residual_deg, singular):
        if not ok:
            miss = f"predicted miss {miss_mm:.3g} mm, {miss_deg:.3g} deg"
            if miss_mm <= tol_mm and miss_deg <= tol_deg:
                failures[k] = (f"is unreachable: the robot cannot take its compensated command within its joint "
                               f"limits ({miss})")
            elif at_singularity:
                failures[k] = (f"did not converge: its solve stopped at a singularity, no joints near the target's "
                               f"take its compensated pose ({miss})")
            else:
                failures[k] = f"did not converge ({miss})"
    chosen = [program.targets[k] for k in idx]
    for k, same in zip(idx, configuration_kept(robot, program, chosen, q0[idx], q1[idx])):
        if not same and k not in failures:
            failures[k] = "leaves its configuration (" + configurations_text(program, q0[k], q1[k]) + ")"
    return q1, commanded, residual_mm, residual_deg


def _result(program, targets, frame, tool, tool_model, wanted, commanded, q1, failures, residual_mm,
            residual_deg, orientation, keep_unconverged, tolerance) -> ProgramResult:
    """The rewritten text, the corrections and the failures. A target whose correction is within the
    compensation's ``tolerance`` (mm, degrees) keeps its text: a model that predicts no error gives the
    program back byte for byte, whatever the round-off of its solves (1e-12 m in a UR's 12 decimals)."""
    n = len(targets)
    out_pose = inverse_poses(frame) @ commanded @ inverse_poses(tool_model) @ tool
    original = inverse_poses(frame) @ wanted @ inverse_poses(tool_model) @ tool
    correction_mm, correction_deg = pose_errors(out_pose, original) if n else (np.zeros(0), np.zeros(0))
    dialect, replacements = program.dialect, []
    for k in failures:
        correction_mm[k] = correction_deg[k] = 0.0
        residual_mm[k] = residual_deg[k] = np.nan
        replacements.append(dialect.note(program.text, targets[k], f"partcal: not compensated: {failures[k]}"))
    unmoved = (correction_mm <= tolerance[0]) & (correction_deg <= tolerance[1])
    for kind in ("pose", "joints"):
        rows = [k for k, t in enumerate(targets) if t.kind == kind and k not in failures and not unmoved[k]]
        if not rows:
            continue
        chosen = [targets[k] for k in rows]
        texts = dialect.texts(chosen, joints_deg=q1[rows]) if kind == "joints" else \
            dialect.texts(chosen, out_pose[rows, :3, 3], out_pose[rows, :3, :3], tol_deg=tolerance[1])
        replacements += [(f.start, f.end, new) for t, row in zip(chosen, texts) for f, new in zip(t.fields, row)
                         if new != f.text]
    listed = [(targets[k], why) for k, why in sorted(failures.items())]
    output = program.rewritten(replacements) if not listed or keep_unconverged else None
    return ProgramResult(program, output, listed, correction_mm, correction_deg, residual_mm, residual_deg,
                         orientation)


def _frames(program: Program, given: ProgramFrames) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The frame and the tool (n, 4, 4) mm of every target (identity for joint targets); every frame or tool
    that is neither given nor in the program is named in one refusal, with the first target that uses it."""
    n = len(program.targets)
    frame, tool = np.tile(np.eye(4), (n, 1, 1)), np.tile(np.eye(4), (n, 1, 1))
    unknown: dict[tuple[str, str], Target] = {}
    for k, t in enumerate(program.targets):
        if t.kind == "pose":
            for what, name, given_poses, out in (("frame", t.frame, given.frames, frame),
                                                 ("tool", t.tool, given.tools, tool)):
                pose = _lookup(program, name, given_poses)
                if pose is None:
                    unknown.setdefault((what, name), t)
                else:
                    out[k] = pose
    if unknown:
        (what, name), first = next(iter(unknown.items()))
        others = [f"{w} {nm!r} ({tg.where(program.path)})" for (w, nm), tg in list(unknown.items())[1:]]
        option = "--frame" if what == "frame" else "--tool"
        raise UnknownFrameError(f"{first.where(program.path)}: it is given in the {what} {name!r}, which is unknown: "
                                f"give it with {option} '{name}=VALUE' (VALUE in the program's own syntax, "
                                "docs/predictor.md)" + (f"; unknown too: {', '.join(others)}" if others else "")
                                + "; nothing written")
    return frame, tool


def _lookup(program: Program, name: str | None, given: dict) -> NDArray[np.float64] | None:
    """The pose (4, 4) mm of a frame or tool named ``name`` (None: the default), given on the command line or
    declared in the program; None when it is neither."""
    if name is None:
        return given.get(None, np.eye(4))
    if name in given:
        return given[name]
    return program.frames.get(name)


def _inverse_pose(robot, poses, seeds, tol_mm: float, tol_deg: float):
    """The robot's pose IK of ``poses`` (n, 4, 4) from ``seeds``, solved to :data:`EXACT_MM` / :data:`EXACT_DEG`;
    a solve that stalls short of that (a singular wrist) succeeds where it is within ``tol_mm`` / ``tol_deg``
    and the joint limits. One that stalls farther off, at a wrist a hair off straight (axis 4 must turn to the
    direction of a tilt of thousandths of a degree, where it has almost no leverage), is finished by
    Levenberg-Marquardt with restarts along the self-motion (:func:`~partcal.robot.ik_refine.refine_pose`)."""
    ik = robot.inverse_pose(poses, seeds, tol_mm=min(tol_mm, EXACT_MM), tol_deg=min(tol_deg, EXACT_DEG))
    close = (ik.error_mm <= tol_mm) & (ik.error_deg <= tol_deg) & robot.within_limits(ik.q_deg)
    stalled = np.flatnonzero(~(ik.success | close) & (shared_turns(robot, ik.q_deg)[0] >= 0))
    if stalled.size:                  # a wrist a hair off straight: its axis 4 must turn far, with little leverage
        q, error_mm, error_deg = ik.q_deg.copy(), ik.error_mm.copy(), ik.error_deg.copy()
        settings, free = ik_settings(tol_mm, 100, 10.0, 0.05, tol_deg=tol_deg, length_mm=1000.0), robot.free_joints(())
        q[stalled] = refine_pose(robot, poses[stalled, :3, 3], poses[stalled, :3, :3], q[stalled], free, settings,
                                 tol_deg, 1000.0)[0]
        error_mm[stalled], error_deg[stalled] = pose_errors(robot.forward(q[stalled]), poses[stalled])
        close = (error_mm <= tol_mm) & (error_deg <= tol_deg) & robot.within_limits(q)
        ik = dataclasses.replace(ik, q_deg=q, error_mm=error_mm, error_deg=error_deg)
    return dataclasses.replace(ik, success=ik.success | close)


def _outside_limits(robot, q_deg: NDArray[np.float64]) -> str:
    """Why a joint target ``q_deg`` (N,) degrees is outside the robot's limits: each joint beyond its range,
    or the coupled constraint it breaks."""
    low, high = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    beyond = np.flatnonzero((q_deg < low) | (q_deg > high))
    if beyond.size:
        return "is outside the joint limits: " + ", ".join(
            f"joint {j + 1} at {q_deg[j]:g} deg (range {low[j]:g} to {high[j]:g})" for j in beyond)
    return "is outside the joint limits: it breaks a coupled constraint between the joints"


def _intended_joints(robot, program: Program, wanted, q_given, joints, failures: dict) -> NDArray[np.float64]:
    """Joints (n, N) degrees at which the nominal robot has each wanted pose, on the branch the target names.

    Pose targets are solved from the joint target before them in the file (else the home pose), then from
    further seeds spread inside the limits (the same every time) until the branch matches.
    """
    n = len(joints)
    q0 = q_given.copy()
    for k in np.flatnonzero(joints & ~robot.within_limits(q_given)):
        failures[k] = _outside_limits(robot, q_given[k])
    todo = np.flatnonzero(~joints)
    if todo.size == 0:
        return q0
    previous = np.where(joints, np.arange(n), -1)
    previous = np.maximum.accumulate(previous)
    seeds = np.where((previous >= 0)[:, None], q_given[np.maximum(previous, 0)], robot.home_deg)
    spread = np.random.default_rng(0).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1],
                                              (64 * SEED_TRIES, robot.n_joints))
    tries = [seeds[todo]]
    written = np.array([program.targets[k].configuration is not None for k in todo])
    if program.dialect.seeds is not None and written.any():      # seeds in the written configurations
        named = seeds[todo].copy()
        config = np.array([[-1 if c is None else c for c in program.targets[k].configuration]
                           for k in todo[written]])
        named[written] = program.dialect.seeds(config, named[written])
        tries.append(named)
    tries += list(spread[robot.within_limits(spread)][:SEED_TRIES - len(tries)])
    found, reached = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    nearest, nearest_q = np.full(n, np.inf), q0.copy()          # the nearest miss of the pose, and its joints
    low, high = written_ranges(program, program.targets, robot.n_joints)
    for seed in tries:
        rows = todo[~found[todo]]
        if rows.size == 0:
            break
        start = seed if np.ndim(seed) == 1 else seed[~found[todo]]
        ik = _inverse_pose(robot, wanted[rows], start, IK_TOL_MM, IK_TOL_DEG)
        q = nearest_split(robot, ik.q_deg, start, low[rows], high[rows], tol_deg=SPLIT_TOL_DEG,
                          tol_mm=np.radians(SPLIT_TOL_DEG) * robot.reach_mm)
        ok = ik.success & configuration_of(robot, program, [program.targets[k] for k in rows], q, q)
        q0[rows[ok]] = q[ok]
        found[rows[ok]], reached[rows[ik.success]] = True, True
        closer = ik.error_mm < nearest[rows]
        nearest[rows[closer]], nearest_q[rows[closer]] = ik.error_mm[closer], ik.q_deg[closer]
    for k in todo[~found[todo]]:
        failures[k] = _unreachable(robot, program.targets[k], reached[k], nearest[k], nearest_q[k])
    return q0


def _unreachable(robot, target: Target, reached: bool, nearest_mm: float, q_deg) -> str:
    """Why no seed gave a target's pose its intended joints, pointing where the cause is: its configuration
    (the arm takes the pose, but not so), the joint limits (it takes the pose only outside them), the stretched
    arm (a singular pose the solve stops short of), or its frame and tool (the nearest the arm comes is far off: the base or tool in force at its motion may not be
    the one the program was read with)."""
    conf = f" in its configuration {target.configuration}" if target.configuration else ""
    if reached:
        return f"is reachable by the robot's kinematics, but not{conf} (every solution found has another)"
    if nearest_mm <= IK_TOL_MM and not robot.within_limits(np.asarray(q_deg)[None])[0]:
        return f"{_outside_limits(robot, np.asarray(q_deg))} (the arm reaches the pose only there{conf})"
    if nearest_mm < 1.0 and conditioning(robot, q_deg[None], np.arange(robot.n_joints), 1000.0)[0] < 1e-3:
        return (f"is unreachable by the robot's kinematics{conf}: it lies where the arm is stretched out or folded "
                f"(a singular pose), and the solve stops {nearest_mm:.3g} mm short of it")
    return (f"is unreachable by the robot's kinematics{conf}: the nearest the arm comes is {nearest_mm:.4g} mm off, "
            f"in the frame {target.frame or '(the default)'} with the tool {target.tool or '(the default)'} it was "
            "read in; if another base or tool is in force at its motion (set by a subroutine partcal does not "
            "read, or a track moving the robot), give them with --frame and --tool")
