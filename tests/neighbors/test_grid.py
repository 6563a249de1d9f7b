import numpy as np
import pytest

from skpcd.neighbors._grid import argsort_keys, build_grid, snake_order


@pytest.mark.parametrize("top", [0, 5, 3000, 2**40, 2**62 - 1])
def test_argsort_keys_is_a_stable_argsort_for_every_thread_count(top):
    rng = np.random.default_rng(top % 1000)
    keys = rng.integers(0, top + 1, size=200_000, dtype=np.int64)
    expected = np.argsort(keys, kind="stable")
    for n_threads in (1, 2, 3):
        order, sorted_keys = argsort_keys(keys, n_threads)
        np.testing.assert_array_equal(order, expected)
        np.testing.assert_array_equal(sorted_keys, keys[expected])


def test_argsort_keys_leaves_its_input_alone():
    keys = np.random.default_rng(0).integers(0, 99, size=100_000, dtype=np.int64)
    copy = keys.copy()
    argsort_keys(keys, 2)
    np.testing.assert_array_equal(keys, copy)


def test_the_grid_is_the_same_for_every_thread_count():
    rng = np.random.default_rng(1)
    xyz = np.round(rng.uniform(0, 40, (150_000, 3)), 2)
    offsets = np.array([0, 60_000, 60_001, 150_000], dtype=np.int64)
    grids = [build_grid(xyz, offsets, np.full(3, 0.7), n_threads=t) for t in (1, 2)]
    for a, b in zip(*grids, strict=True):
        np.testing.assert_array_equal(a, b)
    # the points of every cell are contiguous, in index order within a cell
    g = grids[0]
    np.testing.assert_array_equal(g.xs, xyz[g.order])
    assert g.cell_start[-1] == len(xyz)


def test_snake_order_is_the_lexsort_of_its_cells():
    rng = np.random.default_rng(2)
    p = rng.uniform(0, 10, (100_000, 3))
    cloud = np.repeat([0, 1, 2], [40_000, 10_000, 50_000])
    h = 0.37
    c = np.floor((p - p.min(axis=0)) / h).astype(np.int64)
    snake = np.where(c[:, 0] % 2 == 0, c[:, 1], -c[:, 1])
    expected = np.lexsort((c[:, 2], snake, c[:, 0], cloud))
    for n_threads in (1, 2):
        np.testing.assert_array_equal(snake_order(p, h, cloud, n_threads), expected)
    alone = np.lexsort((c[:, 2], snake, c[:, 0]))
    np.testing.assert_array_equal(snake_order(p, h), alone)
    # keys beyond an int64: the coordinates are lexsorted instead
    far = np.array([[0.0, 0, 0], [1e30, 1e30, 1e30], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(snake_order(far, 1e-9), [0, 2, 1])
