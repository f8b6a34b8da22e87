"""The virtual robot's contact data: plane touches, fixed-point visits and distances, with their truth.

The cell's true planes and points come from the virtual-robot config's ``features:``; each contact data set
(``datasets: NAME: {plane: ...}``, ``{fixed: ...}`` or ``{distance: ...}``) is generated on the TRUE robot:
the commanded joints are what the robot was told, and the true tool tip (true geometry, base, tool, the
joints' compliance and gear errors) lands on the true plane or point, up to the stated noise. The
generators (:func:`plane_touches`, :func:`fixed_point_visits`, :func:`pair_distances`) are plain functions
for benchmarks; :func:`simulate_observations` makes a study's data sets and :func:`cell_features` what the
cell is given of its features (the features YAML, ``docs/data.md``). See ``docs/virtual_robot.md``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

import yaml

from .._io import atomic_write
from .._validation import one_of
from .._yamlio import Section, range_check
from ..errors import UnreachableError
from ..robot.kinematics import Robot
from ..robot.rotations import matrices_from_rotation_vectors
from .observations import (FEATURE_NAME, ObservationTable, check_ties, unit_vector, vector3_problem,
                           write_observations)
from .sampling import sample_configurations, uniform_configurations

log = logging.getLogger(__name__)
CONTACT_KEYS = ("plane", "fixed", "distance")
"""The keys of a contact data set in a virtual-robot config's ``datasets:``."""
PLANE_GIVEN = ("unknown", "approximate", "tied")
POINT_GIVEN = ("unknown", "known", "tied")
APPROXIMATE_DEG, APPROXIMATE_MM = 0.5, 1.0
"""A plane ``given: approximate`` is written turned by this angle and moved by this offset (random directions,
seeded): a drawing's values, not the truth."""
ON_FEATURE_MM = 1e-6
"""How close (besides the stated noise) the true tip lands on its plane or point: rows missing it are dropped."""
NEAR_PLANE_MM, NEAR_POINT_MM = 150.0, 300.0
"""Candidate configurations whose true tip lies this close to the feature are moved onto it."""
ROUNDS = 12


@dataclass(frozen=True)
class CellFeatures:
    """The cell's true planes and points (base frame) and what the cell is given of each.

    ``planes``: name -> (unit normal (3,), offset mm) with ``n . p = offset``; ``points``: name -> (3,) mm;
    ``given``: ``"planes.NAME"`` / ``"points.NAME"`` -> how it is given; ``ties``: the same keys -> the feature
    it is tied to (``parallel_to`` / ``distance_to``); ``spacing_mm``: a tied plane's offset from its parent.
    """

    planes: dict
    points: dict
    given: dict
    ties: dict
    spacing_mm: dict
    where: Section


def read_cell_features(sec: Section) -> CellFeatures:
    """The config's ``features:`` section (docs/virtual_robot.md, "Contact data")."""
    planes_sec, points_sec = sec.section("planes"), sec.section("points")
    specs, given, ties, spacing = {}, {}, {}, {}
    for name in list(planes_sec.data):
        item = _named(planes_sec, name)
        tied = item.has("parallel_to")
        if tied:
            specs[name] = {"parallel_to": item.get("parallel_to", "str"),
                           "spacing_mm": item.get("spacing_mm", "float", check=_finite)}
            ties[f"planes.{name}"], spacing[name] = specs[name]["parallel_to"], specs[name]["spacing_mm"]
        else:
            specs[name] = {"normal": np.asarray(unit_vector(item, "normal")),
                           "offset_mm": item.get("offset_mm", "float", check=_finite)}
        choices = PLANE_GIVEN if tied else PLANE_GIVEN[:2]
        given[f"planes.{name}"] = item.get("given", "str", default="tied" if tied else "unknown",
                                           check=one_of(*choices).problem)
        item.done()
    planes_sec.done()
    check_ties(planes_sec, specs, "parallel_to")
    planes = {name: _resolved(specs, name) for name in specs}
    points = {}
    for name in list(points_sec.data):
        item = _named(points_sec, name)
        points[name] = np.asarray(item.get("position_mm", "list", check=vector3_problem), dtype=float)
        kind = item.get("given", "str", default="unknown", check=one_of(*POINT_GIVEN).problem)
        given[f"points.{name}"] = kind
        if kind == "tied" or item.has("distance_to"):
            if kind != "tied":
                item.fail(item.path("distance_to"), "is read with given: tied only")
            ties[f"points.{name}"] = item.get("distance_to", "str")
        item.done()
    points_sec.done()
    check_ties(points_sec, {n: {"distance_to": ties.get(f"points.{n}")} for n in points}, "distance_to")
    return CellFeatures(planes, points, given, ties, spacing, sec)


