"""numba kernels of 3D grid sampling: cell keys and distances to the cell
centres, then the point nearest its centre in every cell."""

import math

from numba import njit


@njit(cache=True, nogil=True)
def cell_keys_centres(lo, hi, xyz, corner, h, dims, keys, d2):
    """Cell key ``(x * ny + y) * nz + z`` of points ``lo`` to ``hi`` and
    their squared distance to the centre of their cell, into ``keys`` and
    ``d2``. Computed from ``xyz - corner`` (the cloud's minimum: exact for a
    cloud far from the origin), in the arithmetic of NumPy's
    ``((u - (floor(u / h) + 0.5) * h) ** 2).sum(axis=1)``."""
    ny, nz = dims[1], dims[2]
    for i in range(lo, hi):
        ux = xyz[i, 0] - corner[0]
        uy = xyz[i, 1] - corner[1]
        uz = xyz[i, 2] - corner[2]
        cx = math.floor(ux / h)
        cy = math.floor(uy / h)
        cz = math.floor(uz / h)
        keys[i] = (cx * ny + cy) * nz + cz
        ex = ux - (cx + 0.5) * h
        ey = uy - (cy + 0.5) * h
        ez = uz - (cz + 0.5) * h
        d2[i] = (ex * ex + ey * ey) + ez * ez


@njit(cache=True, nogil=True)
def nearest_in_cells(lo, hi, sorted_keys, order, d2, chosen):
    """For every run of equal keys that starts at a position ``lo`` to
    ``hi`` of ``sorted_keys`` (the keys sorted stably, point ``order[t]``
    at position ``t``), flag in ``chosen`` the point nearest its cell's
    centre, the lowest index among ties (a run lists its points by index).
    A run that starts in the range is followed past ``hi``; one that
    started before it is left to the range holding its start."""
    n = len(sorted_keys)
    t = lo
    while t < hi and t > 0 and sorted_keys[t] == sorted_keys[t - 1]:
        t += 1
    while t < hi:
        best = order[t]
        best_d = d2[best]
        u = t + 1
        while u < n and sorted_keys[u] == sorted_keys[t]:
            j = order[u]
            if d2[j] < best_d:
                best, best_d = j, d2[j]
            u += 1
        chosen[best] = True
        t = u
