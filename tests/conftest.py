"""Shared fixtures: the real DALES objects beside the checkout."""

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DALES_DIR = Path(
    os.environ.get("SKPCD_DALES_DIR", ROOT.parent / "shared" / "data" / "dales_objects")
)


@pytest.fixture(scope="session")
def dales_dir():
    """The folder of real DALES objects (missing: skipped, or failed in CI)."""
    if not (DALES_DIR / "labels.csv").is_file():
        if os.environ.get("CI"):
            pytest.fail(f"the DALES objects are missing from {DALES_DIR}")
        pytest.skip(f"the DALES objects are not at {DALES_DIR} (set SKPCD_DALES_DIR)")
    return DALES_DIR


@pytest.fixture(scope="session")
def dales(dales_dir):
    """All DALES objects as ``(clouds, labels, names)``."""
    from skpcd.io import read_segments

    return read_segments(dales_dir, dales_dir / "labels.csv")
