"""Ground removal on street and aerial scans: CSF against SMRF, per class.

The default ground filter of :func:`~skpcd.segmentation.segment_scene` is
chosen here. Every method runs on

- simulated street scans with per-point classes
  (:func:`~skpcd.datasets.make_street_scene`, 100 m streets, seeds
  ``STREET_SEEDS``; two of them have overhead wires): ``"mobile"`` at a
  sixteenth of the pattern's density (50 rotations per second, 0.4 degree
  steps: about 450 k points per street instead of 7 M) and ``"ugv"`` (one
  sweep of a 32-beam sensor, 70 k points);
- scenes of real DALES objects on a synthetic rolling terrain
  (:func:`~skpcd.segmentation.make_scene`, 6 objects per class, 3 m apart,
  two seeds): aerial-like (half the DALES density, ground 10 pts/m2) and
  mobile-like (three times denser, ground 80 pts/m2).

For each kind of scene: ground recall (ground points flagged ground) and,
per class, the object loss (points of the class flagged ground: they are
lost to the segmentation). Methods: ``GROUND_PRESETS["csf"]`` (CSF, 1 m
cloth, rigidness 3, slope smoothing, 0.3 m threshold: the default), CSF
with its authors' 0.5 m threshold, and SMRF with the ``"aerial"`` and
``"mobile"`` presets.

Then time and peak memory at 1 and 5 million points (10 M with ``--sizes
1 5 10``): a mobile street scan at the pattern's full density (150 m, seed
10, about 11 M points), its first n points in scan order (a shorter
street), each method in a fresh process; the peak is VmHWM above the
process after loading the points and compiling the kernels on a small scene
(reset through /proc/self/clear_refs), reported in bytes per point.

    python benchmarks/bench_ground.py                  # about 10 minutes
    python benchmarks/bench_ground.py --sizes 1 5 10
    python benchmarks/bench_ground.py --no-memory --out /tmp/g.json

The results go to ``benchmarks/results/ground.{json,txt}``. The machine is a
shared 2-core VM: times are noisy (other jobs ran at the same time).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from measure import maxrss_mb, provenance, reset_peak  # noqa: E402

DALES = Path(
    os.environ.get(
        "SKPCD_DALES_DIR", HERE.parents[1] / "shared" / "data" / "dales_objects"
    )
)
STREET_SEEDS = (0, 1, 10, 58)
DALES_SEEDS = (0, 1)
MOBILE_PARAMS = {"rotation_rate": 50.0, "angular_step": 0.4}
DALES_SAMPLINGS = {
    "dales aerial": {"resample": 0.5, "ground_density": 10.0},
    "dales mobile": {"resample": 3.0, "ground_density": 80.0},
}
BIG = {"length": 150.0, "random_state": 10}


def methods():
    from skpcd.segmentation import GROUND_PRESETS

    return {
        "csf (default)": dict(GROUND_PRESETS["csf"]),
        "csf thr 0.5": {**GROUND_PRESETS["csf"], "threshold": 0.5},
        "smrf aerial": dict(GROUND_PRESETS["aerial"]),
        "smrf mobile": dict(GROUND_PRESETS["mobile"]),
    }


def street_scans():
    """The simulated streets: ``(kind, seed, bunch of make_street_scene)``."""
    from skpcd.datasets import make_street_scene

    for scanner in ("mobile", "ugv"):
        for seed in STREET_SEEDS:
            s = make_street_scene(
                100.0,
                scanner=scanner,
                scanner_params=MOBILE_PARAMS if scanner == "mobile" else None,
                random_state=seed,
            )
            yield f"street {scanner}", seed, s


def street_scenes():
    for kind, seed, s in street_scans():
        yield kind, seed, s.points, s.labels.astype(str)


def dales_scenes_with_truth():
    """The DALES scenes: ``(kind, seed, points, classes, object ids)``."""
    from skpcd.io import read_segments
    from skpcd.segmentation import make_scene

    clouds, labels, _ = read_segments(DALES, DALES / "labels.csv")
    for seed in DALES_SEEDS:
        rng = np.random.default_rng(seed)
        pick = np.concatenate(
            [
                rng.choice(np.flatnonzero(labels == c), 6, replace=False)
                for c in np.unique(labels)
            ]
        )
        for kind, kw in DALES_SAMPLINGS.items():
            points, truth = make_scene(
                [clouds[i] for i in pick], gap=3.0, random_state=seed, **kw
            )
            cls = np.where(
                truth >= 0,
                labels[pick][np.maximum(truth, 0)],
                np.where(truth == -1, "ground", "noise"),
            )
            yield kind, seed, points, cls, truth


def dales_scenes():
    for kind, seed, points, cls, _ in dales_scenes_with_truth():
        yield kind, seed, points, cls


def quality():
    from skpcd.segmentation import GroundFilter

    # per kind of scene and method: counts of points and of ground flags
    table = {}
    for gen in (street_scenes, dales_scenes):
        for kind, seed, points, cls in gen():
            print(f"{kind} seed {seed}: {len(points)} points", flush=True)
            for name, params in methods().items():
                t = time.perf_counter()
                g = GroundFilter(**params).fit_predict(points)
                dt = time.perf_counter() - t
                entry = table.setdefault(kind, {}).setdefault(
                    name, {"n": {}, "flagged": {}, "seconds": 0.0, "points": 0}
                )
                entry["seconds"] += dt
                entry["points"] += len(points)
                for c in np.unique(cls):
                    mine = cls == c
                    entry["n"][c] = entry["n"].get(c, 0) + int(mine.sum())
                    entry["flagged"][c] = entry["flagged"].get(c, 0) + int(
                        g[mine].sum()
                    )
    return table


def summarise(table):
    out = {}
    for kind, per in table.items():
        out[kind] = {}
        for name, e in per.items():
            n, f = e["n"], e["flagged"]
            objects = [c for c in n if c not in ("ground", "noise")]
            out[kind][name] = {
                "ground_recall": f["ground"] / n["ground"],
                "object_loss": sum(f[c] for c in objects)
                / max(sum(n[c] for c in objects), 1),
                "loss_by_class": {c: f[c] / n[c] for c in sorted(objects)},
                "points_by_class": {c: n[c] for c in sorted(objects)},
                "seconds": e["seconds"],
                "points": e["points"],
            }
    return out


# --- time and memory ----------------------------------------------------------


def worker(name, n, path):
    """One method on the first n points of the big scan, in this process."""
    from skpcd.segmentation import GroundFilter

    params = methods()[name]
    points = np.ascontiguousarray(np.load(path, mmap_mode="r")[:n])
    # compile the kernels (and load CSF) on a small scene first
    GroundFilter(**params).fit_predict(points[:20000])
    base = reset_peak()
    t = time.perf_counter()
    g = GroundFilter(**params).fit_predict(points)
    dt = time.perf_counter() - t
    peak = maxrss_mb()
    print(
        json.dumps(
            {
                "seconds": dt,
                "peak_mb": peak - base,
                "bytes_per_point": (peak - base) * 2**20 / n,
                "ground_share": float(g.mean()),
            }
        )
    )


def memory(sizes, folder):
    path = Path(folder) / "street.npy"
    if not path.exists():
        from skpcd.datasets import make_street_scene

        print("simulating the big street scan...", flush=True)
        s = make_street_scene(BIG["length"], scanner="mobile", **big_kw())
        np.save(path, s.points)
        del s
    total = len(np.load(path, mmap_mode="r"))
    out = {"scan_points": total, "runs": []}
    for size in sizes:
        n = int(size * 1_000_000)
        if n > total:
            print(f"{size} M: the scan has only {total} points", flush=True)
            continue
        for name in methods():
            if name == "csf thr 0.5":
                continue  # same cost as the default
            cmd = [sys.executable, __file__, "--worker", name, str(n), str(path)]
            t = time.perf_counter()
            try:
                res = subprocess.run(
                    cmd, capture_output=True, text=True, timeout=1800, check=True
                )
                row = json.loads(res.stdout.strip().splitlines()[-1])
            except (subprocess.SubprocessError, ValueError) as exc:
                row = {"error": str(exc)[-300:]}
            row.update({"method": name, "points": n})
            row["wall_with_start"] = time.perf_counter() - t
            print(row, flush=True)
            out["runs"].append(row)
    return out


def big_kw():
    return {"random_state": BIG["random_state"]}


def write(results, out):
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(
        json.dumps({**provenance(), **results}, indent=1)
    )
    lines = [
        "skpcd ground removal benchmark (benchmarks/bench_ground.py), "
        + results["date"],
        f"load average at the end {os.getloadavg()[0]:.1f} (2 cores): "
        "times are noisy when it exceeds 2",
        "",
        "ground recall and object loss (share of the class's points flagged "
        "ground), summed over the scenes",
    ]
    for kind, per in results.get("quality", {}).items():
        classes = sorted({c for e in per.values() for c in e["loss_by_class"]})
        lines.append("")
        lines.append(
            f"{kind}: {next(iter(per.values()))['points'] // 1000} k points in all"
        )
        head = f"{'method':<16}{'recall':>8}{'loss':>7}{'s':>6}" + "".join(
            f"{c[:9]:>10}" for c in classes
        )
        lines.append(head)
        for name, e in per.items():
            lines.append(
                f"{name:<16}{e['ground_recall']:>8.4f}{e['object_loss']:>7.3f}"
                f"{e['seconds']:>6.1f}"
                + "".join(
                    f"{e['loss_by_class'][c]:>10.3f}"
                    if c in e["loss_by_class"]
                    else f"{'':>10}"
                    for c in classes
                )
            )
    mem = results.get("memory")
    if mem:
        lines += [
            "",
            f"time and peak memory (VmHWM above the loaded, warmed-up process) "
            f"on the first n points of a simulated mobile scan "
            f"({mem['scan_points']} points)",
            f"{'method':<16}{'points':>10}{'seconds':>9}{'peak MB':>9}{'B/pt':>7}",
        ]
        for r in mem["runs"]:
            if "error" in r:
                lines.append(f"{r['method']:<16}{r['points']:>10}  failed")
                continue
            lines.append(
                f"{r['method']:<16}{r['points']:>10}{r['seconds']:>9.1f}"
                f"{r['peak_mb']:>9.0f}{r['bytes_per_point']:>7.0f}"
            )
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=float, nargs="*", default=[1, 5])
    p.add_argument("--no-memory", action="store_true")
    p.add_argument("--no-quality", action="store_true")
    p.add_argument("--folder", default=None, help="keep the big scan here")
    p.add_argument("--out", type=Path, default=HERE / "results" / "ground.json")
    p.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        name, n, path = args.worker
        worker(name, int(n), path)
        return
    results = {"date": time.strftime("%Y-%m-%dT%H:%M:%S")}
    if not args.no_quality:
        results["quality"] = summarise(quality())
    if not args.no_memory:
        with tempfile.TemporaryDirectory() as tmp:
            results["memory"] = memory(args.sizes, args.folder or tmp)
    write(results, args.out)


if __name__ == "__main__":
    main()
