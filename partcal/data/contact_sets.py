"""A virtual cell's contact data sets: its cell (``cell:``), the data sets that touch them
(``datasets: NAME: {plane: ...}``, ``{fixed: ...}``, ``{distance: ...}``), their tables, truth and the
cell YAML the cell is given.

:func:`read_true_cell` and :func:`read_contact_dataset` read the config's sections,
:func:`simulate_observations` makes a study's contact sets with the generators of
:mod:`partcal.data.simulate_contacts`, :func:`given_cell` is what the cell knows of its cell
(the cell YAML of ``docs/data.md``), and :func:`write_contact_files` writes it all. See
``docs/virtual_robot.md``, "Contact data".
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from .._io import atomic_write
from .._validation import one_of
from .._yamlio import Section, range_check
from ..errors import UnreachableError
from ..robot.rotations import matrices_from_rotation_vectors
from ..calibration.cell import FEATURE_NAME, check_ties, unit_vector, vector3_problem
from ..calibration.measurement import MeasurementRows
from ..calibration.registry import MEASUREMENT_TYPES
from .measurement_rows import write_measurement_rows
from .sampling import sample_configurations
from .simulate_contacts import all_pairs, fixed_point_visits, pair_distances, plane_touches, random_pairs

log = logging.getLogger(__name__)
BUILT_IN_KEYS = ("plane", "fixed", "distance")
"""The measurement types whose data sets this module simulates itself (the generators of
:mod:`partcal.data.simulate_contacts`)."""


def contact_keys() -> tuple[str, ...]:
    """The keys of a contact data set in a virtual-robot config's ``datasets:``: the built-in ones, and every
    measurement type with a ``simulate`` hook (:class:`~partcal.calibration.measurement.MeasurementType`)."""
    return (*BUILT_IN_KEYS, *(k for k, cls in MEASUREMENT_TYPES.items() if cls.simulate is not None
                              and k not in BUILT_IN_KEYS))


def _hooked_sections() -> dict[str, type]:
    """The cell sections of the types with a ``simulate`` hook beyond the planes and points: section -> type."""
    return {section: cls for k, cls in MEASUREMENT_TYPES.items() if cls.simulate is not None
            for section in (cls.cell_section, *cls.extra_sections) if section and section not in ("planes", "points")}


@dataclass(frozen=True)
class Truth:
    """What a measurement type's ``simulate`` hook reads of the virtual robot: the true tool (position and
    orientation, base frame) at commanded joints, joint configurations drawn within the config's ranges, and the
    true cell (each type's own section as the config gives it)."""

    robot: object
    ranges_deg: dict
    fixed_deg: dict
    cell: dict

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` commanded joint configurations (n, N) deg within the config's ranges and the joint limits."""
        return sample_configurations(self.robot.nominal, n, self.ranges_deg, self.fixed_deg, rng)

    def positions(self, q_deg) -> NDArray[np.float64]:
        """The true tool tip (n, 3) mm in the base frame at commanded joints ``q_deg`` (n, N) deg."""
        return self.robot.true_positions(np.asarray(q_deg, dtype=float))

    def rotations(self, q_deg) -> NDArray[np.float64]:
        """The true tool orientation (n, 3, 3) in the base frame at commanded joints ``q_deg``."""
        return self.robot.true_flange(np.asarray(q_deg, dtype=float))[1]
PLANE_GIVEN = ("unknown", "approximate", "tied")
POINT_GIVEN = ("unknown", "known", "tied")
APPROXIMATE_DEG, APPROXIMATE_MM = 0.5, 1.0
"""A plane ``given: approximate`` is written turned by this angle and moved by this offset (random directions,
seeded): a drawing's values, not the truth."""


@dataclass(frozen=True)
class TrueCell:
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
    sections: dict = None       # the true sections of types with a simulate hook, as the config gives them


def read_true_cell(sec: Section) -> TrueCell:
    """The config's ``cell:`` section (docs/virtual_robot.md, "Contact data")."""
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
        measurement = item.get("given", "str", default="unknown", check=one_of(*POINT_GIVEN).problem)
        given[f"points.{name}"] = measurement
        if measurement == "tied" or item.has("distance_to"):
            if measurement != "tied":
                item.fail(item.path("distance_to"), "is read with given: tied only")
            ties[f"points.{name}"] = item.get("distance_to", "str")
        item.done()
    points_sec.done()
    check_ties(points_sec, {n: {"distance_to": ties.get(f"points.{n}")} for n in points}, "distance_to")
    sections = {name: dict(sec.get(name, "map")) for name in _hooked_sections() if sec.has(name)}
    return TrueCell(planes, points, given, ties, spacing, sec, sections)


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


def read_contact_dataset(item: Section, cell: TrueCell | None) -> dict:
    """One contact data set of ``datasets:`` (``plane:``, ``fixed:`` or ``distance:``), checked against the
    cell."""
    item.renamed("noise_mm", "noise")
    noise = item.get("noise", "float", default=0.01, check=range_check(0))
    hooked = [k for k in contact_keys() if k not in BUILT_IN_KEYS and item.has(k)]
    if hooked:                  # a type's own hook simulates it: its mapping is the hook's to read
        return {"type": hooked[0], "noise": noise, "params": dict(item.get(hooked[0], "map"))}
    if item.has("plane") or item.has("fixed"):
        key = "plane" if item.has("plane") else "fixed"
        counts = item.section(key)
        names = (cell.planes if key == "plane" else cell.points) if cell is not None else {}
        spec = {"type": key, "noise": noise, "counts": {}}
        for name in list(counts.data):
            if name not in names:
                counts.fail(counts.path(str(name)), f"names no {'plane' if key == 'plane' else 'point'} of "
                                                    f"cell.{key}s ({', '.join(names) or 'none defined'})")
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
    return {"type": "distance", "noise": noise, "pairs": pairs, "poses": poses}


def simulate_observations(study) -> dict[str, MeasurementRows]:
    """Every contact data set of a study (``study.observations``), deterministic for its seed: each draws from
    its own stream (``SeedSequence(seed, spawn_key=(39, k))``), so the point data sets do not change."""
    out = {}
    vr = study.robot
    for k, (name, spec) in enumerate(study.observations.items(), start=1):
        rng = np.random.default_rng(np.random.SeedSequence(study.seed, spawn_key=(39, k)))
        out[name] = _dataset(vr, study, name, spec, rng)
        log.info("simulated %s: %d rows", name, len(out[name]))
    return out


def _dataset(vr, study, name: str, spec: dict, rng: np.random.Generator) -> MeasurementRows:
    cell, noise = study.cell, spec["noise"]
    if spec["type"] not in BUILT_IN_KEYS:
        truth = Truth(vr, study.ranges_deg, study.fixed_deg, dict((cell.sections or {}) if cell else {}))
        table = MEASUREMENT_TYPES[spec["type"]].simulate(truth, spec["params"], rng, noise)
        return _table(table.q_deg, table.types, table.ids, table.numbers, table.texts, name)
    where = {"ranges_deg": study.ranges_deg, "fixed_deg": study.fixed_deg}
    if spec["type"] in ("plane", "fixed"):
        q, names = [], []
        for feature, count in spec["counts"].items():      # one at a time: a refusal names the feature's key
            try:
                if spec["type"] == "plane":
                    got = plane_touches(vr, cell.planes, {feature: count}, rng, noise, flush=spec["flush"], **where)
                else:
                    got = fixed_point_visits(vr, cell.points, {feature: count}, rng, noise, **where)
            except UnreachableError as exc:
                section = "planes" if spec["type"] == "plane" else "points"
                cell.where.fail(f"{cell.where.where}.{section}.{feature}", f"{exc} (datasets.{name} asks for it)")
            q.append(got[0])
            names += got[1]
        q = np.concatenate(q)
        numbers = {"flush": np.ones(len(q))} if spec.get("flush") else {}
        return _table(q, (spec["type"],) * len(q), None, numbers, {"feature": tuple(names)}, name)
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


def _table(q, measurement, ids, numbers, texts, name) -> MeasurementRows:
    n = len(q)
    return MeasurementRows(q_deg=q, types=measurement, ids=ids or tuple(str(i + 1) for i in range(n)),
                            lines=tuple(range(1, n + 1)), source=name, numbers=numbers, texts=texts, name=name)


def given_cell(cell: TrueCell, noise: dict, rng: np.random.Generator) -> dict:
    """What the cell is given of its cell, in the cell YAML's shape (``docs/data.md``): ``unknown``
    planes and points as ``{}``; ``approximate`` planes turned by :data:`APPROXIMATE_DEG` and moved by
    :data:`APPROXIMATE_MM`; ``tied`` planes by their parent and spacing, ``tied`` points by the true
    distance to theirs; ``known`` points at their true position. ``noise``: type -> its noise (> 0 kept)."""
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
    others = {section: cls.given_section(cell.sections[section], rng) if section == cls.cell_section else
              cls.given_extra_section(section, cell.sections[section], rng)
              for section, cls in _hooked_sections().items() if section in (cell.sections or {})}
    return {"planes": planes, "points": points, **others, "noise": {k: v for k, v in noise.items() if v > 0}}


def truth(cell: TrueCell | None, vr, spec: dict) -> dict:
    """A contact data set's truth (``<name>.truth.yaml``): the true planes and points, the true sections of types
    with a ``simulate`` hook (a camera's poses and intrinsics), the noise, and the true robot's parameters (DH rows, origins, tool, base error)."""
    t = vr.true

    def floats(a):
        return [round(float(v), 9) for v in np.ravel(a)]

    robot = {"name": vr.nominal.name, "a_mm": floats(t.a_mm), "d_mm": floats(t.d_mm),
             "alpha_deg": floats(t.alpha_deg), "theta_offset_deg": floats(t.theta_offset_deg),
             "tool_mm": floats(t.tool_mm), "base_rotation": [floats(r) for r in vr.base_rotation],
             "base_mm": floats(vr.base_mm)}
    if t.origins is not None:
        robot["origins"] = [floats(o) for o in t.origins]
    return {"type": spec["type"], "noise": spec["noise"],
            "planes": {n: {"normal": floats(nv), "offset_mm": round(float(o), 9)}
                       for n, (nv, o) in (cell.planes.items() if cell else ())},
            "points": {n: {"position_mm": floats(p)} for n, p in (cell.points.items() if cell else ())},
            **({"sections": cell.sections} if cell is not None and cell.sections else {}),
            "true_robot": robot}


def write_contact_files(study, observations: dict, note) -> list[tuple[Path, Path]]:
    """Write each contact data set (``<name>.csv``, ``<name>.truth.yaml``) and the cell's ``cell.yaml`` to
    temporary names in ``study.output``; return the (temporary, final) pairs for the caller to rename as one
    set. ``note(study, what)`` gives each file's heading comment."""
    pending = []
    noise: dict[str, float] = {}
    for name, table in observations.items():
        spec = study.observations[name]
        noise[spec["type"]] = max(noise.get(spec["type"], 0.0), spec["noise"])
        tmp = study.output / f".{name}.csv.partial"
        pending.append((tmp, study.output / f"{name}.csv"))
        write_measurement_rows(table, tmp, comment=note(study, f"contact data set '{name}' ({spec['type']})"))
        tmp = study.output / f".{name}.truth.yaml.partial"
        pending.append((tmp, study.output / f"{name}.truth.yaml"))
        _write_yaml(tmp, truth(study.cell, study.robot, spec), note(study, f"the truth of '{name}'"))
        if (spec.get("params") or {}).get("render"):
            pending += _image_files(study, name, table)
    if study.cell is not None:
        rng = np.random.default_rng(np.random.SeedSequence(study.seed, spawn_key=(39, 0)))
        tmp = study.output / ".cell.yaml.partial"
        pending.append((tmp, study.output / "cell.yaml"))
        _write_yaml(tmp, given_cell(study.cell, noise, rng), note(study, "what the cell knows of its "
                    "planes and points (read_cell, docs/data.md)"))
    return pending


def _image_files(study, name: str, table: MeasurementRows) -> list[tuple[Path, Path]]:
    """A camera data set's images (``render: true``) in ``<name>_images/<camera>/``, each file written to a
    temporary name: the folder ``partcal detect`` reads, one image per image of the rows with its joints CSV.
    Rendered from their own stream (``spawn_key=(41, k)``): the rows do not change."""
    from .boards import image_files          # OpenCV, imported only when images are rendered
    k = list(study.observations).index(name) + 1
    rng = np.random.default_rng(np.random.SeedSequence(study.seed, spawn_key=(41, k)))
    pending = []
    for relative, data in image_files(table, study.cell.sections, study.robot.true_flange, rng).items():
        final = study.output / f"{name}_images" / relative
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = final.with_name(f".{final.name}.partial")
        tmp.write_bytes(data)
        pending.append((tmp, final))
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
