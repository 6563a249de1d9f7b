"""The options of segmentation that ``skpcd segment`` and ``skpcd identify``
share (those of :func:`skpcd.segmentation.segment_scene`), and the parsing
of their values."""

from skpcd.cli._common import add_n_jobs, add_output_options, add_scheduler

# The choices of --ground and --method, written out (as GROUND_PRESETS of
# skpcd.segmentation.ground has them, tests/cli/test_startup.py checks) so
# that building the parser loads no library: ``skpcd --help`` imports
# neither scikit-learn nor numba.
GROUND_CHOICES = ("auto", "street", "csf", "aerial", "mobile", "from-file", "none")
METHODS = ("dbscan", "euclidean", "range-image")


def add_segmentation_options(p):
    """The options of :func:`skpcd.segmentation.segment_scene`."""
    p.add_argument(
        "--ground",
        choices=GROUND_CHOICES,
        default="auto",
        help="ground removal preset (GroundFilter): auto, chosen from what the "
        "scan is (aerial for an airborne tile, street for the others; said on "
        "stderr); street, the cloth simulation filter with the bases of objects "
        "given back; csf, the cloth simulation filter alone; aerial or mobile, "
        "SMRF; from-file, the ground the scan already carries in its "
        "classification (class 2, or --ground-codes); or none (default auto)",
    )
    p.add_argument(
        "--ground-codes",
        type=ground_codes,
        default=(2,),
        metavar="CODES",
        help="with --ground from-file, the classification codes of ground "
        "points, comma-separated (default 2, ASPRS ground; e.g. 2,8)",
    )
    p.add_argument(
        "--sensor",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=None,
        help="position of the sensor of a single sweep, if known (helps "
        "--ground auto tell a robot from a car; with --method range-image, "
        "where the rays start, default the origin, or 1.85 m above the "
        "ground under it when the origin is on the road)",
    )
    p.add_argument(
        "--no-structures",
        dest="structures",
        action="store_false",
        help="cluster every non-ground point alike: no facade and wire segments, "
        "no splitting of clusters at vertical trunks",
    )
    p.add_argument(
        "--method",
        choices=METHODS,
        default="dbscan",
        help="dbscan: AutoEpsDBSCAN, eps from the data unless --eps; euclidean: "
        "EuclideanClusters, eps 0.2 unless --eps; range-image: one sweep of a "
        "spinning sensor cut in its range image (rings by azimuth columns; "
        "the rings of a ring or scanner_channel field when the file has one), "
        "fast, fastest with --no-structures: with --ground auto the ground is "
        "walked along the image's columns, and neighbouring pixels are joined "
        "by the angle between them; the sweep must be in its sensor's frame, "
        "or --sensor X Y Z given; --eps, --eps-scale and --min-samples do not "
        "apply, and --tile-size is refused (default dbscan)",
    )
    p.add_argument(
        "--eps",
        type=float,
        default=None,
        help="clustering radius, in the units of the coordinates (dbscan, euclidean)",
    )
    p.add_argument(
        "--unit",
        type=unit_length,
        default="auto",
        metavar="METRES|auto",
        help="length of a coordinate unit in metres (0.3048 for feet): the "
        "defaults are in metres and a scan in other units is segmented in "
        "metres; auto: the unit of a LAS/LAZ file's CRS, else metres "
        "(default auto)",
    )
    p.add_argument(
        "--eps-scale",
        type=float,
        default=2.5,
        help="dbscan without --eps: the radius is this multiple of the knee "
        "distance of the k-distance curve (default 2.5)",
    )
    p.add_argument(
        "--min-samples", type=int, default=5, help="DBSCAN core count (default 5)"
    )
    p.add_argument(
        "--min-size", type=int, default=50, help="smallest segment kept (default 50)"
    )
    p.add_argument("--max-size", type=int, default=None, help="largest segment kept")
    p.add_argument("--random-state", type=int, default=0, help="seed (default 0)")
    p.add_argument(
        "--keep-fields",
        action="store_true",
        help="copy the scene's extra fields (intensity...) into the outputs "
        "(identify from LAS/LAZ to LAS/LAZ always keeps every dimension)",
    )
    p.add_argument(
        "--tile-size",
        type=float,
        default=None,
        help="process the scene in square tiles of this side (in the units of "
        "the coordinates), streaming "
        "LAS/LAZ input, so that memory is bounded by the tile, not the scene; "
        "same ground and segments as without, except with the structures step "
        "(facades, wires, trunk splitting), whose segments agree up to a "
        "bound (see the user guide); not with --method range-image",
    )
    p.add_argument(
        "--tile-buffer",
        type=float,
        default=None,
        help="overlap around each tile (units of the coordinates); default: "
        "the smallest that keeps "
        "the result exact (see segment_scene)",
    )
    add_n_jobs(p)
    add_output_options(p)
    add_scheduler(p)


def unit_length(text):
    """The value of ``--unit``: "auto" or a length in metres, over 0."""
    import argparse

    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(
            f"expected auto or a length in metres over 0 (0.3048 for feet), "
            f"got {text!r}"
        )
    return value


def ground_codes(text):
    """The value of ``--ground-codes``: integers 0 to 255, comma-separated."""
    import argparse

    try:
        codes = tuple(int(t) for t in text.split(","))
    except ValueError:
        codes = ()
    if not codes or not all(0 <= c <= 255 for c in codes):
        raise argparse.ArgumentTypeError(
            f"expected classification codes 0 to 255, comma-separated (2,8), "
            f"got {text!r}"
        )
    return codes
