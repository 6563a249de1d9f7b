"""``skpcd info FILE``: points, fields, bounds and spacing of a file."""

import numpy as np


def add_parser(sub):
    p = sub.add_parser("info", help="points, fields, bounds and spacing of a file")
    p.add_argument(
        "file", help="a point-cloud file (.xyz .txt .pts .csv .npy .ply .pcd .las .laz)"
    )
    p.set_defaults(func=run)
    return p


def run(args):
    from skpcd.io import read_point_cloud
    from skpcd.preprocessing import point_spacing

    points, extras = read_point_cloud(args.file, fields="all", nonfinite="keep")
    finite = np.isfinite(points).all(axis=1)
    valid = points[finite]
    bad = len(points) - len(valid)
    out = [
        f"file      {args.file}",
        f"points    {len(points)}"
        + (f" ({bad} with NaN/inf coordinates)" if bad else ""),
        "fields    x y z" + "".join(f" {n}" for n in extras),
    ]
    if len(valid):
        lo, hi = valid.min(axis=0), valid.max(axis=0)
        for axis, a, b in zip("xyz", lo, hi):
            out.append(f"{axis}         [{a:.4f}, {b:.4f}]  extent {b - a:.4f}")
        out.append(
            f"spacing   {point_spacing(valid, workers=-1):.4f} (median nearest distinct"
            " neighbour)"
        )
    print("\n".join(out))
    return 0
