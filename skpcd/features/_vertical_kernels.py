"""numba kernels of :mod:`skpcd.features._vertical`."""

import math

from numba import njit

__all__ = ["geometric_median"]


@njit(cache=True, nogil=True)
def geometric_median(x, y, max_iter, tol):
    """The point minimising the sum of distances to ``(x[i], y[i])``.

    Weiszfeld's iterations from the mean; a point closer than ``tol`` to
    the estimate gets the weight ``1 / tol``. Stops when a step is shorter
    than ``tol`` or after ``max_iter`` steps.
    """
    n = x.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += x[i]
        cy += y[i]
    cx /= n
    cy /= n
    for _ in range(max_iter):
        sw = 0.0
        sx = 0.0
        sy = 0.0
        for i in range(n):
            d = math.hypot(x[i] - cx, y[i] - cy)
            w = 1.0 / max(d, tol)
            sw += w
            sx += w * x[i]
            sy += w * y[i]
        nx = sx / sw
        ny = sy / sw
        step = math.hypot(nx - cx, ny - cy)
        cx = nx
        cy = ny
        if step <= tol:
            break
    return cx, cy
