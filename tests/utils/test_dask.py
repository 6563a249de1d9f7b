"""Batches of clouds on joblib backends and on a real Dask cluster.

:func:`~skpcd.utils._parallel.map_batches` runs in-process unless a joblib
backend is chosen; then batches of whole clouds (or queries) are dispatched
and every estimator's output must be bit-identical to the plain call,
whatever the batches and wherever they run.
"""

import itertools
import math
import threading

import joblib
import numpy as np
import pytest

from skpcd.classification import CaseBasedClassifier
from skpcd.encoding import BagOfFeatures
from skpcd.features import (
    FPFHTransformer,
    ImprovedPFHTransformer,
    OverallDescriptor,
    PFHTransformer,
    ShapeFeatures,
)
from skpcd.preprocessing import NormalEstimator
from skpcd.utils._parallel import (
    BATCH_POINTS,
    batch_bounds,
    batch_config,
    chosen_backend,
    effective_threads,
    map_batches,
)


def _same(a, b):
    """Equal, NaN equal to NaN, through lists and tuples; dtypes too."""
    if isinstance(a, (list, tuple)):
        return (
            type(a) is type(b)
            and len(a) == len(b)
            and all(_same(x, y) for x, y in zip(a, b))
        )
    a, b = np.asarray(a), np.asarray(b)
    nan = a.dtype.kind in "fc"
    return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=nan)


# --- batch_bounds and map_batches -------------------------------------------


def test_batch_bounds_cut_before_the_cloud_that_overflows():
    assert batch_bounds([3, 3, 3, 10, 1], 6) == [(0, 2), (2, 3), (3, 4), (4, 5)]
    assert batch_bounds([2, 2, 2], 6) == [(0, 3)]
    assert batch_bounds([2, 2, 2], 4) == [(0, 2), (2, 3)]
    # empty clouds ride along with their neighbours
    assert batch_bounds([0, 5, 0, 0, 5], 5) == [(0, 4), (4, 5)]


def test_batch_bounds_never_split_and_keep_order():
    rng = np.random.default_rng(0)
    sizes = rng.integers(0, 50, size=300)
    for budget in (1, 7, 49, 100, 10_000):
        bounds = batch_bounds(sizes, budget)
        # contiguous, in order, every cloud once
        assert bounds[0][0] == 0 and bounds[-1][1] == len(sizes)
        assert all(a[1] == b[0] and a[0] < a[1] for a, b in itertools.pairwise(bounds))
        for lo, hi in bounds:
            total = sizes[lo:hi].sum()
            # over budget only as a batch of one cloud
            assert total <= budget or hi - lo == 1
            # greedy: the next cloud did not fit
            if hi < len(sizes):
                assert total + sizes[hi] > budget


def test_batch_bounds_empty_and_huge():
    assert batch_bounds([], 10) == []
    assert batch_bounds([10**9], 1000) == [(0, 1)]
    assert batch_bounds([1, 10**9, 1], 1000) == [(0, 1), (1, 2), (2, 3)]
    with pytest.raises(ValueError, match="at least 1"):
        batch_bounds([1], 0)
    with pytest.raises(ValueError, match="negative"):
        batch_bounds([1, -1], 5)


def _record(calls):
    lock = threading.Lock()

    def func(batch, n_jobs):
        with lock:
            calls.append((list(batch), n_jobs, effective_threads(None)))
        return [len(c) for c in batch]

    return func


def test_local_path_is_one_call():
    clouds = [np.zeros((n, 3)) for n in (5, 6, 7)]
    calls = []
    assert map_batches(_record(calls), clouds, 3, batch_points=1) == [5, 6, 7]
    assert len(calls) == 1 and calls[0][1] == 3
    # n_jobs without a backend: still local, threads as before; the batch
    # function gets the thread count, resolved once by map_batches
    calls.clear()
    with joblib.parallel_config(n_jobs=2):
        map_batches(_record(calls), clouds, None, batch_points=1)
    assert len(calls) == 1 and calls[0][1] == 2 and calls[0][2] == 2
    calls.clear()
    # the sequential backend runs in-process too
    with joblib.parallel_config(backend="sequential"):
        map_batches(_record(calls), clouds, None, batch_points=1)
    assert len(calls) == 1


