"""A virtual robot: the "true" machine behind the nominal model, and a laser tracker.

The true robot differs from its nominal DH model by the error sources the
paper names: link length, offset and twist deviations and joint zero offsets
(random, per DH row), a tool-fixture error, a misaligned base frame, joint
compliance under gravity (lumped masses, configuration dependent) and a
cyclic gear-transmission error. The tracker adds a scale error of its own
(its ppm accuracy) and averages noisy readings (its ppm repeatability). The
tool may carry several targets (reflectors), each read with its own noise,
and the tracker may measure the tool's orientation too. All of it comes from
one YAML file and one seed; see ``docs/virtual_robot.md``.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import made_folder, replace_all
from .._validation import one_of, safe_name
from .._yamlio import Section, load_yaml, range_check
from ..errors import ConfigError, PartcalError
from ..robot.description import joint_columns, load_robot, robot_reference
from ..robot.iso_cube import largest_cube, solve_cube
from ..robot.kinematics import Robot
from ..robot.rotations import (matrices_from_rotation_vectors, matrix_from_rpy_deg, rpy_deg_from_matrix,
                               xyz_deg_from_matrices)
from ..robot.trajectories import PATHS, paper_path
from .contact_sets import (contact_keys, TrueCell, read_true_cell, read_contact_dataset,
                           simulate_observations, write_contact_files)
from .formats import TARGET_NAME
from .measurements import Measurements, write_measurements
from .pose_columns import PRIMARY
from .sampling import FARTHEST_POINT_UP_TO, sample_configurations  # noqa: F401 (public here as before)

log = logging.getLogger(__name__)
GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class Compliance:
    """Gravity sag of one joint: ``dq = torque / stiffness``.

    The torque is that of point masses at DH frame origins about the z axis
    of the pivot frame, with gravity along ``-z`` of the base.
    """

    joint: int                      # 1-based actuated joint that deflects
    pivot_frame: int                # DH frame whose z axis is the hinge
    mass_frames: tuple[int, ...]    # frames carrying the lumped masses
    masses_kg: tuple[float, ...]
    stiffness_nm_per_deg: float

    def deflection_deg(self, origins: NDArray[np.float64], axes: NDArray[np.float64]) -> NDArray[np.float64]:
        """Joint deflection in degrees for frames ``(n, R + 1, 3)``."""
        pivot, axis = origins[:, self.pivot_frame], axes[:, self.pivot_frame]
        torque = np.zeros(origins.shape[0])
        for frame, kg in zip(self.mass_frames, self.masses_kg):
            lever_m = (origins[:, frame] - pivot) / 1000.0
            force = np.array([0.0, 0.0, -kg * GRAVITY_M_S2])
            torque += np.einsum("ij,ij->i", axis, np.cross(lever_m, force))
        return torque / self.stiffness_nm_per_deg


@dataclass(frozen=True)
class Tracker:
    """Laser tracker: scale error (accuracy) and averaged reading noise (repeatability)."""

    position_mm: NDArray[np.float64]
    accuracy_ppm: float
    repeatability_ppm: float
    readings: int
    orientation_noise_deg: float | None = None      # None: the orientation is not measured


@dataclass(frozen=True, eq=False)
class VirtualRobot:
    """The nominal model, the true robot, and the tracker that measures it."""

    nominal: Robot
    true: Robot
    base_rotation: NDArray[np.float64]
    base_mm: NDArray[np.float64]
    compliance: tuple[Compliance, ...]
    gear: tuple[tuple[int, float, float, float], ...]   # (joint, amplitude_deg, cycles_per_rev, phase_deg)
    tracker: Tracker
    tracker_scale: float
    targets: dict = field(default_factory=dict)     # extra targets: name -> nominal offset (3,) mm
    repeatability_mm: float = 0.0   # standard deviation per axis of the tool position between visits of one pose

    def actual_joints(self, q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """Joint angles the arm really takes when ``q_deg`` is commanded."""
        q = self.nominal.check_joints(q_deg).copy()
        for joint, amp, cycles, phase in self.gear:
            q[:, joint - 1] += amp * np.sin(np.radians(cycles * q[:, joint - 1] + phase))
        if self.compliance:
            origins, axes = self.true.frames(q)
            for c in self.compliance:
                q[:, c.joint - 1] += c.deflection_deg(origins, axes)
        return q

    def true_positions(self, q_deg) -> NDArray[np.float64]:
        """Noise-free positions the true robot reaches, ``(n, 3)`` mm in the base frame."""
        p = self.true.positions(self.actual_joints(q_deg))
        return p @ self.base_rotation.T + self.base_mm

    def true_flange(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Noise-free flange (last frame) positions ``(n, 3)`` mm and orientations ``(n, 3, 3)`` in the base frame."""
        pose = self.true.flange(self.actual_joints(q_deg))
        return pose[:, :3, 3] @ self.base_rotation.T + self.base_mm, self.base_rotation @ pose[:, :3, :3]

    def true_tool(self, target: str) -> NDArray[np.float64]:
        """An extra target's true offset in the flange frame, mm: its nominal one moved by the fixture error."""
        return self.targets[target] + (self.true.tool_mm - self.nominal.tool_mm)

    def measure(self, q_deg, rng: np.random.Generator) -> NDArray[np.float64]:
        """What the tracker reports of the primary target: the mean of ``readings`` noisy readings per pose.

        With a ``repeatability_mm`` the arm itself stops each time a little
        elsewhere: every visit adds independent normal noise of that standard
        deviation per axis to the true position (drawn only when it is set, so
        data sets without it are unchanged).
        """
        p = self.true_positions(q_deg)
        if self.repeatability_mm > 0:
            p = p + rng.normal(0.0, self.repeatability_mm, size=p.shape)
        return self._read(p, rng)

    def _read(self, p: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
        """The tracker's reading of true points ``(n, 3)`` mm: its scale error and averaged noise."""
        t = self.tracker
        dist = np.linalg.norm(p - t.position_mm, axis=1)
        scaled = t.position_mm + (1.0 + self.tracker_scale) * (p - t.position_mm)
        sigma = t.repeatability_ppm * 1e-6 * dist
        noise = rng.standard_normal((p.shape[0], t.readings, 3)).mean(axis=1)
        return scaled + sigma[:, None] * noise

    def measure_more(self, q_deg, rng: np.random.Generator) -> tuple[dict, NDArray[np.float64] | None]:
        """The extra targets (name -> ``(n, 3)`` mm, each with its own noise) and the tool's orientation
        (intrinsic XYZ degrees, turned by a small random rotation of ``orientation_noise_deg`` per axis; None
        when not measured)."""
        if not self.targets and self.tracker.orientation_noise_deg is None:
            return {}, None
        p_fl, r_fl = self.true_flange(q_deg)
        extra = {name: self._read(p_fl + r_fl @ self.true_tool(name), rng) for name in self.targets}
        sigma = self.tracker.orientation_noise_deg
        if sigma is None:
            return extra, None
        turns = matrices_from_rotation_vectors(np.radians(rng.standard_normal((len(p_fl), 3)) * sigma))
        return extra, xyz_deg_from_matrices(turns @ r_fl)


@dataclass(frozen=True)
class Study:
    """A parsed virtual-experiment config: the robot and the data sets to produce."""

    robot: VirtualRobot
    seed: int
    output: Path
    datasets: dict[str, dict]
    ranges_deg: dict[int, tuple[float, float]]
    fixed_deg: dict[int, float]
    source: Path
    cell: TrueCell | None = None                # the cell's true planes and points (``cell:``)
    observations: dict = field(default_factory=dict)  # contact data sets: name -> spec (simulate_contacts)


def load_study(path: str | Path) -> Study:
    """Read a virtual-experiment YAML (``configs/sk120_virtual.yaml``)."""
    path = Path(path)
    data, lines = load_yaml(path)
    top = Section(data, "", lines, str(path))
    if isinstance(data, dict) and "robot" not in data and {"links", "joints"} <= set(data):
        raise ConfigError(f"{path}: a robot description (it has 'links' and 'joints'), not a virtual robot's "
                          "config: a virtual robot names its nominal robot under 'robot' and adds 'errors', "
                          "'tracker', 'sampling' and 'datasets' (docs/virtual_robot.md)")
    spec = top.get("robot", "any", check=lambda v: None if isinstance(v, (str, dict)) else
                   "a built-in robot name, a robot YAML or URDF file, or {urdf: FILE.urdf, base: LINK, tip: LINK}")
    try:
        robot = load_robot(robot_reference(spec, path.parent))
    except ConfigError as exc:
        top.fail(top.path("robot"), str(exc))
    nominal, targets = _targets(top, robot)
    seed = top.get("seed", "int", check=range_check(0, integer=True))
    output = Path(os.path.normpath(path.parent / top.get("output", "str")))
    seeds = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(seeds[0])
    errors = top.section("errors", required=True)
    true, base_rot, base_mm = _true_robot(nominal, errors, rng)
    compliance = _compliance(errors, nominal)
    gear = _gear(errors, nominal)
    repeatability = errors.get("repeatability_mm", "float", default=0.0, check=range_check(0))
    tr = top.section("tracker", required=True)
    tracker = Tracker(
        position_mm=np.asarray(tr.get("position_mm", "list", check=_vector3), dtype=float),
        accuracy_ppm=tr.get("accuracy_ppm", "float", check=range_check(0)),
        repeatability_ppm=tr.get("repeatability_ppm", "float", check=range_check(0)),
        readings=tr.get("readings", "int", check=range_check(1, 10_000, integer=True)),
        orientation_noise_deg=tr.get("orientation_noise_deg", "float", default=None, check=range_check(0)))
    tr.done()
    errors.done()
    scale = np.random.default_rng(seeds[1]).uniform(-1, 1) * tracker.accuracy_ppm * 1e-6
    sampling = top.section("sampling", required=True)
    ranges = _joint_map(sampling, "ranges_deg", nominal, pairs=True)
    fixed = _joint_map(sampling, "fixed_deg", nominal, pairs=False)
    sampling.done()
    top.renamed("features", "cell")
    cell = read_true_cell(top.section("cell")) if top.has("cell") else None
    datasets, observations = _datasets(top.section("datasets", required=True), cell)
    top.done()
    robot = VirtualRobot(nominal, true, base_rot, base_mm, compliance, gear, tracker, scale, targets, repeatability)
    return Study(robot, seed, output, datasets, ranges, fixed, path, cell, observations)


def _targets(top: Section, nominal: Robot) -> tuple[Robot, dict]:
    """The nominal robot (its tool the primary target ``A`` when given) and the extra targets' offsets.

    ``targets: {A: [x, y, z], B: [...]}``: offsets in the flange frame, mm.
    Without ``A`` the primary target is the robot's own tool.
    """
    sec = top.section("targets")
    out = {}
    for name in list(sec.data):
        if not isinstance(name, str) or not TARGET_NAME.match(name):
            sec.fail(sec.path(str(name)), f"a target name is letters, digits and '_'; got {name!r}")
        out[name] = np.asarray(sec.get(name, "list", check=_vector3), dtype=float)
    sec.done()
    if PRIMARY in out:
        nominal = nominal.replace(tool_mm=out.pop(PRIMARY))
    return nominal, out


def _vector3(value) -> str | None:
    ok = len(value) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    return None if ok else "a list of three numbers"


def _true_robot(nominal: Robot, errors: Section, rng: np.random.Generator):
    dh = errors.section("dh_sigma", required=True)
    length = dh.get("length_mm", "float", check=range_check(0))
    twist = dh.get("twist_deg", "float", check=range_check(0))
    zero = dh.get("zero_offset_deg", "float", check=range_check(0))
    dh.done()
    rows = nominal.alpha_deg.size
    deviations = rng.standard_normal((4, rows)) * np.array([[length], [length], [twist], [zero]])
    tool = np.asarray(errors.get("tool_mm", "list", check=_vector3), dtype=float)
    base = errors.section("base", required=True)
    rot = matrix_from_rpy_deg(base.get("rotation_deg", "list", check=_vector3))
    shift = np.asarray(base.get("translation_mm", "list", check=_vector3), dtype=float)
    base.done()
    true = nominal.replace(a_mm=nominal.a_mm + deviations[0], d_mm=nominal.d_mm + deviations[1],
                           alpha_deg=nominal.alpha_deg + deviations[2],
                           theta_offset_deg=nominal.theta_offset_deg + deviations[3],
                           tool_mm=nominal.tool_mm + tool, origins=_tilted(nominal, errors))
    return true, rot, shift


def _tilted(nominal: Robot, errors: Section):
    """The true rows' origins ``(R, 6)`` with ``errors.tilt_deg`` (``{qK: degrees}``): the row that joint K
    turns ends turned by that much about its frame's y axis, so that the next axis leans out of the plane
    a DH row keeps it in (a tilt between parallel axes: Hayati's beta). None without tilts."""
    tilts = _joint_map(errors, "tilt_deg", nominal, pairs=False)
    if not tilts:
        return nominal.origins
    out = np.zeros((nominal.alpha_deg.size, 6)) if nominal.origins is None else nominal.origins.copy()
    for joint, angle in tilts.items():
        row = int(np.flatnonzero(nominal.coupling[:, joint - 1])[0])
        turned = matrix_from_rpy_deg(out[row, 3:]) @ matrix_from_rpy_deg([0.0, angle, 0.0])
        out[row, 3:] = rpy_deg_from_matrix(turned)
    return out


def _compliance(errors: Section, robot: Robot) -> tuple[Compliance, ...]:
    out = []
    items = errors.get("compliance", "list", default=[])
    n_frames = robot.alpha_deg.size + 1
    for i, item in enumerate(items):
        sec = Section(item, f"{errors.path('compliance')}[{i}]", errors.lines, errors.source)
        joint = sec.get("joint", "int", check=range_check(1, robot.n_joints, integer=True))
        pivot = sec.get("pivot_frame", "int", check=range_check(0, n_frames - 1, integer=True))
        stiff = sec.get("stiffness_Nm_per_deg", "float", check=range_check(1e-9))
        frames, kgs = [], []
        for k, m in enumerate(sec.get("masses", "list")):
            ms = Section(m, f"{sec.path('masses')}[{k}]", sec.lines, sec.source)
            frames.append(ms.get("frame", "int", check=range_check(0, n_frames - 1, integer=True)))
            kgs.append(ms.get("kg", "float", check=range_check(0)))
            ms.done()
        sec.done()
        out.append(Compliance(joint, pivot, tuple(frames), tuple(kgs), stiff))
    return tuple(out)


def _gear(errors: Section, robot: Robot) -> tuple:
    out = []
    for i, item in enumerate(errors.get("gear", "list", default=[])):
        sec = Section(item, f"{errors.path('gear')}[{i}]", errors.lines, errors.source)
        out.append((sec.get("joint", "int", check=range_check(1, robot.n_joints, integer=True)),
                    sec.get("amplitude_deg", "float", check=range_check(0)),
                    sec.get("cycles_per_rev", "float", check=range_check(0)),
                    sec.get("phase_deg", "float", default=0.0)))
        sec.done()
    return tuple(out)


def _joint_map(sec: Section, key: str, robot: Robot, pairs: bool) -> dict:
    sub = sec.section(key)
    names = joint_columns(robot.n_joints)
    out = {}
    for j, name in enumerate(names, start=1):
        if not sub.has(name):
            continue
        if pairs:
            lo, hi = sub.get(name, "list", check=lambda v: None if len(v) == 2 and v[0] < v[1]
                             else "[low, high] with low < high")
            out[j] = (float(lo), float(hi))
        else:
            out[j] = sub.get(name, "float")
    sub.done()
    return out


def _datasets(sec: Section, cell: TrueCell | None) -> tuple[dict[str, dict], dict[str, dict]]:
    """The point data sets and the contact data sets (``plane:``, ``fixed:``, ``distance:``) of ``datasets:``."""
    out, contacts = {}, {}
    for name in list(sec.data):
        problem = safe_name(str(name))
        if problem:
            sec.fail(sec.path(str(name)), f"the data-set name {str(name)!r} must be {problem}")
        item = sec.section(name)
        keys = contact_keys()
        given = [k for k in ("sample", "path", "iso9283", *keys) if item.has(k)]
        if len(given) != 1:
            item.fail(item.where, "give exactly one of 'sample: N' (sampled configurations), "
                                  f"'path: NAME' ({', '.join(PATHS)}), 'iso9283: CYCLES' (the ISO 9283 cube's "
                                  "P1..P5), or contact data 'plane:', 'fixed:' or 'distance:' (docs/virtual_robot.md)")
        if given[0] in keys:
            if cell is None and given[0] in ("plane", "fixed"):
                item.fail(item.path(given[0]), "needs the cell's planes and points: add a 'cell:' section")
            contacts[name] = read_contact_dataset(item, cell)
            item.done()
            continue
        if item.has("sample"):
            spec = {"sample": item.get("sample", "int", check=range_check(1, 10**7, integer=True))}
        elif item.has("iso9283"):
            spec = {"iso9283": item.get("iso9283", "int", check=range_check(1, 10_000, integer=True)),
                    "cube": item.get("cube", "list", default=None, check=_cube)}
        else:
            spec = {"path": item.get("path", "str", check=one_of(*PATHS).problem),
                    "start_mm": item.get("start_mm", "list", default=None, check=_vector3)}
        item.done()
        out[name] = spec
    if not out and not contacts:
        sec.fail(sec.where, "lists no data set")
    return out, contacts


def _cube(value) -> str | None:
    ok = isinstance(value, list) and len(value) == 4 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in value)
    return None if ok and value[3] > 0 else "[cx, cy, cz, edge] in mm (the cube's centre and a positive edge)"


