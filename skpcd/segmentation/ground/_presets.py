"""The parameters of :class:`~skpcd.segmentation.GroundFilter` for each kind
of scan, in one place."""

__all__ = ["FROM_FILE", "GROUND_PRESETS"]

# "aerial" are the defaults of GroundFilter (those of Pingel et al. and of
# PDAL's filters.smrf); "mobile" SMRF for dense, low urban mobile scans;
# "csf" the cloth simulation filter with the defaults of its authors (cloth
# 1 m, hard cloth, slope smoothing) but a 0.3 m threshold instead of 0.5,
# which takes about half as many object points for ground at the cost of a
# slightly lower ground recall (benchmarks/bench_ground.py); "street" is
# "csf" followed by the pass that gives the bases of objects back
# (keep_bases), the default of the scans made from the street (SCAN_KINDS in
# skpcd/segmentation/_scan_kind.py).
GROUND_PRESETS = {
    "csf": {
        "method": "csf",
        "cell": 1.0,
        "threshold": 0.3,
        "rigidness": 3,
        "slope_smooth": True,
    },
    "aerial": {
        "cell": 1.0,
        "slope": 0.15,
        "window": 18.0,
        "threshold": 0.5,
        "scalar": 1.25,
    },
    "street": {
        "method": "csf",
        "cell": 1.0,
        "threshold": 0.3,
        "rigidness": 3,
        "slope_smooth": True,
        "keep_bases": True,
    },
    "mobile": {
        "cell": 0.5,
        "slope": 0.15,
        "window": 10.0,
        "threshold": 0.25,
        "scalar": 1.25,
    },
}

# Besides the presets, ground="from-file" (--ground from-file) takes the
# ground a scan already carries in its classification
# (skpcd/segmentation/ground/_classified.py).
FROM_FILE = "from-file"
