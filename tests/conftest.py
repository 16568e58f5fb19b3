"""Shared fixtures: the path to the real third-party material kept in ``tests/data`` (see its README)."""

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA
