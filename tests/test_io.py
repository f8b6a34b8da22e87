"""Atomic writing: outputs appear whole or not at all, also when the process is terminated."""

import os
import signal
import subprocess
import sys

import pytest

from partcal import PartcalError
from partcal._io import atomic_write

WRITER = """
import sys, time
from partcal._io import atomic_write, exit_cleanly_on_sigterm
if sys.argv[2] == "clean":
    exit_cleanly_on_sigterm()
with atomic_write(sys.argv[1]) as handle:
    handle.write("half of it")
    handle.flush()
    print("writing", flush=True)
    time.sleep(60)
"""


@pytest.mark.parametrize("clean", [True, False])
def test_a_terminated_write_leaves_the_old_file_and_no_temporary_one(tmp_path, clean):
    """SIGTERM in the middle of a write: with the command line's handler the old content stays and no hidden
    temporary file is left; Python's default (the control) leaves the temporary file behind."""
    target = tmp_path / "predictions.csv"
    target.write_text("old")
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(target), "clean" if clean else "default"],
                             stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "writing"
    child.send_signal(signal.SIGTERM)
    code = child.wait(timeout=30)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert target.read_text() == "old"
    if clean:
        assert code == 143 and left == ["predictions.csv"]
    else:
        assert code == -signal.SIGTERM and len(left) == 2 and left[0].startswith(".predictions.csv.")


def test_a_failed_write_keeps_the_old_file(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_write(target) as handle:
            handle.write("new")
            raise RuntimeError("disk gone")
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["out.txt"]


def test_a_folder_is_not_a_file_to_write(tmp_path):
    with pytest.raises(PartcalError, match="is a folder; give the name of a file to write"):
        with atomic_write(tmp_path):
            pass