def test_bounded_local_path_runs_batches_in_turn():
    clouds = [np.zeros((n, 3)) for n in (5, 6, 7)]
    calls = []
    out = map_batches(_record(calls), clouds, 2, batch_points=11, bounded=True)
    assert out == [5, 6, 7]
    # in-process, one batch after the other, each with the caller's n_jobs
    assert [len(c[0]) for c in calls] == [2, 1] and all(c[1] == 2 for c in calls)


def test_pooled_descriptors_are_computed_batch_by_batch(small_objects, monkeypatch):
    clouds, _ = small_objects
    pfh = PFHTransformer(n_neighbors=10, pooling="mean")
    whole = pfh.fit_transform(clouds)
    batches = []
    compute = PFHTransformer._transform_batch

    def spy(self, batch, n_jobs):
        batches.append(len(batch))
        return compute(self, batch, n_jobs)

    monkeypatch.setattr(PFHTransformer, "_transform_batch", spy)
    with batch_config(batch_points=5000):  # a few clouds per batch
        pooled = pfh.transform(clouds)
    assert len(batches) > 3 and sum(batches) == len(clouds)
    assert _same(pooled, whole)
    # per-point rows stay one call: nothing to bound
    batches.clear()
    PFHTransformer(n_neighbors=10).fit(clouds).transform(clouds)
    assert batches == [len(clouds)]


