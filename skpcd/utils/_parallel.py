"""Threads for the numba kernels, from scikit-learn style ``n_jobs``.

Kernels are serial ``nogil`` numba functions over a range of rows,
``kernel(lo, hi, *args)``, writing into arrays allocated by the caller; this
module cuts the rows into chunks and runs them on a pool of Python threads.
Compared with numba's ``parallel=True``, this compiles several times faster,
needs no threading layer, and the thread count is an argument, not global
state.
"""

from concurrent.futures import ThreadPoolExecutor

__all__ = ["effective_threads", "parallel_rows", "release_free_memory"]

# Rows per chunk at least; chunks are also small enough to balance the load.
_MIN_CHUNK = 4096
_CHUNKS_PER_THREAD = 8


def effective_threads(n_jobs):
    """Number of threads for ``n_jobs``: None is 1 (unless a
    :func:`joblib.parallel_config` context says otherwise), -1 all cores.

    Parameters
    ----------
    n_jobs : int or None
        Requested parallelism.

    Returns
    -------
    n_threads : int
        At least 1.
    """
    from joblib import effective_n_jobs

    return max(1, int(effective_n_jobs(n_jobs)))


def parallel_rows(kernel, n_rows, n_jobs, *args, min_chunk=_MIN_CHUNK):
    """Run ``kernel(lo, hi, *args)`` over ``range(n_rows)`` in chunks.

    Parameters
    ----------
    kernel : callable
        A numba function compiled with ``nogil=True`` (it must release the
        GIL for the threads to run at once); it writes its results into
        arrays among ``args``, rows ``lo`` to ``hi`` only.
    n_rows : int
        Number of rows.
    n_jobs : int or None
        Threads, as in scikit-learn.
    *args
        Passed to the kernel.
    min_chunk : int, default=4096
        Fewest rows per chunk (lower for expensive rows).
    """
    n_threads = effective_threads(n_jobs)
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


_LIBC = []


def release_free_memory():
    """Give the memory that the C heap holds free back to the system.

    glibc keeps freed blocks below its (self-raising) mmap threshold in the
    heap, so the large temporaries of a search (tens of MB) stay in the
    resident set after they are freed; ``malloc_trim`` returns their pages
    before the kernels allocate their outputs, which lowers the peak. A
    no-op where the C library is not glibc.
    """
    if not _LIBC:
        try:
            import ctypes

            libc = ctypes.CDLL("libc.so.6")
            _LIBC.append(libc.malloc_trim)
        except (OSError, AttributeError):
            _LIBC.append(None)
    if _LIBC[0] is not None:
        _LIBC[0](0)
