"""Union-find over an array ``parent`` (``parent[t] == t`` at a root), for
the numba kernels of the density clustering and of the structures.

Both helpers are inlined: they take an array, and a call that is not
inlined costs an atomic reference-count update of it each time.
"""

from numba import njit


@njit(cache=True, nogil=True, inline="always")
def find_root(parent, t):
    """Root of ``t`` with path halving. Inlined."""
    while parent[t] != t:
        parent[t] = parent[parent[t]]
        t = parent[t]
    return t


@njit(cache=True, nogil=True, inline="always")
def union_lower(parent, s, t):
    """Join the trees of ``s`` and ``t`` (``s``'s root found first), the
    lower root kept as the root of both. Inlined."""
    a = find_root(parent, s)
    b = find_root(parent, t)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b
