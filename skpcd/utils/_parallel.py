"""Threads for the numba kernels, and batches of clouds for joblib backends.

Kernels are serial ``nogil`` numba functions over a range of rows,
``kernel(lo, hi, *args)``, writing into arrays allocated by the caller;
:func:`parallel_rows` cuts the rows into chunks and runs them on a pool of
Python threads.

``n_jobs`` becomes a thread count in one place, :func:`effective_threads`,
called at the boundary: by :func:`map_batches` for the estimators (which
hand each batch function its thread count) and by the public function
forms (``compute_neighborhoods``, ``compute_pfh``, ``grid_dbscan``...).
Below the boundary every function takes ``n_threads``, a positive int
(:func:`parallel_rows` refuses anything else), and nothing looks at
``n_jobs`` again. The thread-local state of a dispatched batch is read only
by :func:`effective_threads` itself, so that an estimator called inside a
batch (a pipeline step in a dispatched task) gets the batch's share of the
cores, not its own ``n_jobs``.

Compared with numba's ``parallel=True``, these threads compile several
times faster, need no threading layer, and the thread count is an
argument, not global state.

:func:`map_batches` is the one place where work on a list of clouds is
split into batches of whole clouds: in-process by default, dispatched with
joblib (``sklearn.utils.parallel``) when the caller chose a backend with
:func:`joblib.parallel_config`, e.g. ``backend="dask"`` to run on the
workers of a ``dask.distributed`` cluster.
"""

import contextlib
import contextvars
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from joblib import cpu_count, effective_n_jobs
from joblib.parallel import LokyBackend, SequentialBackend, get_active_backend
from sklearn.utils.parallel import Parallel, delayed

__all__ = [
    "BATCH_POINTS",
    "batch_bounds",
    "batch_config",
    "effective_threads",
    "map_batches",
    "parallel_rows",
    "task_threads",
]

# Rows per chunk at least; chunks are also small enough to balance the load.
_MIN_CHUNK = 4096
_CHUNKS_PER_THREAD = 8

# Points per batch at most (by default) when batches are dispatched to a
# joblib backend: about 1 M points keeps the per-task overhead (pickling,
# scheduling: milliseconds) small against the work (PFH k=10: about a
# second per million points and core) and a batch's temporaries to a few
# hundred MB.
BATCH_POINTS = 1_000_000
_BATCH_POINTS = contextvars.ContextVar("skpcd_batch_points", default=None)

# Inside a batch run by map_batches: the threads of that task (set per
# thread, for the tasks of a threading backend).
_TASK = threading.local()


def effective_threads(n_jobs):
    """Number of threads for ``n_jobs``: None is 1 (unless a
    :func:`joblib.parallel_config` context says otherwise), -1 all cores.

    Inside a batch dispatched by :func:`map_batches`, the threads given to
    that batch, whatever ``n_jobs`` says.

    Parameters
    ----------
    n_jobs : int or None
        Requested parallelism.

    Returns
    -------
    n_threads : int
        At least 1.
    """
    task = getattr(_TASK, "n_threads", None)
    if task is not None:
        return task
    return max(1, int(effective_n_jobs(n_jobs)))


def task_threads():
    """The threads of the batch of :func:`map_batches` running here, or None
    outside one (e.g. to limit BLAS threads in a dispatched batch only).

    Returns
    -------
    n_threads : int or None
        The cores left to the batch's task.
    """
    return getattr(_TASK, "n_threads", None)


# Wall seconds in the parallel sections, by name, while thread_profile()
# collects them (for benchmarks/bench_threads.py); None otherwise.
_PROFILE = None
_PROFILE_DEPTH = threading.local()


@contextlib.contextmanager
def parallel_section(name):
    """Mark a section whose work is spread over the threads.

    A no-op unless :func:`thread_profile` is collecting; then the wall time
    of the outermost section is added to ``name``'s total. Everything
    outside the sections is the serial part of a call (the part that no
    thread count shortens).
    """
    profile = _PROFILE
    depth = getattr(_PROFILE_DEPTH, "depth", 0)
    if profile is None or depth:
        yield
        return
    _PROFILE_DEPTH.depth = 1
    t0 = time.perf_counter()
    try:
        yield
    finally:
        _PROFILE_DEPTH.depth = 0
        profile[name] = profile.get(name, 0.0) + time.perf_counter() - t0


