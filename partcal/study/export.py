"""``partcal export``: the calibrated robot of a kinematic model file, in the forms a cell reads.

From a model file of kind ``kinematic`` (hybrids too) it writes the
identified geometry (:mod:`partcal.robot.export` does the writing):

- ``<name>.urdf``: the calibrated chain, joint offsets folded into the joint
  origins, the identified base pose as the fixed joint ``world -> base_link``
  and the tool point, turned by the tool's identified turn, as ``flange -> tcp``; identified cameras and boards
  (camera rows) as fixed links, ``NAME_optical_frame`` and ``NAME_board``, from ``world`` (in the cell) or
  ``flange``;
- ``<name>_ur_kinematics.yaml``: ur_description's ``default_kinematics.yaml``
  (UR-shaped six-joint chains turned by q1..q6), with the TCP it needs in
  ``tool0``, position and rotation, in its header (the file has no tool);
- ``<name>_dh.csv``: the DH table, when the identified chain is one (DH
  parametrization of a DH robot);
- ``<name>_robot.yaml``: partcal's own robot YAML of the calibrated chain.

What geometry cannot carry (compliance, transmission harmonics, a residual
model; the tool's turn in the files whose tool is a point) is named in one
line, with the RMS of the exported geometry beside the full model's on a data
set when one is given. An export that can write nothing is refused.
"""

from __future__ import annotations

import csv
import hashlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from ..data.formats import load_format
from ..data.measurements import read_measurements
from ..errors import PartcalError
from ..metrics import pooled_rms
from ..calibration.camera_cell import mounted_frames
from ..calibration.parameters import geometric_size, own_geometry
from ..models.kinematic import KinematicModel
from ..robot.description import robot_to_dict
from ..robot.export import ExportError, dh_rows, transform, ur_kinematics_from_robot, urdf_from_robot
from ..robot.kinematics import Robot, matrix_from_euler_deg
from ..robot.rotations import matrices_from_rotation_vectors
from .persist import load_model

FORMATS = ("urdf", "ur", "dh", "yaml")


@dataclass(frozen=True)
class Exported:
    """What :func:`export_model` wrote (``files``: format -> path), what it could not (``skipped``: format ->
    why), and what the geometry leaves out and, with data, what it leaves on them (``not_carried``: one line,
    empty when there is nothing to say)."""

    files: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    not_carried: str = ""
    tcp_mm: NDArray[np.float64] | None = None
    tcp_text: str = ""            # the UR TCP, position and rotation, as the controller takes it (one line)

    def lines(self) -> list[str]:
        """What ``partcal export`` prints: each file written or not, the UR tool centre point, what is not
        carried."""
        out = [f"{fmt}: {path}" for fmt, path in self.files.items()]
        out += [f"{fmt}: not written: {why}" for fmt, why in self.skipped.items()]
        if self.tcp_text:
            out.append("ur: the kinematics file has no tool; set the tool centre point in tool0 on the controller: "
                       f"{self.tcp_text}")
        return out + ([self.not_carried] if self.not_carried else [])


def calibrated_geometry(model: KinematicModel) -> tuple[Robot, NDArray[np.float64]]:
    """The identified chain in the robot's own base frame, and its base pose ``(4, 4)`` (mm) in the measurement
    frame (the identified base correction: ``Rz Ry Rx`` turn, then the shift)."""
    values = model.identification_.value
    size = geometric_size(model.robot_, model.parametrization_)
    robot = own_geometry(model.robot_, values, model.parametrization_)
    return robot, transform(matrix_from_euler_deg(values[size - 3:size]), values[size - 6:size - 3])


def tool_turn(model: KinematicModel) -> NDArray[np.float64] | None:
    """The identified turn ``(3, 3)`` of the tool (reflector, probe) in the flange frame, None when the
    identification did not turn it (``probe.rx``, ``probe.ry``, ``probe.rz``: a rotation vector, degrees)."""
    if not model.orientation_:
        return None
    names = list(model.identification_.names)
    rotvec_deg = model.identification_.value[[names.index(f"probe.r{c}") for c in "xyz"]]
    return matrices_from_rotation_vectors(np.radians(rotvec_deg))[0]


