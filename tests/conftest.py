"""Shared fixtures: the real DALES objects beside the checkout, and a
synthetic stand-in that is always there.

A guarantee that does not depend on real data (tiled equals untiled,
bit-identity across backends, ...) is tested through ``labelled_objects``:
once on synthetic objects (always) and once on the DALES objects (the
real-data layer, skipped when the folder is missing, failed in CI).
"""

import os
from pathlib import Path

import numpy as np
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


REAL_MOBILE_DIR = Path(
    os.environ.get(
        "SKPCD_REAL_MOBILE_DIR", ROOT.parent / "shared" / "data" / "real_mobile"
    )
)


@pytest.fixture(scope="session")
def real_sweeps():
    """The real car-mounted sweeps (KITTI, PandaSet) beside the checkout, as
    LAS paths (missing: skipped, or failed in CI)."""
    paths = sorted((REAL_MOBILE_DIR / "scans").glob("*.las"))
    if not paths:
        if os.environ.get("CI"):
            pytest.fail(f"the real sweeps are missing from {REAL_MOBILE_DIR}")
        pytest.skip(f"no real sweeps at {REAL_MOBILE_DIR} (set SKPCD_REAL_MOBILE_DIR)")
    return paths


@pytest.fixture(scope="session")
def dales(dales_dir):
    """All DALES objects as ``(clouds, labels, names)``."""
    from skpcd.io import read_segments

    return read_segments(dales_dir, dales_dir / "labels.csv")


@pytest.fixture(scope="session")
def urban_objects():
    """Synthetic objects of the DALES classes, as ``(clouds, labels, names)``
    like :func:`dales`: 20 per class from ``make_urban_objects``, of sizes
    (metres and points) like the DALES ones."""
    from skpcd.datasets import make_urban_objects

    clouds, labels = make_urban_objects(n_per_class=20, random_state=0)
    names = [f"{i:03d}.xyz" for i in range(len(clouds))]
    return clouds, np.asarray(labels), names


@pytest.fixture(scope="session", params=["synthetic", "dales"])
def labelled_objects(request):
    """``(clouds, labels, names)``: the synthetic objects, then the DALES ones
    (skipped without the folder)."""
    name = "urban_objects" if request.param == "synthetic" else "dales"
    return request.getfixturevalue(name)
