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


EXTRA_REAL_DIR = Path(os.environ.get("SKPCD_EXTRA_REAL", ROOT.parent / "extra_real"))


@pytest.fixture(scope="session")
def extra_real():
    """The folder of other real scans beside the checkout (profiler stretches,
    terrestrial stations, the ISPRS filter-test samples, Autzen; its README
    names their sources), as a function of a path in it to that path
    (missing: skipped; their licences do not let them into the repository)."""

    def path(name):
        p = EXTRA_REAL_DIR / name
        if not p.exists():
            pytest.skip(f"no {name} in {EXTRA_REAL_DIR} (set SKPCD_EXTRA_REAL)")
        return p

    return path


REAL_LABELLED_DIR = Path(
    os.environ.get(
        "SKPCD_REAL_LABELLED_DIR", ROOT.parent / "shared" / "data" / "real_labelled"
    )
)


@pytest.fixture(scope="session")
def real_labelled():
    """The folder of real sweeps labelled point by point (SemanticKITTI,
    nuScenes, PandaSet; a ``semantic`` dimension of SemanticKITTI ids), as
    a function of a file name to its path (missing: skipped)."""
    scans = REAL_LABELLED_DIR / "scans"
    if not scans.is_dir():
        pytest.skip(
            f"no labelled sweeps at {REAL_LABELLED_DIR} (set SKPCD_REAL_LABELLED_DIR)"
        )
    return lambda name: scans / name


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


# -- descriptors of a few labelled objects (encoding, classification) --------


def _with_a_wire(cloud):
    """The cloud and, 10 m beyond it, 7 collinear points (a wire).

    Their 6-neighbourhoods are rank 1, so their normals and PFH are
    undefined (NaN), as for real isolated wires or scan lines.
    """
    wire = cloud.max(axis=0) + 10.0 + np.arange(7)[:, None] * [0.3, 0.0, 0.0]
    return np.vstack([cloud, wire])


@pytest.fixture(scope="module")
def dales_small(labelled_objects):
    """8 objects per class (at most 4000 points), in order: synthetic, then
    real DALES ones.

    Every fifth object carries a wire of undefined descriptors.
    """
    all_clouds, all_labels, _ = labelled_objects
    clouds, labels, taken = [], [], {}
    for cloud, label in zip(all_clouds, all_labels, strict=True):
        if taken.get(label, 0) < 8 and len(cloud) <= 4000:
            clouds.append(cloud)
            labels.append(label)
            taken[label] = taken.get(label, 0) + 1
    clouds = [_with_a_wire(c) if i % 5 == 0 else c for i, c in enumerate(clouds)]
    return clouds, np.array(labels)


@pytest.fixture(scope="module")
def dales_pfh(dales_small):
    """The paper's PFH (k = 6, 125 bins) of the small DALES objects."""
    clouds, labels = dales_small
    from skpcd.features import PFHTransformer

    return PFHTransformer(n_neighbors=6, n_jobs=2).transform(clouds), labels


def _subsample(clouds, n_points=300, seed=0):
    rng = np.random.default_rng(seed)
    return [
        c if len(c) <= n_points else c[rng.choice(len(c), n_points, replace=False)]
        for c in clouds
    ]


@pytest.fixture(scope="module")
def dales_cases(labelled_objects):
    """Volume and improved PFH of up to 40 objects per class (at most 300
    points each, to keep the test fast): 20 synthetic ones, then 40 DALES
    ones."""
    from skpcd.classification import make_case_based_pipeline

    clouds, labels, _ = labelled_objects
    keep = np.concatenate([np.flatnonzero(labels == c)[:40] for c in np.unique(labels)])
    clouds = _subsample([clouds[i] for i in keep])
    X = make_case_based_pipeline()[0].fit_transform(clouds)
    return X, labels[keep], clouds


@pytest.fixture(scope="module")
def dask_client():
    """A LocalCluster of 2 worker processes of 1 thread, started for the
    module that asks for it (skipped without the dask extra)."""
    pytest.importorskip(
        "distributed", reason="the dask extra is not installed: pip install skpcd[dask]"
    )
    from distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=2,
        processes=True,
        threads_per_worker=1,
        dashboard_address=":0",
        memory_limit=None,
    )
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()
