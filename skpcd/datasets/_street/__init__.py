"""Simulated LiDAR scans of streets: scene layout, object catalogue, scanners.

Modules: ``_primitives`` (shapes and their packing), ``_raycast`` (the numba
kernels: intersections, the grid, pulses of each scan pattern, the scan
loop), ``_scanners`` (scan patterns and their default numbers),
``_catalogue`` (object builders per class), ``_layout`` (the street) and
``_scene`` (the public functions).
"""

from skpcd.datasets._street._scanners import SPINNING_SENSORS
from skpcd.datasets._street._scene import (
    SCAN_PATTERNS,
    STREET_CLASSES,
    STREET_OBJECT_CLASSES,
    make_street_objects,
    make_street_scene,
)

__all__ = [
    "SCAN_PATTERNS",
    "SPINNING_SENSORS",
    "STREET_CLASSES",
    "STREET_OBJECT_CLASSES",
    "make_street_objects",
    "make_street_scene",
]
