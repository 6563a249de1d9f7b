"""Simulated LiDAR scans of streets: scene layout, object catalogue, scanners.

Modules: ``_primitives`` (shapes and their packing), ``_raycast`` (the numba
kernels: intersections, the grid, pulses of each scan pattern, the scan
loop), ``_scanners`` (scan patterns and their default numbers),
``_catalogue`` (object builders per class), ``_layout`` (the street) and
``_scene`` (the public functions).
"""

from skpcd.datasets._street._scene import (
    SCAN_PATTERNS,
    STREET_CLASSES,
    STREET_OBJECT_CLASSES,
    make_street_objects,
    make_street_scene,
)

__all__ = [
    "SCAN_PATTERNS",
    "STREET_CLASSES",
    "STREET_OBJECT_CLASSES",
    "make_street_objects",
    "make_street_scene",
]


def kernels_cached():
    """Whether numba's cache holds the compiled scan kernel.

    False on the first use after an installation (or with an empty
    ``NUMBA_CACHE_DIR``): the first scan then compiles the kernels, for
    about a minute (the source of the kernels changed: again). True when
    they are already loaded in this process.
    """
    from skpcd.datasets._street._raycast import simulate

    if simulate.signatures:
        return True
    try:  # the index lists the compiled versions, empty when stale or absent
        return bool(simulate._cache._cache_file._load_index())
    except Exception:  # numba's private layout changed: do not guess
        return True