def left_out(model: KinematicModel) -> str:
    """The one line naming what a geometric file cannot carry of ``model`` (empty when nothing)."""
    parts = []
    errors = model.joint_errors_
    if errors.compliance:
        parts.append("the gravity compliance of joint" + ("s " if len(errors.compliance) > 1 else " ")
                     + ", ".join(map(str, errors.compliance)))
    if any(errors.harmonics):
        parts.append(f"transmission harmonics (up to {max(errors.harmonics)} per joint)")
    if model.residual_ is not None:
        parts.append(f"the residual model ({model.residual_.describe()})")
    return "not carried by the geometric files: " + "; ".join(parts) if parts else ""


def export_model(model_path, output: Path, formats=FORMATS, q_deg=None, errors_mm=None) -> Exported:
    """Write the calibrated robot of a kinematic model file into the folder ``output``.

    Parameters
    ----------
    model_path : str or Path
        A model file of kind ``kinematic``.
    output : Path
        The folder (created if missing).
    formats : sequence of {"urdf", "ur", "dh", "yaml"}
    q_deg, errors_mm : ndarray, shapes (n, N) and (n, 3), optional
        A data set (joints, measured errors in the base frame, mm): the line on
        what is not carried then gives the RMS the exported geometry and the
        full model leave on it.
    """
    model, doc = load_model(model_path)
    if not isinstance(model, KinematicModel):
        raise PartcalError(f"{model_path}: a model of kind {doc.get('kind')!r} has no robot geometry to export; "
                           "export reads models of kind 'kinematic'")
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise PartcalError(f"export format {unknown[0]!r}: expected one of {', '.join(FORMATS)}")
    robot, base_pose = calibrated_geometry(model)
    name = Path(model_path).stem
    output = Path(output)
    below = next(f for f in (output, *output.parents) if f.exists() or f == f.parent)
    if not below.is_dir():
        raise PartcalError(f"{output}: {below} is a file; export -o expects a folder (new or existing)")
    stamp = (f"Calibrated {model.robot_.name} from {Path(model_path).name} ({model.parametrization_} "
             "parametrization), written by partcal export.")
    texts, files, skipped, tcp, tcp_text, turn = {}, {}, {}, None, "", tool_turn(model)
    links = [(link, "world" if mount == "cell" else "flange", pose)
             for link, mount, pose in mounted_frames(model.identification_.names, model.identification_.value)]
    writers = {"urdf": lambda: (f"{name}.urdf", urdf_from_robot(robot, base_pose, comment=stamp, tool_rotation=turn,
                                                               fixed_links=links)),
               "yaml": lambda: (f"{name}_robot.yaml", _robot_yaml(robot, stamp)),
               "dh": lambda: (f"{name}_dh.csv", _dh_csv(robot))}
    for fmt in formats:
        try:
            if fmt == "ur":
                ur = ur_kinematics_from_robot(robot, turn)
                tcp, tcp_text = ur.tcp_mm, ur.tcp_text()
                text = ur.yaml_text(_hash(ur.joints), _ur_comment(stamp, ur))
                filename = f"{name}_ur_kinematics.yaml"
            else:
                filename, text = writers[fmt]()
        except ExportError as exc:
            skipped[fmt] = str(exc)
            continue
        texts[fmt] = (filename, text)
    if not texts:                          # nothing to write: say why, and leave no empty folder behind
        raise ExportError(f"export: nothing written for {model_path}: "
                          + "; ".join(f"{fmt}: {why}" for fmt, why in skipped.items()))
    output.mkdir(parents=True, exist_ok=True)
    for fmt, (filename, text) in texts.items():
        with atomic_write(output / filename) as handle:
            handle.write(text)
        files[fmt] = output / filename
    note = left_out(model)
    if q_deg is not None:
        note = _on_data(model, note, q_deg, errors_mm)
    pointless = [f for f in ("yaml", "dh") if f in files]
    if turn is not None and pointless:        # their tool is a point: say what they leave out
        angle = np.degrees(np.arccos(np.clip((np.trace(turn) - 1.0) / 2.0, -1.0, 1.0)))
        note += ("; " if note else "") + (f"the tool's identified turn ({angle:.4f} deg) is not carried by "
                                          f"{' and '.join(files[f].name for f in pointless)} (a tool point only; "
                                          "the URDF and the UR TCP carry it)")
    return Exported(files, skipped, note, tcp, tcp_text)