@contextlib.contextmanager
def thread_profile():
    """Collect the wall time of every :func:`parallel_section` (one caller
    thread at a time), by section name, into the dict it yields."""
    global _PROFILE
    _PROFILE = {}
    try:
        yield _PROFILE
    finally:
        _PROFILE = None


def parallel_rows(kernel, n_rows, n_threads, *args, min_chunk=_MIN_CHUNK):
    """Run ``kernel(lo, hi, *args)`` over ``range(n_rows)`` in chunks.

    Parameters
    ----------
    kernel : callable
        A numba function compiled with ``nogil=True`` (it must release the
        GIL for the threads to run at once); it writes its results into
        arrays among ``args``, rows ``lo`` to ``hi`` only.
    n_rows : int
        Number of rows.
    n_threads : int
        Threads, at least 1 (:func:`effective_threads` of the estimator's
        ``n_jobs``, resolved at the boundary).
    *args
        Passed to the kernel.
    min_chunk : int, default=4096
        Fewest rows per chunk (lower for expensive rows).
    """
    if isinstance(n_threads, bool) or not isinstance(n_threads, (int, np.integer)):
        raise TypeError(
            "parallel_rows takes a thread count: resolve n_jobs with "
            f"effective_threads at the boundary, got {n_threads!r}"
        )
    n_threads = max(1, int(n_threads))
    with parallel_section(getattr(kernel, "__name__", "kernel")):
        _run_rows(kernel, n_rows, n_threads, args, min_chunk)


