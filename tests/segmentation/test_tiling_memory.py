"""The tiled path holds the tiles, not the scan: what grows with the scan
(the points the tiles share, the per-point results) stays on disk."""

import tracemalloc

import numpy as np
import pytest

from skpcd.segmentation._dbscan import sample_queries
from skpcd.segmentation.tiling._eps import chunked_sample_queries
from skpcd.segmentation.tiling._segment import _link_pairs, _stitch


def _chain(n_tiles, n_own, n_shared):
    """Tiles of ``n_own`` consecutive points, one segment each, each sharing
    the first ``n_shared`` points of the next tile (as DBSCAN's core points
    in its buffer), made one at a time as the tiled path makes them."""
    for t in range(n_tiles):
        own = np.arange(t * n_own, (t + 1) * n_own)
        more = n_shared if t + 1 < n_tiles else 0
        index = np.concatenate([own, own[:more] + n_own])
        owned = np.arange(len(index)) < n_own
        shared = np.arange(n_own, n_own + more)
        yield (
            (index, owned),
            (np.zeros(n_own, np.int64), shared, np.zeros(more, np.int64), None),
        )


@pytest.mark.parametrize("exact", [True, False])
def test_stitch_holds_the_segment_pairs_not_the_shared_points(tmp_path, exact):
    # 39 x 50 000 shared points: 31 MB as (point, segment) rows in memory
    n_tiles, n_own, n_shared = 40, 60_000, 50_000
    labels = np.full(n_tiles * n_own, -1, dtype=np.int64)
    tracemalloc.start()
    try:
        kinds = _stitch(
            _chain(n_tiles, n_own, n_shared), labels, 100_000, (1, None), exact,
            tmp_path,
        )  # fmt: skip
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # the chain is one segment, the shared points' file is gone
    assert np.array_equal(labels, np.zeros_like(labels))
    assert len(kinds) == 1
    assert list(tmp_path.iterdir()) == []
    # a tile (1.8 MB of indices, 0.5 MB of labels) and chunks of 100 000 rows
    assert peak < 12e6, peak


@pytest.mark.parametrize("chunk_size", [1, 7, 1000, 10**6])
def test_link_pairs_in_chunks_are_the_unique_rows(chunk_size):
    rng = np.random.default_rng(0)
    labels = rng.integers(-1, 5, 400)
    links = np.column_stack([rng.integers(0, 400, 3000), rng.integers(0, 9, 3000)])
    pairs, count = _link_pairs(links, labels, 9, chunk_size, exact=False)
    other = labels[links[:, 0]]
    rows = np.column_stack([links[:, 1], other])[other >= 0]
    want, want_count = np.unique(rows, axis=0, return_counts=True)
    assert np.array_equal(pairs, want)
    assert np.array_equal(count, want_count)
    assert count.dtype == np.int64


def test_link_pairs_of_no_shared_point():
    pairs, count = _link_pairs(
        np.zeros((0, 2), np.int64), np.zeros(3, np.int64), 0, 5, True
    )
    assert pairs.shape == (0, 2) and count.shape == (0,)


@pytest.mark.parametrize(
    ("n", "max_samples", "chunk_size"),
    [(10, 3, 2), (1000, 100, 7), (1000, 100, 5000), (50, None, 7), (50, 80, 7)],
)
@pytest.mark.parametrize("seed", [0, 7])
def test_chunked_sample_queries_draws_the_untiled_sample(
    n, max_samples, chunk_size, seed
):
    got = chunked_sample_queries(n, max_samples, seed, chunk_size)
    assert np.array_equal(got, sample_queries(n, max_samples, seed))
    # a RandomState instance is consumed as by the untiled draw
    a, b = np.random.RandomState(seed), np.random.RandomState(seed)
    chunked_sample_queries(n, max_samples, a, chunk_size)
    sample_queries(n, max_samples, b)
    assert a.random() == b.random()


def test_chunked_sample_queries_holds_a_chunk_not_the_points():
    # 5 M non-ground points: 80 MB of keys and ranks drawn at once
    tracemalloc.start()
    try:
        got = chunked_sample_queries(5_000_000, 100_000, 0, 200_000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert np.array_equal(got, sample_queries(5_000_000, 100_000, 0))
    assert peak < 15e6, peak


def test_tiles_give_the_freed_heap_back(monkeypatch, tmp_path):
    # glibc keeps freed blocks in the heap: without malloc_trim what the
    # caller freed (the kind's sample of the scan) and each tile's
    # temporaries stay resident under the next tile's
    import skpcd.segmentation.tiling._dispatch as dispatch
    import skpcd.segmentation.tiling._segment as seg
    from skpcd.segmentation import segment_scene

    calls = []

    def trim():
        calls.append(len(calls))

    monkeypatch.setattr(dispatch, "release_free_memory", trim)
    monkeypatch.setattr(seg, "release_free_memory", trim)
    rng = np.random.default_rng(0)
    xyz = rng.uniform([0, 0, 0], [60, 20, 2], (4000, 3))
    result = segment_scene(
        xyz, ground="street", structures=False, eps=1.0, tile_size=20,
        temp_folder=tmp_path,
    )  # fmt: skip
    assert len(result.labels) == len(xyz)
    # before and after the spill, each of the 3 tiles in the cloth's pass,
    # and each tile of each pass over the tiles (cloth, bases, clusters)
    assert len(calls) >= 2 + 3 + 3 * 3


def test_the_scan_kind_sample_holds_one_chunk_at_a_time(tmp_path):
    # 4 M points read in chunks of 1 M: the sample keeps copies of its rows,
    # not views that would keep every chunk (24 MB of xyz each) alive
    from skpcd.io import write_point_cloud
    from skpcd.segmentation._scene import _scan_sample

    rng = np.random.default_rng(0)
    path = tmp_path / "scan.las"
    write_point_cloud(path, rng.uniform(0, 100, (4_000_000, 3)))
    tracemalloc.start()
    try:
        sample = _scan_sample(path, 0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(sample) == 200_000
    # one chunk as read with its xyz, and the sample: 90 MB; views of the
    # chunks kept all four chunks' xyz alive: 134 MB
    assert peak < 110e6, peak
