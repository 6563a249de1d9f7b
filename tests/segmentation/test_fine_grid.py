"""The fine-grid path of the grid DBSCAN (cells at most eps / sqrt(3) wide,
the dense scans' path) gives the same core points and labels as the
obvious DBSCAN and as the radius-grid path, on lattices full of ties and
on real sweeps."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.io import read_point_cloud
from skpcd.segmentation import _clusters
from skpcd.segmentation._clusters import grid_dbscan

from .test_clusters import reference_dbscan


def _path(monkeypatch, fine):
    """Force the fine grid (always) or the radius grid (never)."""
    monkeypatch.setattr(_clusters, "_FINE_MIN_POINTS", 0.0 if fine else np.inf)


def _dense(n, seed):
    """Dense blobs (many points to a fine cell) and sparse noise."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 2, (4, 3))
    pts = centres[rng.integers(0, 4, n)] + rng.normal(0, 0.15, (n, 3))
    return np.vstack([pts, rng.uniform(-1, 3, (n // 10, 3))])


@pytest.mark.parametrize("eps", [0.05, 0.12, 0.3])
@pytest.mark.parametrize("min_samples", [1, 2, 5, 12])
def test_fine_path_equals_reference(monkeypatch, eps, min_samples):
    _path(monkeypatch, fine=True)
    xyz = _dense(700, seed=int(eps * 100) + min_samples)
    labels, core = grid_dbscan(xyz, eps, min_samples)
    ref_labels, ref_core = reference_dbscan(xyz, eps, min_samples)
    np.testing.assert_array_equal(core, ref_core)
    np.testing.assert_array_equal(labels, ref_labels)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    steps=st.integers(1, 6),
    min_samples=st.integers(1, 9),
    n_jobs=st.sampled_from([1, 2]),
)
def test_fine_path_on_a_lattice(seed, steps, min_samples, n_jobs):
    """Points on a 1/8 lattice (duplicates, pairs exactly ``eps`` apart,
    border points tied between clusters) with ``eps`` a lattice multiple."""
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.normal(0, 0.4, (int(rng.integers(2, 400)), 3)) * 8) / 8
    eps = steps / 8
    with pytest.MonkeyPatch.context() as mp:
        _path(mp, fine=True)
        labels, core = grid_dbscan(xyz, eps, min_samples, n_jobs=n_jobs)
    ref_labels, ref_core = reference_dbscan(xyz, eps, min_samples)
    np.testing.assert_array_equal(core, ref_core)
    np.testing.assert_array_equal(labels, ref_labels)


@pytest.mark.parametrize("eps", [0.2, 0.5])
@pytest.mark.parametrize("min_samples", [1, 5])
def test_fine_and_radius_grids_agree_on_a_real_sweep(
    monkeypatch, real_sweeps, eps, min_samples
):
    xyz = np.ascontiguousarray(read_point_cloud(real_sweeps[3]))
    _path(monkeypatch, fine=False)
    want = grid_dbscan(xyz, eps, min_samples, n_jobs=2)
    _path(monkeypatch, fine=True)
    for n_jobs in (1, 2):
        got = grid_dbscan(xyz, eps, min_samples, n_jobs=n_jobs)
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[0], want[0])


def test_the_fine_grid_is_taken_only_where_cells_hold_points():
    dense = _dense(3000, seed=1)
    assert _clusters._fine_dbscan(dense, 0.3, 5, 1) is not None
    sparse = np.random.default_rng(0).uniform(0, 100, (3000, 3))
    assert _clusters._fine_dbscan(sparse, 0.3, 5, 1) is None
    # cells that would need more than 2**20 to a side: the radius grid
    wide = np.vstack([dense, [[1e7, 0, 0]]])
    assert _clusters._fine_dbscan(wide, 0.3, 5, 1) is None
    assert _clusters._fine_dbscan(dense, 0.0, 5, 1) is None
