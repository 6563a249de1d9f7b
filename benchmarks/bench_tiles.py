"""Tiled segmentation against in-memory segmentation on real scans.

For each of the real car-mounted sweeps (KITTI, PandaSet;
``$SKPCD_REAL_MOBILE_DIR/scans``, default ``../shared/data/real_mobile``),
``segment_scene`` in memory and with ``tile_size`` (30 m by default, small
against a sweep's 100-200 m so that most segments meet a tile border), the
same options otherwise (``eps`` given, so that the comparison is of the
tiling alone):

- ``ground="csf"`` and ``"street"`` without the structures step: points
  whose ground flag differs, and whether the labels are identical (the
  tiled path is meant to give the in-memory answer bit for bit);
- ``ground="street"`` with the structures step (the default): the adjusted
  Rand index of the labels over the points in a segment in either run, and
  the share of those points outside the best one-to-one match of segments.

    python benchmarks/bench_tiles.py --out benchmarks/results/tiles.json

Results: ``benchmarks/results/tiles.{json,txt}``, with the commit, machine
and date of the run.
"""

import argparse
import json
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from measure import provenance
from sklearn.metrics import adjusted_rand_score

from skpcd.io import read_point_cloud
from skpcd.segmentation import segment_scene

DATA = Path(
    os.environ.get(
        "SKPCD_REAL_MOBILE_DIR",
        Path(__file__).resolve().parents[2] / "shared" / "data" / "real_mobile",
    )
)


def mismatch(a, b):
    """Share of the points in a segment (in either labelling) outside the
    best one-to-one match of segments (greedy by overlap)."""
    seg = (a >= 0) | (b >= 0)
    pairs, count = np.unique(
        np.column_stack([a[seg], b[seg]]), axis=0, return_counts=True
    )
    used_a, used_b, agree = set(), set(), 0
    for i in np.argsort(-count, kind="stable"):
        x, y = pairs[i]
        if x >= 0 and y >= 0 and x not in used_a and y not in used_b:
            used_a.add(x)
            used_b.add(y)
            agree += int(count[i])
    return 1.0 - agree / max(int(seg.sum()), 1)


def compare(path, tile, eps, tmp):
    xyz = read_point_cloud(path)
    row = {"scan": path.name, "points": len(xyz)}
    for ground in ("csf", "street"):
        t0 = time.perf_counter()
        a = segment_scene(xyz, ground=ground, structures=False, eps=eps)
        t1 = time.perf_counter()
        b = segment_scene(
            path, ground=ground, structures=False, eps=eps, tile_size=tile,
            temp_folder=tmp,
        )  # fmt: skip
        t2 = time.perf_counter()
        row[ground] = {
            "ground_points": int(a.ground.sum()),
            "ground_differ": int((a.ground != b.ground).sum()),
            "labels_identical": bool(np.array_equal(a.labels, b.labels)),
            "segments": [a.n_segments, b.n_segments],
            "seconds": [round(t1 - t0, 2), round(t2 - t1, 2)],
        }
    a = segment_scene(xyz, ground="street", eps=eps)
    b = segment_scene(path, ground="street", eps=eps, tile_size=tile, temp_folder=tmp)
    seg = (a.labels >= 0) | (b.labels >= 0)
    row["structures"] = {
        "ground_differ": int((a.ground != b.ground).sum()),
        "ari": float(adjusted_rand_score(a.labels[seg], b.labels[seg])),
        "mismatch": mismatch(a.labels, b.labels),
        "segments": [a.n_segments, b.n_segments],
        "kinds": [
            {
                k: int((np.asarray(s.kinds) == k).sum())
                for k in ("object", "facade", "wire")
            }
            for s in (a, b)
        ],
    }
    return row


def write(results, out):
    out.write_text(json.dumps(results, indent=1) + "\n")
    lines = [
        "skpcd tiled against in-memory segmentation (benchmarks/bench_tiles.py)",
        f"  {results['date']}, commit {results['commit']}, {results['machine']}",
        f"  tiles of {results['tile_size']:g} m, eps {results['eps']:g}; data: "
        "the 12 real sweeps of ../shared/data/real_mobile (KITTI, PandaSet)",
        "",
        f"{'scan':24} {'points':>7}  {'csf: gnd differ':>15} {'labels':>6}  "
        f"{'street: gnd differ':>18} {'labels':>6}  {'structures: ARI':>15} "
        f"{'mismatch %':>10} {'segments':>9}",
    ]
    for r in results["scans"]:
        c, s, st = r["csf"], r["street"], r["structures"]
        lines.append(
            f"{r['scan']:24} {r['points']:>7}  {c['ground_differ']:>15} "
            f"{'same' if c['labels_identical'] else 'DIFF':>6}  "
            f"{s['ground_differ']:>18} "
            f"{'same' if s['labels_identical'] else 'DIFF':>6}  "
            f"{st['ari']:>15.5f} {100 * st['mismatch']:>10.3f} "
            f"{st['segments'][0]:>4}/{st['segments'][1]:<4}"
        )
    aris = [r["structures"]["ari"] for r in results["scans"]]
    mis = [r["structures"]["mismatch"] for r in results["scans"]]
    lines += [
        "",
        f"structures: ARI min {min(aris):.5f}, median {np.median(aris):.5f}; "
        f"mismatch max {100 * max(mis):.3f} %, median {100 * np.median(mis):.3f} %",
    ]
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tile-size", type=float, default=30.0)
    parser.add_argument("--eps", type=float, default=0.5)
    parser.add_argument("--out", type=Path, default=Path("/tmp/tiles.json"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    paths = sorted((DATA / "scans").glob("*.las"))
    if not paths:
        sys.exit(f"no real sweeps in {DATA / 'scans'} (set SKPCD_REAL_MOBILE_DIR)")
    results = {
        **provenance(),
        "tile_size": args.tile_size,
        "eps": args.eps,
        "scans": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            results["scans"].append(compare(path, args.tile_size, args.eps, tmp))
            print(
                results["scans"][-1]["scan"],
                results["scans"][-1]["structures"],
                flush=True,
            )
    write(results, args.out)


if __name__ == "__main__":
    main()
