"""The exception hierarchy: every user error is a :class:`PartcalError`; and warnings held back as texts.

User errors (bad files, bad parameters, bad arrays) subclass ``ValueError`` so
that code written for scikit-learn conventions keeps working; the command
line turns any of them into exit code 2 and one line on stderr.
:func:`held_warnings` holds a block's warnings so that a run says each once, in
its own words; :func:`log_to_stderr` prints partcal's messages in one format, each once (the command
line's choice of what is shown).
"""

from __future__ import annotations

import logging
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager


class PartcalError(ValueError):
    """Base class of every error caused by the user's input."""


class DataError(PartcalError):
    """A measurement file or array is malformed (names file, row and column)."""


class ConfigError(PartcalError):
    """A YAML file (run config, robot, virtual robot) is malformed."""


class RobotFileError(ConfigError):
    """A robot description (a URDF) is malformed or does not hold the chain asked for (names the file, the
    element and its line, and what was expected)."""


class UnreachableError(PartcalError):
    """Inverse kinematics found no joint angles for one or more targets.

    Attributes
    ----------
    indices : list of int
        0-based indices of the targets that were not reached.
    distances_mm : list of float
        Remaining position error of each of those targets, in mm.
    """

    def __init__(self, message: str, indices=(), distances_mm=()):
        super().__init__(message)
        self.indices = list(indices)
        self.distances_mm = list(distances_mm)


class ModelFileError(PartcalError):
    """A model file is damaged, foreign, or of an unsupported version."""


@contextmanager
def held_warnings(*, exclusive: bool = False) -> Iterator[list[str]]:
    """Collect partcal's log warnings and Python warnings of a block (a list of texts, in order), printing none.

    With ``exclusive`` the block's warnings reach no handler already on partcal's logger, not even the
    collector of an enclosing ``held_warnings``: the enclosing block hears of them only as the caller
    words them (the spread calibration's fits, held inside a model's fit, say).
    """
    said: list[str] = []

    class Hold(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            said.append(record.getMessage())

    logger, handler = logging.getLogger("partcal"), Hold(logging.WARNING)
    handlers, propagate = logger.handlers[:], logger.propagate
    logger.handlers = [handler] if exclusive else handlers + [handler]
    logger.propagate = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("ignore", RuntimeWarning)      # numbers are checked, never warned about
            yield said
        said += [str(w.message) for w in caught]
    finally:
        logger.handlers, logger.propagate = handlers, propagate


class _Stderr(logging.StreamHandler):
    """partcal's messages on stderr in one format (``partcal: warning: ...``), each once: a warning repeated by
    every fold or data set is said one time."""

    def __init__(self):
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if text in self.seen:
            return False
        self.seen.add(text)
        return super().filter(record)

    def format(self, record: logging.LogRecord) -> str:
        where = f" {record.name}" if record.levelno < logging.WARNING else ""
        return f"partcal: {record.levelname.lower()}{where}: {record.getMessage()}"


_HANDLER = _Stderr()


def log_to_stderr(level: int) -> None:
    """Log records at ``level`` and above on stderr (the one at the time of the call), each message once
    (``partcal: warning: ...``); other libraries' debug chatter stays at INFO and above."""
    _HANDLER.stream = sys.stderr
    _HANDLER.seen.clear()
    root = logging.getLogger()
    if _HANDLER not in root.handlers:
        root.addHandler(_HANDLER)
    root.setLevel(level)
    for name in ("matplotlib", "PIL", "asyncio", "urllib3"):
        logging.getLogger(name).setLevel(max(level, logging.INFO))