def simulate(study: Study) -> dict[str, Measurements]:
    """Produce every data set of a study (deterministic for its seed)."""
    vr = study.robot
    out = {}
    children = np.random.SeedSequence(study.seed).spawn(2 + len(study.datasets))[2:]
    for (name, spec), child in zip(study.datasets.items(), children):
        rng = np.random.default_rng(child)
        labels = (name,)
        try:
            if "sample" in spec:
                q = sample_configurations(vr.nominal, spec["sample"], study.ranges_deg, study.fixed_deg, rng)
            elif "iso9283" in spec:            # P1..P5 of the cube, once per cycle: the cycles are the repeats
                c = spec["cube"]
                cube = largest_cube(vr.nominal, random_state=rng) if c is None else solve_cube(vr.nominal, c[:3], c[3])
                q = np.tile(cube.q_deg, (spec["iso9283"], 1))
                labels = tuple(f"P{k + 1}" for k in range(len(cube.q_deg)))
            else:
                targets = paper_path(spec["path"], spec["start_mm"])
                seed = vr.nominal.home_deg.copy()
                for j, value in study.fixed_deg.items():
                    seed[j - 1] = value
                q = vr.nominal.inverse_path(targets, seed, fixed=tuple(study.fixed_deg))
        except PartcalError as exc:     # a cube or path out of reach: the data set of the config that asks for it
            raise ConfigError(f"{study.source}: datasets.{name}: {exc}") from None
        nominal = vr.nominal.positions(q)
        measured = vr.measure(q, rng)
        extra, orientation = vr.measure_more(q, rng)
        flange = vr.nominal.flange(q)
        out[name] = Measurements(q, nominal, measured, name=name, labels=labels * (len(q) // len(labels)),
                                 extra_measured_mm=extra,
                                 extra_nominal_mm={t: flange[:, :3, 3] + flange[:, :3, :3] @ vr.targets[t]
                                                   for t in extra},
                                 measured_orientation_deg=orientation,
                                 nominal_orientation_deg=None if orientation is None
                                 else xyz_deg_from_matrices(flange[:, :3, :3]))
        log.info("simulated %s: %d poses", name, len(q))
    return out


def _shown(path: Path) -> str:
    """``path`` as a command run here would name it: relative to the working folder when inside it, else
    absolute (``configs/sk120_virtual.yaml`` from the project's root)."""
    full = Path(path).resolve()
    try:
        return full.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return str(full)


def write_study(study: Study, data: dict[str, Measurements], observations: dict | None = None) -> list[Path]:
    """Write each data set to ``<output>/<name>.csv`` and return the paths.

    Contact data sets (``observations``: :func:`~partcal.data.simulate_contacts.simulate_observations` of the
    study, made here when not given) add ``<name>.csv`` in the measurement-type contract, ``<name>.truth.yaml``
    and the cell's ``cell.yaml``. The files are replaced as a set: all are written to temporary names
    first and renamed only when every one of them is complete.
    """
    if observations is None:
        observations = simulate_observations(study)
    pending = []
    with made_folder(study.output):
        try:
            for name, m in data.items():
                target = study.output / f"{name}.csv"
                tmp = study.output / f".{name}.csv.partial"
                pending.append((tmp, target))
                write_measurements(m, tmp, comment=_note(study, f"data set '{name}'"))
            if observations:
                pending += write_contact_files(study, observations, _note)
            replace_all(pending)
        finally:
            for tmp, _ in pending:
                tmp.unlink(missing_ok=True)
    return [target for _, target in pending]


def _note(study: Study, what: str) -> str:
    """The comment heading a simulated file: where it comes from and how to make it again."""
    return (f"Virtual {study.robot.nominal.name}, {what}, simulated by partcal from {study.source.name} with seed "
            f"{study.seed}.\nRegenerate with: partcal simulate {_shown(study.source)}. Do not edit by hand.")