def _named(parent: Section, name) -> Section:
    if not isinstance(name, str) or not FEATURE_NAME.match(name):
        parent.fail(parent.path(str(name)), f"a feature's name is letters, digits, '_', '.' or '-'; got {name!r}")
    return parent.section(name)


def _resolved(specs: dict, name: str) -> tuple[NDArray[np.float64], float]:
    spec = specs[name]
    if "normal" in spec:
        return spec["normal"], spec["offset_mm"]
    normal, offset = _resolved(specs, spec["parallel_to"])
    return normal, offset + spec["spacing_mm"]


def _finite(value: float) -> str | None:
    return None if np.isfinite(value) else "a finite number"


def read_contact_dataset(item: Section, cell: CellFeatures | None) -> dict:
    """One contact data set of ``datasets:`` (``plane:``, ``fixed:`` or ``distance:``), checked against the
    features."""
    noise = item.get("noise_mm", "float", default=0.01, check=range_check(0))
    if item.has("plane") or item.has("fixed"):
        key = "plane" if item.has("plane") else "fixed"
        counts = item.section(key)
        names = (cell.planes if key == "plane" else cell.points) if cell is not None else {}
        spec = {"kind": key, "noise_mm": noise, "counts": {}}
        for name in list(counts.data):
            if name not in names:
                counts.fail(counts.path(str(name)), f"names no {'plane' if key == 'plane' else 'point'} of "
                                                    f"features.{key}s ({', '.join(names) or 'none defined'})")
            spec["counts"][name] = counts.get(name, "int", check=range_check(1, 10**6, integer=True))
        counts.done()
        if not spec["counts"]:
            counts.fail(counts.where, "names no feature")
        if key == "plane":
            spec["flush"] = item.get("flush", "bool", default=False)
        return spec
    dist = item.section("distance")
    pairs = dist.get("pairs", "any", check=lambda v: None if v == "all" or (
        isinstance(v, int) and not isinstance(v, bool) and v >= 1) else "'all' or a number of random pairs >= 1")
    poses = dist.get("poses", "int", check=range_check(2, 10**6, integer=True))
    dist.done()
    if pairs != "all" and pairs > poses * (poses - 1) // 2:
        dist.fail(dist.path("pairs"), f"must be at most {poses * (poses - 1) // 2} (the pairs of {poses} poses); "
                                      f"got {pairs}")
    return {"kind": "distance", "noise_mm": noise, "pairs": pairs, "poses": poses}


# ------------------------------------------------------------------------------------------------ generators
def true_robot_in_base(vr) -> Robot:
    """The true robot with the virtual robot's base error folded into its base frame: its positions of the
    ACTUAL joints are the true tool tips in the base frame (``vr.true_positions`` of the commanded ones)."""
    t = vr.true
    return t.replace(base_rotation=vr.base_rotation @ t.base_rotation,
                     base_mm=vr.base_rotation @ t.base_mm + vr.base_mm)


def commanded_joints(vr, q_actual: NDArray[np.float64], q_start: NDArray[np.float64]) -> NDArray[np.float64]:
    """The commanded joints whose actual joints (compliance, gear errors) are ``q_actual`` ``(n, N)`` degrees,
    by fixed-point iteration from ``q_start`` (the errors change slowly with the joints)."""
    q = np.array(q_start, dtype=float)
    for _ in range(50):
        step = q_actual - vr.actual_joints(q)
        q += step
        if np.abs(step).max(initial=0.0) < 1e-12:
            break
    return q


