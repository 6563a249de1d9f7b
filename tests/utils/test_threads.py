"""Every threaded stage gives the same bits on one, two and three threads, on
inputs large enough that parallel_rows really cuts the work into chunks."""

import numpy as np
import pytest

from skpcd.datasets import make_point_clouds
from skpcd.features import FPFHTransformer, ImprovedPFHTransformer, PFHTransformer
from skpcd.preprocessing import NormalEstimator, compute_neighborhoods, grid_sample


@pytest.fixture(scope="module")
def clouds():
    # two large clouds (chunks of 4096 rows and more) and small ones
    big = make_point_clouds(2, n_points=40_000, random_state=0)
    return big + make_point_clouds(30, n_points=(50, 400), random_state=1)


@pytest.mark.parametrize(
    "make",
    [
        lambda n: PFHTransformer(n_neighbors=10, n_jobs=n, undefined="keep"),
        lambda n: PFHTransformer(radius=0.03, n_jobs=n, undefined="keep"),
        lambda n: FPFHTransformer(n_neighbors=10, n_jobs=n, undefined="keep"),
        lambda n: ImprovedPFHTransformer(n_neighbors=10, n_jobs=n),
        lambda n: NormalEstimator(n_neighbors=10, n_jobs=n),
        lambda n: PFHTransformer(n_neighbors=10, n_jobs=n, pooling="mean"),
    ],
    ids=["pfh", "pfh-radius", "fpfh", "improved", "normals", "pfh-pooled"],
)
def test_transformers_give_the_same_bits_on_any_thread_count(clouds, make):
    one = make(1).fit_transform(clouds)
    for n in (2, 3):
        other = make(n).fit_transform(clouds)
        for a, b in zip(one, other, strict=True):
            np.testing.assert_array_equal(a, b)


def test_search_and_sampling_give_the_same_bits_on_any_thread_count(clouds):
    xyz = np.vstack(clouds[:2])
    one = compute_neighborhoods(xyz, n_neighbors=10, n_jobs=1)
    ball = compute_neighborhoods(xyz, radius=0.02, n_jobs=1)
    for n in (2, 3):
        other = compute_neighborhoods(xyz, n_neighbors=10, n_jobs=n)
        np.testing.assert_array_equal(one.indices, other.indices)
        np.testing.assert_array_equal(one.sqdist, other.sqdist)
        other = compute_neighborhoods(xyz, radius=0.02, n_jobs=n)
        np.testing.assert_array_equal(ball.indptr, other.indptr)
        np.testing.assert_array_equal(ball.indices, other.indices)
        np.testing.assert_array_equal(
            grid_sample(xyz, 0.02, n_jobs=1), grid_sample(xyz, 0.02, n_jobs=n)
        )