def _on_data(model: KinematicModel, note: str, q_deg, errors_mm) -> str:
    """The line on what the exported geometry leaves on a data set (joints (n, N) deg, measured errors (n, 3)
    mm): its 3-D RMS beside the full model's (when the geometry leaves something out, ``note``) and the
    uncompensated one, with a warning where the geometry alone is worse than no calibration."""
    geometry = model.identified_robot_.positions(q_deg) - model.robot_.positions(q_deg)
    left, before = pooled_rms(errors_mm - geometry), pooled_rms(errors_mm)
    figures = f"on the {len(q_deg)} poses given: 3-D RMS left {left:.3f} mm by the exported geometry"
    if note:
        figures += f", {pooled_rms(errors_mm - model.predict(q_deg)[:, :3]):.3f} mm by the full model"
    figures += f", {before:.3f} mm uncompensated"
    if left > before:
        figures += ("; the exported geometry alone makes these poses worse than no calibration: use the full model "
                    "(partcal compensate), not the exported files")
    return f"{note} ({figures})" if note else figures


def export_files(model_path, output: str | Path, formats=None, *, data=None, fmt=None) -> Exported:
    """``partcal export``: :func:`export_model` (``formats`` None: every one of :data:`FORMATS` the chain
    allows, the others in ``skipped`` with the reason) with the poses and errors of the measurement file
    ``data`` (its format YAML ``fmt``), read against the model's robot, when one is given."""
    q = errors = None
    if data:
        robot = load_model(model_path)[0].robot_
        measured = read_measurements(data, robot, fmt=load_format(fmt) if fmt else None)
        q, errors = measured.q_deg, measured.errors_mm
    return export_model(model_path, Path(output), FORMATS if formats is None else tuple(formats), q, errors)


def _robot_yaml(robot: Robot, stamp: str) -> str:
    import yaml

    spec = robot_to_dict(robot)
    spec["description"] = stamp
    return yaml.safe_dump(spec, sort_keys=False)


def _dh_csv(robot: Robot) -> str:
    rows = dh_rows(robot)
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    out.write(f"# tool_mm,{','.join(repr(float(v)) for v in robot.tool_mm)}\n")
    return out.getvalue()


def _hash(joints: dict) -> str:
    """A tag for the file's ``hash`` field: ``calib_partcal_`` and 16 hex digits of its numbers."""
    text = repr(sorted((k, sorted(v.items())) for k, v in joints.items()))
    return "calib_partcal_" + hashlib.sha256(text.encode()).hexdigest()[:16]


def _ur_comment(stamp: str, ur) -> str:
    return (f"{stamp}\nur_description's kinematics parameters: per joint the origin from the parent link, "
            "translation x, y, z (metres) then\nrotation Rz(yaw) Ry(pitch) Rx(roll) (radians, fixed axes), then the "
            "joint's turn about z. The chain starts in\nbase_link_inertia (partcal's robot base frame; base_link is "
            "turned by 180 degrees about z from it).\nThe hash is partcal's own tag, not the controller's calibration "
            "checksum.\nThis file has no tool: set the tool centre point in tool0 on the controller, position and "
            f"rotation:\n{ur.tcp_text()}.")