def test_threading_backend_batches_in_order():
    clouds = [np.zeros((n, 3)) for n in (5, 6, 7, 1, 1, 9)]
    calls = []
    with joblib.parallel_config(backend="threading", n_jobs=2):
        out = map_batches(_record(calls), clouds, batch_points=12)
    assert out == [5, 6, 7, 1, 1, 9]
    batches = sorted(tuple(len(c) for c in b) for b, _, _ in calls)
    assert batches == [(5, 6), (7, 1, 1), (9,)]
    # each batch: the cores left by the 2 batches at once, also for the
    # kernels' effective_threads whatever n_jobs they are given
    want = max(1, joblib.cpu_count() // 2)
    assert {(n, t) for _, n, t in calls} == {(want, want)}
    # no batch larger than the total over the batches at once (29 / 2)
    calls.clear()
    with joblib.parallel_config(backend="threading", n_jobs=2):
        map_batches(_record(calls), clouds, batch_points=10**6)
    batches = sorted(tuple(len(c) for c in b) for b, _, _ in calls)
    assert batches == [(5, 6), (7, 1, 1), (9,)]


def test_batch_config_and_results_joined():
    clouds = [np.zeros((n, 3)) for n in (4, 4, 4, 4)]

    def func(batch, n_jobs):
        k = len(batch)
        return np.full((k, 2), k), [k] * k, (np.arange(k), ["x"] * k)

    with joblib.parallel_config(backend="threading", n_jobs=2):
        with batch_config(batch_points=4):
            arr, lst, (idx, names) = map_batches(func, clouds)
        # restored on exit: 2 batches of 8 points (the total over 2)
        arr2, _, _ = map_batches(func, clouds)
    assert arr.shape == (4, 2) and (arr == 1).all() and lst == [1, 1, 1, 1]
    assert idx.tolist() == [0, 0, 0, 0] and names == ["x"] * 4
    assert (arr2 == 2).all()
    with pytest.raises(ValueError, match="positive integer"):
        with batch_config(batch_points=0):
            pass
    assert BATCH_POINTS == 1_000_000


def test_nested_calls_stay_in_their_batch():
    clouds = [np.zeros((3, 3))] * 4
    inner = []

    def outer(batch, n_jobs):
        return map_batches(_record(inner), batch, n_jobs, batch_points=1)

    with joblib.parallel_config(backend="threading", n_jobs=2):
        assert map_batches(outer, clouds, batch_points=6) == [3, 3, 3, 3]
    # one inner call per outer batch: not cut again
    assert len(inner) == 2


def test_sizes_must_match_items():
    with joblib.parallel_config(backend="threading", n_jobs=2):
        with pytest.raises(ValueError, match="one entry per item"):
            map_batches(lambda b, n: list(b), [np.zeros((1, 3))] * 3, sizes=[1, 2])


# --- estimators on synthetic and real objects ----------------------------------


@pytest.fixture(scope="module")
def small_objects(labelled_objects):
    """40 objects (synthetic, then DALES) of every class, at most 2500
    points each."""
    clouds, labels, _ = labelled_objects
    labels = np.asarray(labels)
    keep = [i for i, c in enumerate(clouds) if len(c) <= 2500]
    rng = np.random.default_rng(0)
    picked = np.sort(rng.choice(keep, size=40, replace=False))
    return [clouds[i] for i in picked], labels[picked]


@pytest.fixture(scope="module")
def workloads(small_objects):
    """Each estimator's output-producing call on the objects, with its plain
    (in-process) result."""
    clouds, labels = small_objects
    train, test = clouds[:24], clouds[24:]
    pfh = FPFHTransformer(n_neighbors=10).fit_transform(train)
    bof = BagOfFeatures(n_words=8, random_state=0, max_descriptors=2000).fit(pfh)
    bof_in = FPFHTransformer(n_neighbors=10).fit_transform(test)
    union = [OverallDescriptor(), ImprovedPFHTransformer(undefined="zero")]

    def cases(cl):
        return np.hstack([union[0].transform(cl)[:, 9:10], union[1].transform(cl)])

    # threshold 0.6: some queries named, some unknown (at 0.9 all were
    # unknown on both sources: predict compared nothing)
    case_based = CaseBasedClassifier(volume_column=0, threshold=0.6)
    case_based.fit(cases(train), labels[:24])
    queries = cases(test)
    assert len(set(case_based.predict(queries).tolist())) > 2
    calls = {
        "pfh_knn": lambda: PFHTransformer(n_neighbors=10).transform(clouds),
        "pfh_radius": lambda: PFHTransformer(radius=1.0).transform(clouds),
        "pfh_undefined": lambda: PFHTransformer(radius=0.4).undefined_mask(clouds),
        "fpfh": lambda: FPFHTransformer(n_neighbors=12, n_jobs=2).transform(clouds),
        "fpfh_pooled": lambda: FPFHTransformer(
            radius=1.0, pooling="mean", undefined="drop"
        ).transform(clouds),
        "improved": lambda: ImprovedPFHTransformer().transform(clouds),
        "normals": lambda: NormalEstimator(include_curvature=True).transform(clouds),
        "shape": lambda: ShapeFeatures().transform(clouds),
        "overall": lambda: OverallDescriptor().transform(clouds),
        "bof": lambda: bof.transform(bof_in),
        "case_predict": lambda: case_based.predict(queries),
        "case_decision": lambda: case_based.decision_function(queries),
        "case_retrieve": lambda: case_based.retrieve(queries, n_cases=3),
    }
    # what a batch counts: points, descriptors, queries
    sizes = {
        "bof": [len(d) for d in bof_in],
        "case_predict": [1] * len(queries),
        "case_decision": [1] * len(queries),
        "case_retrieve": [1] * len(queries),
    }
    points = [len(c) for c in clouds]
    return {
        name: (call, call(), np.asarray(sizes.get(name, points)))
        for name, call in calls.items()
    }


@pytest.mark.parametrize(
    "name",
    [
        "pfh_knn",
        "pfh_radius",
        "pfh_undefined",
        "fpfh",
        "fpfh_pooled",
        "improved",
        "normals",
        "shape",
        "overall",
        "bof",
        "case_predict",
        "case_decision",
        "case_retrieve",
    ],
)
def test_threading_backend_is_bit_identical(workloads, name):
    call, want, sizes = workloads[name]
    # down to one cloud (one query) per batch, and an uneven cut
    for batch_points in (1, sizes.sum() // 3 + 1):
        with joblib.parallel_config(backend="threading", n_jobs=2):
            with batch_config(batch_points=batch_points):
                got = call()
        assert _same(got, want), (name, batch_points)


@pytest.mark.parametrize("name", ["shape", "case_retrieve"])
def test_process_backend_is_bit_identical(workloads, name):
    call, want, sizes = workloads[name]
    with joblib.parallel_config(backend="multiprocessing", n_jobs=2):
        assert chosen_backend() is not None
        with batch_config(batch_points=sizes.sum() // 3 + 1):
            got = call()
    assert _same(got, want)


def test_loky_runs_in_process():
    # joblib's default backend, chosen or not: skpcd's threads, one call
    clouds = [np.zeros((n, 3)) for n in (5, 6, 7)]
    calls = []
    with joblib.parallel_config(backend="loky", n_jobs=2):
        assert chosen_backend() is None
        map_batches(_record(calls), clouds, None, batch_points=1)
    assert len(calls) == 1


# --- a real Dask cluster ---------------------------------------------------


def _run_on_dask(client, call):
    """The call's result and the workers that ran its batches."""
    from distributed import get_task_stream

    with get_task_stream(client) as stream:
        with joblib.parallel_config(backend="dask"):
            result = call()
    workers = [t["worker"] for t in stream.data if "run_batch" in str(t["key"])]
    return result, workers


def test_dask_batches_use_the_cores_of_their_worker(dask_client):
    clouds = [np.zeros((n, 3)) for n in (3, 3, 3, 3)]

    def threads(batch, n_jobs):
        return [(n_jobs, effective_threads(None), effective_threads(8))] * len(batch)

    with joblib.parallel_config(backend="dask"):  # scale-out never silently off
        assert type(chosen_backend()).__name__ == "DaskDistributedBackend"
    got, workers = _run_on_dask(dask_client, lambda: map_batches(threads, clouds))
    # 2 workers of 1 thread on this machine: its cores shared by 2 threads
    want = max(1, joblib.cpu_count() // 2)
    assert set(got) == {(want, want, want)}
    assert len(workers) == 2
    assert set(workers) <= set(dask_client.scheduler_info()["workers"])


@pytest.mark.parametrize(
    "name",
    ["pfh_knn", "pfh_radius", "fpfh", "improved", "bof", "case_predict"],
)
def test_dask_cluster_is_bit_identical(dask_client, workloads, name):
    call, want, sizes = workloads[name]
    cluster_workers = set(dask_client.scheduler_info()["workers"])
    for per_worker in (1, 2):
        budget = math.ceil(sizes.sum() / (len(cluster_workers) * per_worker))
        n_batches = len(batch_bounds(sizes, budget))
        assert n_batches >= len(cluster_workers) * per_worker
        with batch_config(batch_points=budget):
            got, workers = _run_on_dask(dask_client, call)
        assert _same(got, want), (name, per_worker)
        # each batch ran as a task on one of the cluster's workers, not here
        assert len(workers) == n_batches, (name, per_worker, workers)
        assert set(workers) <= cluster_workers


def test_parallel_rows_takes_a_thread_count():
    # n_jobs is resolved at the boundary (map_batches, the function forms);
    # the row runner refuses an unresolved one
    from skpcd.utils._parallel import parallel_rows

    out = []
    parallel_rows(lambda lo, hi: out.append((lo, hi)), 3, 1)
    assert out == [(0, 3)]
    for bad in (None, -1.0, True):
        with pytest.raises(TypeError, match="thread count"):
            parallel_rows(lambda lo, hi: None, 3, bad)
