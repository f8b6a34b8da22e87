"""Atomic file writing: outputs appear complete or not at all."""

from __future__ import annotations

import os
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import PartcalError


@contextmanager
def atomic_write(path: str | Path, mode: str = "w", **kwargs):
    """Open a temporary file beside ``path``; rename it over ``path`` on success.

    If the block raises, the temporary file is removed and ``path`` keeps its
    previous content.
    """
    if str(path).endswith(("/", os.sep)) or Path(path).is_dir():
        raise PartcalError(f"{path}: is a folder; give the name of a file to write")
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise PartcalError(f"{path}: cannot write here: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, mode, **kwargs) as handle:
            yield handle
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def exit_cleanly_on_sigterm() -> None:
    """Make SIGTERM (``kill``, a cell controller or a job scheduler stopping a run) raise ``SystemExit(143)``.

    Python's default for SIGTERM ends the process at once, so no ``finally`` runs and a file half-written by
    :func:`atomic_write` stays behind as a hidden ``.NAME.tmp`` (20 MB for a large run's predictions). As an
    exception, the termination removes the temporary files and leaves every finished output as it was.
    Call it once, from the main thread of a program.
    """
    def stop(signum, frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, stop)


def check_folder_writable(folder: str | Path) -> None:
    """Fail early, before long work, if files cannot be created in ``folder``; the folders made to find out
    are removed again (a run refused later leaves no empty folder)."""
    with made_folder(folder, keep=False):
        pass


@contextmanager
def made_folder(folder: str | Path, *, keep: bool = True):
    """``folder`` made (with its missing parents) and probed for writing; the folders made here are removed
    again if the block raises (or, ``keep=False``, always), as long as they are empty."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise PartcalError(f"{folder}: exists and is not a folder")
    made = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise PartcalError(f"{folder}: cannot write here ({exc.strerror or exc})") from None
        yield folder
    except BaseException:
        _remove_empty(made)
        raise
    if not keep:
        _remove_empty(made)


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first) while they are empty."""
    for path in folders:
        try:
            path.rmdir()
        except OSError:
            return


def replace_all(pairs: list[tuple[Path, Path]]) -> None:
    """Rename every finished temporary file over its target, after all of them were written.

    Callers write each file to a temporary name first; only when all exist are
    they renamed, so a failure while writing leaves every old file as it was.
    """
    for _, path in pairs:          # what would stop a rename is found before the first one
        if Path(path).is_dir():
            raise PartcalError(f"{path}: is a folder; cannot replace it with a file (no file was changed)")
    for tmp, path in pairs:
        try:
            os.replace(tmp, path)
        except OSError as exc:
            raise PartcalError(f"{path}: cannot write ({exc.strerror or exc})") from None


def refuse_input_as_output(output, command: str, inputs) -> None:
    """Refuse an output ``-o`` naming one of the command's input files (``inputs``: pairs of what it is and
    its path).

    Writing there would replace the input (a raw export, the model file) with
    the output; the same file under another name (a link) counts too.
    """
    if output is None or not Path(output).exists():
        return
    for what, path in inputs:
        if path is not None and Path(path).exists() and os.path.samefile(output, path):
            raise PartcalError(f"{command}: -o {output} is the {what} ({path}); writing there would replace an "
                               "input, so name another file")