def _run_rows(kernel, n_rows, n_threads, args, min_chunk):
    if n_threads == 1 or n_rows <= min_chunk:
        kernel(0, n_rows, *args)
        return
    size = max(min_chunk, -(-n_rows // (n_threads * _CHUNKS_PER_THREAD)))
    bounds = [(lo, min(n_rows, lo + size)) for lo in range(0, n_rows, size)]
    # compile (or load) the kernel once, before the threads race to do it:
    # an empty range, so that no chunk runs alone
    kernel(0, 0, *args)
    with ThreadPoolExecutor(n_threads) as pool:
        for future in [pool.submit(kernel, lo, hi, *args) for lo, hi in bounds]:
            future.result()


@contextlib.contextmanager
def batch_config(*, batch_points=None):
    """Set the batch size of :func:`map_batches` within a ``with`` block.

    Parameters
    ----------
    batch_points : int or None, default=None
        Points per batch at most (a larger cloud is a batch of its own);
        None restores the default, :data:`BATCH_POINTS` (1 000 000).

    Yields
    ------
    None

    Examples
    --------
    >>> import joblib
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.features import FPFHTransformer
    >>> from skpcd.utils import batch_config
    >>> clouds = make_point_clouds(4, n_points=50, random_state=0)
    >>> with joblib.parallel_config(backend="threading", n_jobs=2):
    ...     with batch_config(batch_points=100):  # 2 clouds per batch
    ...         fpfh = FPFHTransformer(n_neighbors=8).transform(clouds)
    >>> len(fpfh)
    4
    """
    if batch_points is not None and not (
        isinstance(batch_points, (int, np.integer))
        and not isinstance(batch_points, bool)
        and batch_points >= 1
    ):
        raise ValueError(
            f"batch_points must be a positive integer or None, got {batch_points!r}"
        )
    token = _BATCH_POINTS.set(None if batch_points is None else int(batch_points))
    try:
        yield
    finally:
        _BATCH_POINTS.reset(token)


def batch_bounds(sizes, batch_points):
    """Cut items into contiguous batches of at most ``batch_points`` points.

    Items are taken in order; a batch closes before the item that would
    take it past ``batch_points``. An item is never split: one larger than
    ``batch_points`` is a batch of its own.

    Parameters
    ----------
    sizes : array-like of int of shape (n_items,)
        Points of each item (non-negative).
    batch_points : int
        Points per batch at most (at least 1).

    Returns
    -------
    bounds : list of (int, int)
        ``(start, stop)`` of each batch, covering ``range(n_items)`` in
        order; empty for no item.

    Examples
    --------
    >>> from skpcd.utils._parallel import batch_bounds
    >>> batch_bounds([3, 3, 3, 10, 1], 6)
    [(0, 2), (2, 3), (3, 4), (4, 5)]
    """
    sizes = np.asarray(sizes, dtype=np.int64).reshape(-1)
    if batch_points < 1:
        raise ValueError(f"batch_points must be at least 1, got {batch_points}")
    if (sizes < 0).any():
        raise ValueError("sizes must not be negative")
    bounds, start, total = [], 0, 0
    for i, n in enumerate(sizes.tolist()):
        if total + n > batch_points and i > start:
            bounds.append((start, i))
            start, total = i, 0
        total += n
    if len(sizes):
        bounds.append((start, len(sizes)))
    return bounds


def chosen_backend():
    """The joblib backend that batches are dispatched to, or None to run
    in-process.

    joblib's public :func:`joblib.parallel.get_active_backend` says which
    backend is active. None (in-process) inside a batch of
    :func:`map_batches`, for the sequential backend, for a backend joblib
    itself set in its workers (``nesting_level`` above 0), and for loky,
    joblib's default: it cannot be told from an explicit
    ``parallel_config(backend="loky")``, and skpcd's own threads (its
    kernels release the GIL) use this machine's cores without pickling
    clouds to worker processes. Every other backend gets the batches:
    Dask, Ray or any backend registered with
    :func:`joblib.register_parallel_backend`, and joblib's threading and
    multiprocessing backends.
    """
    if getattr(_TASK, "n_threads", None) is not None:
        return None
    backend, _ = get_active_backend()
    if isinstance(backend, (LokyBackend, SequentialBackend)):
        return None
    if (getattr(backend, "nesting_level", 0) or 0) > 0:
        return None
    return backend


def dask_hosts(backend):
    """Threads of all Dask workers per host, if ``backend`` is joblib's Dask
    backend; else None."""
    client = getattr(backend, "client", None)
    if client is None or type(backend).__name__ != "DaskDistributedBackend":
        return None
    from distributed.comm import get_address_host

    hosts = {}
    for address, n in client.ncores().items():
        host = get_address_host(address)
        hosts[host] = hosts.get(host, 0) + int(n)
    return hosts


def _task_threads(n_threads, hosts):
    """The threads of a batch where it runs: ``n_threads``, or on a Dask
    worker the cores of its machine shared by all worker threads there."""
    if hosts is None:
        return n_threads
    try:
        from distributed import get_worker
        from distributed.comm import get_address_host

        worker = get_worker()
    except (ImportError, ValueError):  # not on a worker
        return n_threads
    busy = hosts.get(get_address_host(worker.address), 0)
    if not busy:  # a worker that joined since: its own threads
        busy = getattr(getattr(worker, "state", worker), "nthreads", 1)
    return max(1, cpu_count() // max(busy, 1))


def run_batch(func, batch, n_threads, hosts):
    """Run one batch of :func:`map_batches` with the threads of its task."""
    n_threads = _task_threads(n_threads, hosts)
    before = getattr(_TASK, "n_threads", None)
    _TASK.n_threads = n_threads
    try:
        return func(batch, n_threads)
    finally:
        _TASK.n_threads = before


def _concat(parts):
    """One result from the results of consecutive batches."""
    first = parts[0]
    if len(parts) == 1:
        return first
    if isinstance(first, tuple):
        return tuple(_concat(list(p)) for p in zip(*parts))
    if isinstance(first, list):
        return [x for part in parts for x in part]
    return np.concatenate(parts, axis=0)


def map_batches(
    func, items, n_jobs=None, *, sizes=None, batch_points=None, bounded=False
):
    """``func(items, n_threads)``, in batches of items on a joblib backend.

    Outside a :func:`joblib.parallel_config` context that chooses a
    backend (and with joblib's default backend, loky, even when chosen:
    see ``chosen_backend``), this is ``func(items, effective_threads(n_jobs))``:
    one call, in-process. Inside one (``backend="dask"`` with a
    ``dask.distributed.Client``, ``"threading"``, ``"multiprocessing"``,
    any registered backend), the items are cut into contiguous
    batches of whole items (:func:`batch_bounds`) dispatched with
    :class:`sklearn.utils.parallel.Parallel` (scikit-learn's configuration
    goes with them), and the results are joined in order.

    How ``n_jobs`` and the numba threads combine:

    - no backend chosen: ``n_jobs`` threads for the kernels (None: 1, or
      the ``n_jobs`` of a ``parallel_config`` without a backend; -1: all
      cores);
    - a backend chosen: ``n_jobs`` is the ``Parallel`` ``n_jobs``, the
      batches run at once (None: the context's; the Dask backend always
      uses all worker threads), and each batch's kernels run on the cores
      left to its task: ``inner_max_num_threads`` when the context sets
      it; on a Dask worker, the cores of its machine divided by the
      threads of all workers on that machine; otherwise the cores of this
      machine divided by the batches run at once. There is no
      oversubscription, and no batch starts a process pool of its own.

    The batches are at most ``batch_points`` points, and at most the total
    divided by the batches run at once, so that every worker gets work.
    The functions given here compute each item on its own, so the result
    does not depend on the batches or on where they run: it is
    bit-identical to the in-process call.

    Parameters
    ----------
    func : callable
        ``func(batch, n_threads)``, ``batch`` a slice of ``items`` and
        ``n_threads`` the threads for its kernels (an int), returns a
        list (one entry per item), an array (rows in item order) or a
        tuple of those. Pickled with the batch for process backends.
    items : sequence
        Clouds, descriptor arrays or query rows: a list, a tuple or an
        array, sliced into batches.
    n_jobs : int or None, default=None
        The estimator's ``n_jobs``, as above.
    sizes : array-like of int of shape (n_items,), default=None
        Points of each item; None: ``len`` of each item.
    batch_points : int, default=None
        Points per batch at most; None: the value of :func:`batch_config`,
        by default :data:`BATCH_POINTS`.
    bounded : bool, default=False
        Also cut the items into batches when no backend is chosen, and run
        them one after the other in-process (each on ``n_jobs`` threads):
        for functions whose result is much smaller than their temporaries
        (pooled descriptors), so that peak memory is that of one batch, not
        of all items.

    Returns
    -------
    result : list, ndarray or tuple
        What ``func(items, n_threads)`` returns.

    Examples
    --------
    >>> import joblib
    >>> import numpy as np
    >>> from skpcd.utils._parallel import map_batches
    >>> clouds = [np.zeros((n, 3)) for n in (2, 3, 4)]
    >>> def sizes(batch, n_threads):
    ...     return [len(c) for c in batch]
    >>> with joblib.parallel_config(backend="threading", n_jobs=2):
    ...     map_batches(sizes, clouds, batch_points=5)
    [2, 3, 4]
    """
    backend = chosen_backend() if len(items) else None
    if backend is None and not (bounded and len(items) > 1):
        return func(items, effective_threads(n_jobs))
    if sizes is None:
        sizes = [len(x) for x in items]
    sizes = np.asarray(sizes, dtype=np.int64)
    if sizes.shape != (len(items),):
        raise ValueError(
            f"sizes must have one entry per item ({len(items)}), "
            f"got shape {sizes.shape}"
        )
    if batch_points is None:
        batch_points = _BATCH_POINTS.get() or BATCH_POINTS
    if backend is None:  # bounded, in-process: one batch after the other
        bounds = batch_bounds(sizes, int(batch_points))
        n_threads = effective_threads(n_jobs)
        return _concat([func(items[lo:hi], n_threads) for lo, hi in bounds])
    n_tasks = max(1, int(effective_n_jobs(n_jobs)))
    # every task gets work: at most the total divided by the tasks
    even = -(-int(sizes.sum()) // n_tasks)
    bounds = batch_bounds(sizes, max(1, min(int(batch_points), even)))
    inner = getattr(backend, "inner_max_num_threads", None)
    n_threads = inner or max(1, cpu_count() // n_tasks)
    hosts = None if inner else dask_hosts(backend)
    tasks = (
        delayed(run_batch)(func, items[lo:hi], n_threads, hosts) for lo, hi in bounds
    )
    return _concat(Parallel(n_jobs=n_jobs, batch_size=1)(tasks))