def _newton(vr, tib: Robot, q: NDArray[np.float64], residual, steps: int = 4) -> NDArray[np.float64]:
    """A few minimum-norm Newton steps on the commanded joints: ``residual(tips) -> (values (n, k), rows (n, k, 3))``
    with ``d value / d tip = rows``; the true robot's Jacobian stands for the commanded joints' (the joint
    errors' own slope is small)."""
    q = q.copy()
    for _ in range(steps):
        values, rows = residual(vr.true_positions(q))
        jac = rows @ tib.jacobian(vr.actual_joints(q))               # (n, k, N)
        q -= np.einsum("nik,nk->ni", np.linalg.pinv(jac), values)
    return q


def _solved(vr, tib: Robot, seeds_cmd, targets, rotations=None):
    """Commanded joints putting the true tip on ``targets`` (and the tool z axis as in ``rotations``), and which
    rows the IK reached within the joint limits."""
    qa = vr.actual_joints(seeds_cmd)
    if rotations is None:
        res = tib.inverse(targets, qa, tol_mm=1e-7)
    else:
        poses = np.tile(np.eye(4), (len(targets), 1, 1))
        poses[:, :3, :3], poses[:, :3, 3] = rotations, targets
        res = tib.inverse_pose(poses, qa, tol_mm=1e-7, tol_deg=1e-6)
    q = commanded_joints(vr, res.q_deg, seeds_cmd)
    return q, res.success & vr.nominal.within_limits(q)


def _plane_args(plane) -> tuple[NDArray[np.float64], float]:
    if isinstance(plane, dict):
        normal = np.asarray(plane["normal"], dtype=float)
        return normal / np.linalg.norm(normal), float(plane["offset_mm"])
    normal, offset = plane
    normal = np.asarray(normal, dtype=float)
    return normal / np.linalg.norm(normal), float(offset)


