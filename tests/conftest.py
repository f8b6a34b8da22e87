"""Shared fixtures and paths."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"


@pytest.fixture(scope="session")
def sk120():
    from partcal import load_robot

    return load_robot("motoman_sk120")
