"""KITTI Velodyne ``.bin`` scans: float32 records of x, y, z and remission.

The layout of the KITTI odometry and object benchmarks and of SemanticKITTI
(``sequences/NN/velodyne/FFFFFF.bin``): no header, 16 bytes per point,
little-endian float32 ``x, y, z, remission`` (remission 0 to 1, read as the
field ``intensity``). The file size must be a multiple of 16 bytes; the
per-point labels of SemanticKITTI live in a ``.label`` file beside it
(:func:`skpcd.io.read_point_labels`).
"""

import numpy as np

from skpcd.exceptions import PointCloudFileError

RECORD = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])


def read(path):
    """Read a ``.bin`` scan into ``(fields, info)``."""
    size = path.stat().st_size
    if size % RECORD.itemsize:
        raise PointCloudFileError(
            path,
            f"a KITTI .bin scan holds 16 bytes per point (float32 x, y, z, "
            f"remission); its {size} bytes are not a multiple of 16.",
        )
    data = np.fromfile(path, dtype=RECORD)
    points = np.column_stack([data[c].astype(np.float64) for c in "xyz"])
    fields = {c: points[:, j] for j, c in enumerate("xyz")}
    fields["intensity"] = data["intensity"]
    return fields, {"xyz": points}


def write(path, fields, *, encoding=None):
    """Write x, y, z and ``intensity`` (0 where absent) as float32 records."""
    if encoding not in (None, "binary"):
        raise ValueError(f".bin scans are always binary; got encoding={encoding!r}")
    other = sorted(set(fields) - {"x", "y", "z", "intensity"})
    if other:
        raise ValueError(
            "a KITTI .bin scan holds x, y, z and intensity only; cannot write "
            + ", ".join(other)
            + " (write LAS/LAZ or PLY to keep them)"
        )
    out = np.zeros(len(fields["x"]), dtype=RECORD)
    for name in fields:
        out[name] = np.asarray(fields[name])
    out.tofile(path)
