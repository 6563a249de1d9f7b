"""Street scans cut into objects, scored on the truth: the defaults of
:func:`~skpcd.segmentation.segment_scene` (CSF, facades, wires, trunk
splitting) against plain clustering and the previous default.

Scenes (as in ``bench_ground.py``): simulated streets
(:func:`~skpcd.datasets.make_street_scene`, 100 m, seeds ``SEEDS``; mobile at
a sixteenth of the pattern's density, about 450 k points, and UGV, 70 k)
and scenes of real DALES objects on a synthetic terrain
(:func:`~skpcd.segmentation.make_scene`, aerial-like and mobile-like).

Methods (``min_cluster_size=50`` for all):

- ``default``: ``segment_scene(points)``: CSF, facades and wires taken out,
  DBSCAN with automatic eps, clusters split at vertical trunks;
- ``csf, no structures``: ``structures=False``;
- ``smrf aerial, no structures``: the defaults before issue 19;
- ``smrf mobile, no structures``: the street preset before issue 19.

Scores, over the object points more than 0.5 m above the true ground (the
lowest half metre is the ground filter's business, scored by the ground
recall and in ``bench_ground.py``): ground recall; ``kept``, the share of
those points in a segment; ``purity``, the share of the points of each
segment that belong to its main object (point-weighted); the adjusted Rand
index; objects recovered whole (90 % of the object in one segment, 90 % of
that segment the object) per class, for objects of at least 30 scored
points. On the street scenes the facades of neighbouring buildings touch
(a row of houses is one wall): all facade points count as one object for
purity and ARI and facades are not counted in ``whole``; the facade and
wire typing is scored instead: the share of the facade (wire) points in
segments of type "facade" ("wire"), and the share of the points of those
segments that are truly facade (wire).

Then time and peak memory per stage at 1 and 5 million points (the first n
points of the 150 m full-density mobile scan of ``bench_ground.py``), each
in a fresh process (VmHWM above the warmed-up process with its points
loaded): CSF ground; ``segment_scene`` end to end with the defaults and
without structures; and, on the non-ground points of CSF with skpcd's eps,
scikit-learn's ``DBSCAN(n_jobs=2)`` and Open3D's ``cluster_dbscan`` (8 GB
address-space cap, 20 minute timeout; a failure is reported).

    python benchmarks/bench_street_segmentation.py            # ~20 minutes
    python benchmarks/bench_street_segmentation.py --no-timing

Results: ``benchmarks/results/street_segmentation.{json,txt}``. Shared 2-core
VM: times are noisy.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from sklearn.metrics import adjusted_rand_score

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_ground import dales_scenes_with_truth, street_scans  # noqa: E402
from measure import import_open3d, maxrss_mb, provenance, reset_peak  # noqa: E402

MIN_SIZE = 50
METHODS = {
    "default": {},
    "csf, no structures": {"structures": False},
    "smrf aerial, no structures": {"ground": "aerial", "structures": False},
    "smrf mobile, no structures": {"ground": "mobile", "structures": False},
}
CAP_GB = 8


def street_scenes():
    for kind, seed, s in street_scans():
        cls = s.labels.astype(str)
        height = s.points[:, 2] - s.ground_height(s.points[:, 0], s.points[:, 1])
        inst = s.instances.copy()
        inst[cls == "facade"] = inst.max() + 1  # one wall
        yield kind, seed, s.points, cls, inst, height


def dales_scenes():
    from skpcd.datasets._object_scene import terrain_height

    for kind, seed, points, cls, truth in dales_scenes_with_truth():
        height = points[:, 2] - terrain_height(points[:, 0], points[:, 1], 1.0)
        yield kind, seed, points, cls, truth, height


def score(seg, cls, inst, height):
    """Counts of one segmentation of one scene (summed over scenes later)."""
    labels = seg.labels
    is_obj = (cls != "ground") & (cls != "noise")
    scored = is_obj & (height > 0.5)
    out = {
        "ground": int((cls == "ground").sum()),
        "ground_hit": int(seg.ground[cls == "ground"].sum()),
        "scored": int(scored.sum()),
        "kept": int((labels[scored] >= 0).sum()),
    }
    lab, ins = labels[scored], inst[scored]
    seg_in = lab >= 0
    pairs, cnt = np.unique(
        np.column_stack([lab[seg_in], ins[seg_in]]), axis=0, return_counts=True
    )
    best = np.zeros(int(labels.max()) + 2)
    np.maximum.at(best, pairs[:, 0], cnt)
    out["pure"] = int(best.sum())
    out["ari"] = float(adjusted_rand_score(ins, lab))
    # whole objects per class
    size_i = dict(zip(*np.unique(ins, return_counts=True)))
    size_s = dict(zip(*np.unique(lab[seg_in], return_counts=True)))
    order = np.lexsort((cnt, pairs[:, 1]))
    last = np.r_[pairs[order, 1][1:] != pairs[order, 1][:-1], True]
    top = {
        int(i): (int(s), int(c))
        for s, i, c in zip(
            pairs[order, 0][last], pairs[order, 1][last], cnt[order][last]
        )
    }
    whole = {}
    cls_s = cls[scored]
    for c in np.unique(cls_s):
        if c == "facade":
            continue
        ids = [i for i in np.unique(ins[cls_s == c]) if size_i[i] >= 30]
        ok = 0
        for i in ids:
            if i in top:
                s, k = top[i]
                ok += k >= 0.9 * size_i[i] and k >= 0.9 * size_s[s]
        whole[str(c)] = [int(ok), len(ids)]
    out["whole"] = whole
    # typing of facades and wires
    kinds = np.asarray(seg.kinds, dtype=object)
    point_kind = np.where(labels >= 0, kinds[np.maximum(labels, 0)], "")
    for k in ("facade", "wire"):
        truth_k = scored & (cls == k)
        typed = scored & (point_kind == k)
        out[f"{k}_points"] = int(truth_k.sum())
        out[f"{k}_typed"] = int((truth_k & typed).sum())
        out[f"{k}_segment_points"] = int(typed.sum())
    return out


def quality():
    from skpcd.segmentation import segment_scene

    table = {}
    for gen in (street_scenes, dales_scenes):
        for kind, seed, points, cls, inst, height in gen():
            print(f"{kind} seed {seed}: {len(points)} points", flush=True)
            for name, kw in METHODS.items():
                t = time.perf_counter()
                seg = segment_scene(points, min_cluster_size=MIN_SIZE, **kw)
                dt = time.perf_counter() - t
                row = score(seg, cls, inst, height)
                row.update(
                    seconds=dt, n_segments=seg.n_segments, seed=seed, eps=seg.eps
                )
                row["kinds"] = {
                    k: int((np.asarray(seg.kinds) == k).sum())
                    for k in ("object", "facade", "wire")
                }
                print(f"  {name}: {row}", flush=True)
                table.setdefault(kind, {}).setdefault(name, []).append(row)
    return table


def summarise(table):
    out = {}
    for kind, per in table.items():
        out[kind] = {}
        for name, rows in per.items():

            def tot(key, rows=rows):
                return sum(r[key] for r in rows)

            whole = {}
            for r in rows:
                for c, (ok, n) in r["whole"].items():
                    a, b = whole.get(c, (0, 0))
                    whole[c] = (a + ok, b + n)
            s = {
                "ground_recall": tot("ground_hit") / max(tot("ground"), 1),
                "kept": tot("kept") / max(tot("scored"), 1),
                "purity": tot("pure") / max(tot("kept"), 1),
                "ari": float(np.mean([r["ari"] for r in rows])),
                "whole": sum(a for a, _ in whole.values())
                / max(sum(b for _, b in whole.values()), 1),
                "whole_by_class": {c: list(v) for c, v in sorted(whole.items())},
                "seconds": tot("seconds"),
                "segments": tot("n_segments"),
            }
            for k in ("facade", "wire"):
                if tot(f"{k}_points"):
                    s[f"{k}_recall"] = tot(f"{k}_typed") / tot(f"{k}_points")
                    s[f"{k}_precision"] = tot(f"{k}_typed") / max(
                        tot(f"{k}_segment_points"), 1
                    )
            out[kind][name] = s
    return out


# --- time and memory per stage ------------------------------------------------

STAGES = (
    "ground csf",
    "segment_scene default",
    "segment_scene no structures",
    "sklearn DBSCAN",
    "open3d cluster_dbscan",
)


def worker(stage, n, path):
    from skpcd.segmentation import GroundFilter, estimate_eps, segment_scene

    points = np.ascontiguousarray(np.load(path, mmap_mode="r")[:n])
    extra = {}
    if stage in ("sklearn DBSCAN", "open3d cluster_dbscan"):
        ground = GroundFilter(method="csf", threshold=0.3).fit_predict(points)
        rest = np.ascontiguousarray(points[~ground])
        eps = estimate_eps(rest, random_state=0)
        del points, ground
        extra = {"eps": eps, "non_ground": len(rest)}
        if stage == "sklearn DBSCAN":
            from sklearn.cluster import DBSCAN

            def run():
                return DBSCAN(eps=eps, min_samples=5, n_jobs=2).fit(rest).labels_

        else:
            o3d = import_open3d()
            pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))

            def run():
                return np.asarray(pc.cluster_dbscan(eps, 5, print_progress=False))

    elif stage == "ground csf":
        segment_scene(points[:20000])  # compile

        def run():
            return GroundFilter(method="csf", threshold=0.3).fit_predict(points)

    else:
        kw = {} if stage == "segment_scene default" else {"structures": False}
        segment_scene(points[:20000], **kw)  # compile

        def run():
            return segment_scene(points, **kw).labels

    base = reset_peak()
    t = time.perf_counter()
    labels = run()
    dt = time.perf_counter() - t
    peak = maxrss_mb() - base
    print(
        json.dumps(
            {
                "seconds": dt,
                "peak_mb": peak,
                "bytes_per_point": peak * 2**20 / n,
                "clusters": int(np.max(labels)) + 1 if len(labels) else 0,
                **extra,
            }
        )
    )


def _cap():
    lim = CAP_GB * 2**30
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))


def timing(sizes, path, stages=STAGES):
    out = []
    for size in sizes:
        n = int(size * 1_000_000)
        for stage in stages:
            cmd = [sys.executable, __file__, "--worker", stage, str(n), str(path)]
            try:
                res = subprocess.run(
                    cmd,
                    capture_output=True,
                    text=True,
                    timeout=1200,
                    check=True,
                    preexec_fn=_cap,
                )
                row = json.loads(res.stdout.strip().splitlines()[-1])
            except subprocess.TimeoutExpired:
                row = {"error": "timeout (20 min)"}
            except (subprocess.SubprocessError, ValueError) as exc:
                err = getattr(exc, "stderr", "") or str(exc)
                row = {"error": err.strip().splitlines()[-1][-200:] if err else "?"}
            row.update(stage=stage, points=n)
            print(row, flush=True)
            out.append(row)
    return out


def write(results, out):
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(
        json.dumps({**provenance(), **results}, indent=1)
    )
    lines = [
        "skpcd street segmentation benchmark "
        "(benchmarks/bench_street_segmentation.py), " + results["date"],
        f"load average at the end {os.getloadavg()[0]:.1f} (2 cores): "
        "times are noisy when it exceeds 2",
        "scores over the object points > 0.5 m above the true ground; whole: "
        "objects in one segment (90 %/90 %); facade/wire: recall / precision "
        "of the segment types",
    ]
    for kind, per in results.get("quality", {}).items():
        lines += ["", kind]
        lines.append(
            f"{'method':<28}{'ground':>7}{'kept':>6}{'purity':>7}{'ARI':>6}"
            f"{'whole':>6}{'facade r/p':>12}{'wire r/p':>11}{'s':>6}"
        )
        for name, s in per.items():
            fac = (
                f"{s['facade_recall']:.2f}/{s['facade_precision']:.2f}"
                if "facade_recall" in s
                else "-"
            )
            wir = (
                f"{s['wire_recall']:.2f}/{s['wire_precision']:.2f}"
                if "wire_recall" in s
                else "-"
            )
            lines.append(
                f"{name:<28}{s['ground_recall']:>7.4f}{s['kept']:>6.3f}"
                f"{s['purity']:>7.3f}{s['ari']:>6.3f}{s['whole']:>6.2f}"
                f"{fac:>12}{wir:>11}{s['seconds']:>6.0f}"
            )
        lines.append("  whole by class (recovered/objects):")
        for name, s in per.items():
            lines.append(
                f"  {name:<26}"
                + ", ".join(f"{c} {a}/{b}" for c, (a, b) in s["whole_by_class"].items())
            )
    if results.get("timing"):
        lines += [
            "",
            "time and peak memory per stage (VmHWM above the warmed-up process "
            "with its points loaded), first n points of a simulated mobile scan",
            f"{'stage':<30}{'points':>10}{'seconds':>9}{'peak MB':>9}{'B/pt':>7}",
        ]
        for r in results["timing"]:
            if "error" in r:
                lines.append(f"{r['stage']:<30}{r['points']:>10}  {r['error']}")
                continue
            lines.append(
                f"{r['stage']:<30}{r['points']:>10}{r['seconds']:>9.1f}"
                f"{r['peak_mb']:>9.0f}{r['bytes_per_point']:>7.0f}"
            )
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=float, nargs="*", default=[1, 5])
    p.add_argument("--no-timing", action="store_true")
    p.add_argument("--no-quality", action="store_true")
    p.add_argument("--folder", default=None, help="the big scan (bench_ground.py)")
    p.add_argument(
        "--out", type=Path, default=HERE / "results" / "street_segmentation.json"
    )
    p.add_argument("--stages", nargs="*", default=list(STAGES), choices=STAGES)
    p.add_argument(
        "--merge",
        type=Path,
        default=None,
        help="keep the results of this earlier JSON for what is not rerun "
        "(quality, and the timing rows of the stages not in --stages)",
    )
    p.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        stage, n, path = args.worker
        worker(stage, int(n), path)
        return
    results = {"date": time.strftime("%Y-%m-%dT%H:%M:%S")}
    if not args.no_quality:
        results["quality"] = summarise(quality())
    if not args.no_timing:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(args.folder or tmp)
            path = folder / "street.npy"
            if not path.exists():
                from bench_ground import BIG

                from skpcd.datasets import make_street_scene

                s = make_street_scene(
                    BIG["length"], scanner="mobile", random_state=BIG["random_state"]
                )
                np.save(path, s.points)
                del s
            results["timing"] = timing(args.sizes, path, args.stages)
    if args.merge:
        old = json.loads(args.merge.read_text())
        if "quality" not in results and "quality" in old:
            results["quality"] = old["quality"]
            results["quality_date"] = old["date"]
        kept = [r for r in old.get("timing", []) if r["stage"] not in args.stages]
        results["timing"] = sorted(
            kept + results.get("timing", []),
            key=lambda r: (r["points"], STAGES.index(r["stage"])),
        )
    write(results, args.out)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
