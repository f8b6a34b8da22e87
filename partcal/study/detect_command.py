"""``partcal detect``: a folder of images and its joints CSV -> the camera rows ``partcal run`` identifies from.

The board and the camera come from the cell's ``boards:`` and ``cameras:`` (the same file the run reads), so the
detection uses the geometry the identification will: the board's type, counts and sizes, the camera's image size.
"""

from __future__ import annotations

from pathlib import Path

from ..data.detect import detect_folder, write_pixel_rows
from ..data.measurement_rows import read_cell
from ..errors import DataError
from .config import robot_named


def _one(cell: dict, section: str, name: str | None, option: str, path) -> str:
    """The entry of the cell's ``section`` that ``name`` names, or its only one."""
    entries = cell.get(section) or {}
    if name is None:
        if len(entries) != 1:
            raise DataError(f"{path}: {section}: {len(entries)} entries ({', '.join(entries) or 'none'}); expected "
                            f"one, or name it with {option}")
        return next(iter(entries))
    if name not in entries:
        raise DataError(f"{option} {name}: not among {path}'s {section}: ({', '.join(entries) or 'none'})")
    return name


def detect_images(images, joints, cell, robot, output, *, camera: str | None = None,
                  board: str | None = None) -> list[str]:
    """Detect the cell's board in every image of the folder ``images``, pair each with its row of ``joints``
    (``image, q1..qN``) and write the camera rows to ``output`` (atomically); the lines to print.

    An image where no board is found is named (on stderr, through the log) and left out; the others keep their own
    joints. Raises :class:`DataError` naming the file, line or image (see :func:`partcal.data.detect.detect_folder`)
    and when the cell has several cameras or boards and the option does not choose one."""
    sections = read_cell(cell)
    camera = _one(sections, "cameras", camera, "--camera", cell)
    board = _one(sections, "boards", board, "--board", cell)
    if not Path(images).is_dir():
        raise DataError(f"{images}: not a folder of images")
    found = detect_folder(images, joints, robot_named(robot), sections["boards"][board], camera, board,
                          image_size=sections["cameras"][camera].get("image_size"))
    write_pixel_rows(found, output)
    rows = found.rows
    seen = len(set(rows.texts["image"]))
    lines = [f"camera {camera}, board {board}: {len(rows)} points in {seen} images "
             f"({len(rows) / seen:.1f} an image)"]
    if found.not_found:
        lines.append(f"no board found in {len(found.not_found)} images (left out): {', '.join(found.not_found)}")
    return lines + [f"wrote {output}"]
