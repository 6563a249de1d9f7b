"""Every process-wide memory measure of skpcd, each with its reason.

The descriptor kernels and the tiled segmentation hold large temporaries
(a neighbour search: tens of MB per million points; an output: up to
500 bytes per point). glibc keeps freed blocks below its mmap threshold in
the heap, and raises that threshold itself after the first large free, so
without care a call's temporaries stay resident after it returns and the
next call's peak adds up with them. The measures, all no-ops where the C
library is not glibc:

- :func:`release_free_memory`: ``malloc_trim(0)`` at the points where the
  temporaries of one stage are freed and the next allocates its output;
- :func:`unshared_zeros`: a large output in an anonymous memory map of its
  own (returned to the system with its last view), pre-faulted above
  32 MiB;
- :func:`heap_for_arrays`: in a Dask worker (whose nanny sets
  ``MALLOC_TRIM_THRESHOLD_``, which pins the mmap threshold at 128 KiB),
  the threshold raised back to 32 MiB so that temporaries come from the
  heap instead of freshly zeroed mappings.

``benchmarks/bench_memory.py`` measures each against its absence (peak RSS
and time of a fresh process; results in ``benchmarks/README.md``): on the
DALES objects the trim lowers the FPFH peak by 18 % and the PFH peak by
8 %, freeing the normals before the FPFH output (the descriptors' pair and
final stages) saves their size, and the pre-faulted own maps keep PFH at
9 s instead of 13 s (their peak is the same as the heap's once the trim
runs).
"""

import ctypes
import mmap
import os

import numpy as np

__all__ = ["heap_for_arrays", "release_free_memory", "unshared_zeros"]

# Outputs at least this large get a map of their own (smaller ones: np.zeros).
_OWN_MAP = 1 << 20
# Outputs at least this large are faulted in at once (MAP_POPULATE).
_POPULATE = 32 << 20
# glibc's upper bound for the mmap threshold (M_MMAP_THRESHOLD is -3).
_M_MMAP_THRESHOLD = -3
_HEAP_THRESHOLD = 32 << 20


def _libc():
    """glibc, or None (another C library, or none found)."""
    if not hasattr(_libc, "lib"):
        try:
            lib = ctypes.CDLL("libc.so.6")
            if not (hasattr(lib, "malloc_trim") and hasattr(lib, "mallopt")):
                lib = None
        except OSError:
            lib = None
        _libc.lib = lib
    return _libc.lib


def release_free_memory():
    """Give the memory that the C heap holds free back to the system.

    glibc keeps freed blocks below its (self-raising) mmap threshold in the
    heap, so the large temporaries of a search (tens of MB) stay in the
    resident set after they are freed; ``malloc_trim`` returns their pages
    before the kernels allocate their outputs, which lowers the peak. A
    no-op where the C library is not glibc.
    """
    lib = _libc()
    if lib is not None:
        lib.malloc_trim(0)


def unshared_zeros(shape, dtype):
    """A zeroed output array; a large one in its own anonymous memory map.

    The C heap keeps a freed block below its (self-raising) mmap threshold,
    so the output of one call would stay resident after the caller drops
    it, and the next call's peak would add up with it. Mapped on its own,
    an output goes back to the system with its last view; its pages are
    zero, and resident from the start above 32 MiB (the kernels write them
    all), as written below.
    """
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    if nbytes < _OWN_MAP:
        return np.zeros(shape, dtype=dtype)
    if hasattr(mmap, "MAP_PRIVATE"):
        # private: a shared anonymous map is shmem, slower to fault in.
        # Populated at once: faulted in page by page from the kernel threads,
        # the faults contend (PFH k=10, two threads: 1.6 s of system time
        # against 0.3 s with one). Huge pages (MADV_HUGEPAGE, as numpy
        # advises) are not asked for: on the benchmark VM they made the
        # first call in a process on a 2.6M point cloud 1.5x slower
        flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
        if nbytes >= _POPULATE:  # small outputs: their pages as written
            flags |= getattr(mmap, "MAP_POPULATE", 0)
        buf = mmap.mmap(-1, nbytes, flags=flags)
    else:
        buf = mmap.mmap(-1, nbytes)
    return np.frombuffer(buf, dtype=dtype).reshape(shape)


_HEAP = []


def heap_for_arrays():
    """Let glibc serve array temporaries from the heap in a Dask worker.

    A Dask nanny starts its worker with ``MALLOC_TRIM_THRESHOLD_`` set,
    which also fixes glibc's mmap threshold at 128 KiB: every temporary
    array above that is then a fresh mapping whose pages the kernel faults
    in and zeroes, which made the tile steps two to three times slower on a
    worker than in the driver. Raising the threshold to glibc's own upper
    bound (32 MiB) undoes that; the heap is still trimmed after each tile
    (:func:`release_free_memory`), which is what the setting is for. Once
    per process, and only where the variable is set.

    Returns
    -------
    raised : bool
        Whether the threshold was raised in this process (the caller then
        trims the heap after its work).
    """
    if _HEAP:
        return _HEAP[0]
    ok = False
    if "MALLOC_TRIM_THRESHOLD_" in os.environ:
        lib = _libc()
        if lib is not None:
            ok = bool(lib.mallopt(_M_MMAP_THRESHOLD, _HEAP_THRESHOLD))
    _HEAP.append(ok)
    return ok