def plane_touches(vr, planes: dict, counts: dict, rng: np.random.Generator, noise_mm: float, *, flush: bool = False,
                  ranges_deg: dict | None = None, fixed_deg: dict | None = None
                  ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Commanded joints whose TRUE tool tip touches each TRUE plane, ``counts[name]`` times.

    Parameters
    ----------
    vr : VirtualRobot
    planes : dict
        name -> ``(normal (3,), offset_mm)`` or ``{"normal": ..., "offset_mm": ...}``: the plane
        ``n . p = offset`` (base frame, mm; the normal is normalised).
    counts : dict
        name -> number of touches.
    rng : numpy.random.Generator
    noise_mm : float
        Standard deviation of the miss along the normal: the true tip lies ``N(0, noise_mm)`` off the plane.
    flush : bool
        The tool's z axis along the plane's normal (a flat face of the tool on the plane; the sign nearest
        the sampled orientation), else the sampled orientations (changed a little by the move).
    ranges_deg, fixed_deg : dict, optional
        Joint ranges ``{joint: (lo, hi)}`` and held joints ``{joint: deg}`` (1-based) of the samples.

    Returns
    -------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees, within the joint limits; the touches of each plane in turn.
    names : tuple of str, (n,)
        The plane each row touches.

    Raises
    ------
    UnreachableError
        A plane the arm cannot touch ``counts[name]`` times within its ranges (naming the plane).
    """
    tib, out_q, out_names = true_robot_in_base(vr), [], []
    for name, count in counts.items():
        normal, offset = _plane_args(planes[name])

        def near(tips, qa):
            ok = np.abs(tips @ normal - offset) < NEAR_PLANE_MM
            if flush:
                ok &= np.abs(tib.forward(qa)[:, :3, 2] @ normal) > np.cos(np.radians(45.0))
            return ok

        def targets(tips, qa, k):
            miss = rng.normal(0.0, noise_mm, k) if noise_mm > 0 else np.zeros(k)
            goal = tips - (tips @ normal - offset - miss)[:, None] * normal
            rot = _flush_rotations(tib.forward(qa)[:, :3, :3], normal) if flush else None
            return goal, rot, miss

        def residual(miss):
            return lambda tips: ((tips @ normal - offset - miss)[:, None], np.broadcast_to(normal, (len(tips), 1, 3)))

        q = _visits(vr, tib, count, near, targets, residual, rng, ranges_deg or {}, fixed_deg or {},
                    f"plane {name!r}")
        out_q.append(q)
        out_names += [name] * count
    return np.concatenate(out_q), tuple(out_names)


def fixed_point_visits(vr, points: dict, counts: dict, rng: np.random.Generator, noise_mm: float, *,
                       ranges_deg: dict | None = None, fixed_deg: dict | None = None
                       ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Commanded joints bringing the TRUE tool tip to each TRUE point from different orientations.

    ``points``: name -> position (3,) mm (base frame); ``counts``: name -> visits; the true tip lands
    ``N(0, noise_mm)`` off the point per axis. The orientations are those of random configurations near
    the point, each moved onto it. Returns the commanded joints ``(n, N)`` degrees and each row's point;
    an unreachable point raises :class:`~partcal.errors.UnreachableError` naming it. Other parameters as
    :func:`plane_touches`.
    """
    tib, out_q, out_names = true_robot_in_base(vr), [], []
    for name, count in counts.items():
        point = np.asarray(points[name], dtype=float)

        def near(tips, qa):
            return np.linalg.norm(tips - point, axis=1) < NEAR_POINT_MM

        def targets(tips, qa, k):
            miss = rng.normal(0.0, noise_mm, (k, 3)) if noise_mm > 0 else np.zeros((k, 3))
            return point + miss, None, miss

        def residual(miss):
            return lambda tips: (tips - point - miss, np.broadcast_to(np.eye(3), (len(tips), 3, 3)))

        q = _visits(vr, tib, count, near, targets, residual, rng, ranges_deg or {}, fixed_deg or {},
                    f"point {name!r}")
        out_q.append(q)
        out_names += [name] * count
    return np.concatenate(out_q), tuple(out_names)


def _visits(vr, tib, count, near, targets, residual, rng, ranges, fixed, what) -> NDArray[np.float64]:
    """``count`` commanded configurations: random candidates near a feature, moved onto it (IK on the true
    robot, the joint errors inverted, Newton steps), kept when within the limits and on the feature."""
    kept, tried = [], 0
    for _ in range(ROUNDS):
        cand = uniform_configurations(vr.nominal, max(4000, 100 * count), ranges, fixed, rng)
        tried += len(cand)
        qa = vr.actual_joints(cand) if len(cand) else cand
        close = np.flatnonzero(near(tib.positions(qa), qa)) if len(cand) else np.zeros(0, dtype=int)
        need = count - sum(len(k) for k in kept)
        pick = close[:2 * need]
        if pick.size == 0:
            continue
        goal, rot, miss = targets(tib.positions(qa[pick]), qa[pick], pick.size)
        q, ok = _solved(vr, tib, cand[pick], goal, rot)
        q = _newton(vr, tib, q, residual(miss))
        values, _ = residual(miss)(vr.true_positions(q))
        ok &= (np.abs(values).max(axis=1) < ON_FEATURE_MM) & vr.nominal.within_limits(q)
        kept.append(q[ok][:need])
        if sum(len(k) for k in kept) >= count:
            return np.concatenate(kept)[:count]
    found = sum(len(k) for k in kept)
    raise UnreachableError(f"{what}: the arm reached it {found} times of {count} asked from {tried} sampled "
                           f"configurations: out of reach within the joint ranges, or too near their edge")


def _flush_rotations(rotations: NDArray[np.float64], normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each orientation turned by the smallest rotation that lays its z axis along ``+-normal`` (the nearer)."""
    z = rotations[:, :, 2]
    want = np.where((z @ normal)[:, None] >= 0, normal, -normal)
    axis = np.cross(z, want)
    sin = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(sin, np.einsum("ij,ij->i", z, want))
    vec = np.where(sin[:, None] > 1e-15, axis / np.maximum(sin, 1e-300)[:, None] * angle[:, None], 0.0)
    return matrices_from_rotation_vectors(vec) @ rotations


def pair_distances(vr, q_deg: NDArray[np.float64], pairs: NDArray[np.intp], rng: np.random.Generator,
                   noise_mm: float) -> NDArray[np.float64]:
    """Measured distances between the TRUE tool tips of pose pairs, mm, ``(m,)``: ``|tip_a - tip_b|`` plus
    ``N(0, noise_mm)``. ``pairs`` ``(m, 2)`` holds 0-based rows of ``q_deg`` ``(n, N)`` (commanded, degrees)."""
    tips = vr.true_positions(q_deg)
    pairs = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    d = np.linalg.norm(tips[pairs[:, 0]] - tips[pairs[:, 1]], axis=1)
    return d + (rng.normal(0.0, noise_mm, len(d)) if noise_mm > 0 else 0.0)


def all_pairs(n: int) -> NDArray[np.intp]:
    """Every pair ``(i, j)``, ``i < j < n``, shape ``(n (n - 1) / 2, 2)``, in row order."""
    return np.column_stack(np.triu_indices(n, 1)).astype(np.intp)


def random_pairs(n: int, m: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """``m`` distinct random pairs ``(i, j)``, ``i < j < n``, shape ``(m, 2)``, in row order."""
    return all_pairs(n)[np.sort(rng.choice(n * (n - 1) // 2, size=m, replace=False))]


# ------------------------------------------------------------------------------------------------ a study's sets
def simulate_observations(study) -> dict[str, ObservationTable]:
    """Every contact data set of a study (``study.observations``), deterministic for its seed: each draws from
    its own stream (``SeedSequence(seed, spawn_key=(39, k))``), so the point data sets do not change."""
    out = {}
    vr = study.robot
    for k, (name, spec) in enumerate(study.observations.items(), start=1):
        rng = np.random.default_rng(np.random.SeedSequence(study.seed, spawn_key=(39, k)))
        out[name] = _dataset(vr, study, name, spec, rng)
        log.info("simulated %s: %d rows", name, len(out[name]))
    return out


def _dataset(vr, study, name: str, spec: dict, rng: np.random.Generator) -> ObservationTable:
    cell, noise = study.features, spec["noise_mm"]
    where = {"ranges_deg": study.ranges_deg, "fixed_deg": study.fixed_deg}
    if spec["kind"] in ("plane", "fixed"):
        q, names = [], []
        for feature, count in spec["counts"].items():      # one at a time: a refusal names the feature's key
            try:
                if spec["kind"] == "plane":
                    got = plane_touches(vr, cell.planes, {feature: count}, rng, noise, flush=spec["flush"], **where)
                else:
                    got = fixed_point_visits(vr, cell.points, {feature: count}, rng, noise, **where)
            except UnreachableError as exc:
                section = "planes" if spec["kind"] == "plane" else "points"
                cell.where.fail(f"{cell.where.where}.{section}.{feature}", f"{exc} (datasets.{name} asks for it)")
            q.append(got[0])
            names += got[1]
        q = np.concatenate(q)
        numbers = {"flush": np.ones(len(q))} if spec.get("flush") else {}
        return _table(q, (spec["kind"],) * len(q), None, numbers, {"feature": tuple(names)}, name)
    ranges, fixed = study.ranges_deg, study.fixed_deg
    poses = sample_configurations(vr.nominal, spec["poses"], ranges, fixed, rng)
    n = len(poses)
    pairs = all_pairs(n) if spec["pairs"] == "all" else random_pairs(n, spec["pairs"], rng)
    d = pair_distances(vr, poses, pairs, rng, noise)
    ids = tuple(f"p{i + 1}" for i in range(n)) + tuple(f"d{k + 1}" for k in range(len(pairs)))
    q = np.vstack([poses, poses[pairs[:, 0]]])
    nan = np.full(n, np.nan)
    return _table(q, ("pose",) * n + ("distance",) * len(pairs), ids,
                  {"distance_mm": np.concatenate([nan, d])},
                  {"to": ("",) * n + tuple(f"p{j + 1}" for j in pairs[:, 1])}, name)


def _table(q, kind, ids, numbers, texts, name) -> ObservationTable:
    n = len(q)
    return ObservationTable(q_deg=q, kind=kind, ids=ids or tuple(str(i + 1) for i in range(n)),
                            lines=tuple(range(1, n + 1)), source=name, numbers=numbers, texts=texts, name=name)


def cell_features(cell: CellFeatures, noise_mm: dict, rng: np.random.Generator) -> dict:
    """What the cell is given of its features, in the features YAML's shape (``docs/data.md``): ``unknown``
    planes and points as ``{}``; ``approximate`` planes turned by :data:`APPROXIMATE_DEG` and moved by
    :data:`APPROXIMATE_MM`; ``tied`` planes by their parent and spacing, ``tied`` points by the true
    distance to theirs; ``known`` points at their true position. ``noise_mm``: kind -> mm (> 0 kept)."""
    planes, points = {}, {}
    for name, (normal, offset) in cell.planes.items():
        given = cell.given[f"planes.{name}"]
        if given == "tied":
            planes[name] = {"parallel_to": cell.ties[f"planes.{name}"], "spacing_mm": cell.spacing_mm[name]}
        elif given == "approximate":
            axis = np.cross(normal, rng.standard_normal(3))
            turn = matrices_from_rotation_vectors(axis[None] / np.linalg.norm(axis) * np.radians(APPROXIMATE_DEG))[0]
            planes[name] = {"normal": [round(float(v), 9) for v in turn @ normal],
                            "offset_mm": round(offset + APPROXIMATE_MM * rng.choice([-1.0, 1.0]), 6)}
        else:
            planes[name] = {}
    for name, position in cell.points.items():
        given = cell.given[f"points.{name}"]
        if given == "known":
            points[name] = {"known_mm": [round(float(v), 6) for v in position]}
        elif given == "tied":
            other = cell.ties[f"points.{name}"]
            points[name] = {"distance_to": other,
                            "distance_mm": round(float(np.linalg.norm(position - cell.points[other])), 6)}
        else:
            points[name] = {}
    return {"planes": planes, "points": points, "noise_mm": {k: v for k, v in noise_mm.items() if v > 0}}


def truth(cell: CellFeatures | None, vr, spec: dict) -> dict:
    """A contact data set's truth (``<name>.truth.yaml``): the true planes and points, the noise, and the
    true robot's parameters (DH rows, origins, tool, base error)."""
    t = vr.true

    def floats(a):
        return [round(float(v), 9) for v in np.ravel(a)]

    robot = {"name": vr.nominal.name, "a_mm": floats(t.a_mm), "d_mm": floats(t.d_mm),
             "alpha_deg": floats(t.alpha_deg), "theta_offset_deg": floats(t.theta_offset_deg),
             "tool_mm": floats(t.tool_mm), "base_rotation": [floats(r) for r in vr.base_rotation],
             "base_mm": floats(vr.base_mm)}
    if t.origins is not None:
        robot["origins"] = [floats(o) for o in t.origins]
    return {"kind": spec["kind"], "noise_mm": spec["noise_mm"],
            "planes": {n: {"normal": floats(nv), "offset_mm": round(float(o), 9)}
                       for n, (nv, o) in (cell.planes.items() if cell else ())},
            "points": {n: {"position_mm": floats(p)} for n, p in (cell.points.items() if cell else ())},
            "true_robot": robot}


def write_contact_files(study, observations: dict, note) -> list[tuple[Path, Path]]:
    """Write each contact data set (``<name>.csv``, ``<name>.truth.yaml``) and the cell's ``features.yaml`` to
    temporary names in ``study.output``; return the (temporary, final) pairs for the caller to rename as one
    set. ``note(study, what)`` gives each file's heading comment."""
    pending = []
    noise: dict[str, float] = {}
    for name, table in observations.items():
        spec = study.observations[name]
        noise[spec["kind"]] = max(noise.get(spec["kind"], 0.0), spec["noise_mm"])
        tmp = study.output / f".{name}.csv.partial"
        pending.append((tmp, study.output / f"{name}.csv"))
        write_observations(table, tmp, comment=note(study, f"contact data set '{name}' ({spec['kind']})"))
        tmp = study.output / f".{name}.truth.yaml.partial"
        pending.append((tmp, study.output / f"{name}.truth.yaml"))
        _write_yaml(tmp, truth(study.features, study.robot, spec), note(study, f"the truth of '{name}'"))
    if study.features is not None:
        rng = np.random.default_rng(np.random.SeedSequence(study.seed, spawn_key=(39, 0)))
        tmp = study.output / ".features.yaml.partial"
        pending.append((tmp, study.output / "features.yaml"))
        _write_yaml(tmp, cell_features(study.features, noise, rng), note(study, "what the cell knows of its "
                    "planes and points (read_features, docs/data.md)"))
    return pending


def _write_yaml(path: Path, data: dict, comment: str) -> None:
    with atomic_write(path) as handle:
        for text in comment.splitlines():
            handle.write(f"# {text}\n")
        yaml.safe_dump(_plain(data), handle, sort_keys=False, default_flow_style=None, width=110)


def _plain(value):
    """Numpy scalars and arrays as plain Python numbers and lists (for safe YAML)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value
