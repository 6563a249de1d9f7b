"""Scoped numba thread counts from scikit-learn style ``n_jobs``."""

import contextlib

from joblib import effective_n_jobs

__all__ = ["numba_threads"]


@contextlib.contextmanager
def numba_threads(n_jobs):
    """Run the body with ``n_jobs`` numba threads, restoring the count afterwards.

    ``n_jobs`` follows scikit-learn: None means 1 (unless a
    :func:`joblib.parallel_config` context says otherwise), -1 all cores,
    and the result is capped at ``numba.config.NUMBA_NUM_THREADS``.
    ``numba.set_num_threads`` is thread-local, so this only affects the
    calling thread.

    Parameters
    ----------
    n_jobs : int or None
        Requested parallelism.

    Yields
    ------
    n_threads : int
        The number of threads in force.
    """
    import numba

    n = max(1, min(int(effective_n_jobs(n_jobs)), numba.config.NUMBA_NUM_THREADS))
    previous = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        yield n
    finally:
        numba.set_num_threads(previous)
