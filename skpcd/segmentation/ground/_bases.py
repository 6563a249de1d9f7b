"""The second pass that gives the bases of objects back to them.

CSF and SMRF take the lowest 0.1-0.4 m of cars, bins, hedges and the feet
of poles for ground on street scans: those points lie within the filters'
thresholds of a terrain that is smooth over metres. A second SMRF over the
ground points alone, with small cells and a small window (what rises over
less than 4 m across is not terrain), finds them.
"""

from types import SimpleNamespace

import numpy as np

from skpcd.segmentation.ground._smrf import smrf_fit, smrf_ground

__all__ = ["BASES", "BASE_THRESHOLD", "without_bases"]

# SMRF's parameters in the second pass, and the height above its terrain
# from which a ground point is an object's base (or 3 standard deviations
# of the terrain's roughness when the ground is rougher). Chosen by the
# ground taken from the boxed cars of the real KITTI and PandaSet sweeps
# (benchmarks/bench_scan_kinds.py, results in benchmarks/results/
# scan_kinds.txt), among cells of 0.25 and 0.5 m, windows of 1.5 to 3 m and
# thresholds of 0.07 to 0.15 m.
BASES = {"cell": 0.5, "window": 2.0, "slope": 0.15, "scalar": 1.25}
BASE_THRESHOLD = 0.07


def without_bases(xyz, ground, n_threads=1):
    """Ground flags without the bases of objects.

    The ground points of a first filter are filtered again by SMRF with
    ``BASES`` (small cells and window); those above its terrain by more
    than ``max(BASE_THRESHOLD, 3 * sigma)``, ``sigma`` the robust standard
    deviation (1.4826 times the median absolute deviation) of the heights
    of the kept ground points above the terrain, are no longer ground.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The scene.
    ground : ndarray of shape (n_points,), dtype bool
        The first filter's flags.
    n_threads : int, default=1
        Threads of the second filter.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool
        A copy of ``ground`` with the bases of objects set to False.
    """
    idx = np.flatnonzero(ground)
    if len(idx) < 3:
        return ground.copy()
    pts = np.ascontiguousarray(xyz[idx], dtype=np.float64)
    params = SimpleNamespace(**BASES, threshold=BASE_THRESHOLD, low_noise=None)
    kept, terrain = smrf_fit(pts, params, n_threads)
    height = pts[:, 2] - terrain.sample(pts, False, n_threads)
    with np.errstate(invalid="ignore"):
        sigma = 1.4826 * np.nanmedian(np.abs(height[kept])) if kept.any() else 0.0
    if 3.0 * sigma > BASE_THRESHOLD:
        params.threshold = 3.0 * float(sigma)
        kept = smrf_ground(terrain, pts, params, n_threads)
    out = ground.copy()
    out[idx[~kept]] = False
    return out
