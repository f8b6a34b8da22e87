"""Shared fixtures and paths."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Shared reference data sets live in ../shared beside the repository (never copied into it); a git
# worktree one level deeper finds them by looking further up.
SHARED = next((p / "shared" for p in ROOT.parents if (p / "shared" / "datasets").is_dir()), ROOT.parent / "shared")


@pytest.fixture(scope="session")
def sk120():
    from partcal import load_robot

    return load_robot("motoman_sk120")
