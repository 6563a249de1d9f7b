"""The defaults of ``segment_scene`` on real scans of every kind, and on
simulated scans of every pattern: the scan kind found, ground recall and
precision, objects kept, whole and pure, for the new defaults
(``ground="auto"``) against the previous ones (``ground="csf"``), the SMRF
street preset, CSF + scikit-learn's DBSCAN and Open3D.

Data (nothing here is shipped):

- ``real_mobile``: the 12 real car-mounted sweeps of
  ``../shared/data/real_mobile`` (KITTI HDL-64E, PandaSet Pandar64). Only
  cars, people, signs and other objects are boxed: the ground is unknown,
  so the ground score is the share of boxed object points taken as ground
  (lower is better), by class; an object (20 or more points) is kept when
  half its points are in segments, whole when one segment holds 80 % of
  them, and the purity is the share of that segment's points inside the
  object's box (mean over kept objects).
- ``aerial``: the 15 samples of the ISPRS filter test (reference ground per
  point; ``isprs_filter/``) and PDAL's ``autzen_trim.las`` (no object
  truth: the largest segment and eps are shown), in the folder
  ``SKPCD_EXTRA_REAL`` (default ``../extra_real``, beside the checkout; its
  README names the source of every file).
- ``kinds`` (``--kinds-only`` measures this alone and adds it to the results
  already written): the kind found on each real scan of every kind, against
  the kind it is: the 71 labelled sweeps of ``../shared/data/real_labelled``
  and the 12 of ``real_mobile`` (spinning), the ISPRS samples and Autzen
  (airborne), in ``SKPCD_EXTRA_REAL``: ``sweeps/`` (single sweeps of other
  spinning sensors, 16 to 128 beams), ``profiler/`` (RIEGL profiler on the
  Stereopolis II van in Paris, whole and cut into stretches of 0.1, 0.2 and
  0.35 s by GPS time; a chunk of Paris-rue-Madame; a Lille street of the
  NPM3D course) and ``terrestrial/`` (a RIEGL VZ-400i station, an E57 scan of
  a pump, a TLS pine plot: skpcd has no terrestrial kind); "before" is the
  rule without the azimuth coverage.
- ``kept aside``: real labelled sweeps never used to choose anything,
  scored once (``mobile_labelled/``: SemanticKITTI sequence 07, PandaSet
  semantic segmentation, nuScenes lidarseg): ground recall and precision
  against their ground classes, the share of car, vegetation, fence, pole,
  trunk and person points taken as ground.
- ``dales``: scenes of real DALES objects on a synthetic terrain, as in
  ``bench_ground.py`` (aerial-like and mobile-like samplings); exact
  ground and objects.
- ``simulated``: one street per pattern (:func:`make_street_scene`, 50 m,
  seed 1): profiler ("mobile", at a quarter density), spinning (HDL-64E),
  robot ("ugv" at 0.6 m), aerial; exact ground and objects.

Methods (``min_cluster_size=50``):

- ``auto``: ``segment_scene(points)``, the new default;
- ``previous``: ``ground="csf"``, the default before;
- ``smrf mobile``: ``ground="mobile"``;
- ``CSF + sklearn DBSCAN``: CSF's ground (the "csf" preset) and
  ``sklearn.cluster.DBSCAN(eps, min_samples=5)`` on the rest, eps the
  automatic one of skpcd on those points;
- ``Open3D``: the largest plane (``segment_plane``, 0.2 m, 1000 iterations)
  as ground and ``cluster_dbscan(eps, min_points=5)`` on the rest, the same
  eps.

    python benchmarks/bench_scan_kinds.py          # about 15 minutes

Results: ``benchmarks/results/scan_kinds.{json,txt}``.
"""

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_ground import dales_scenes_with_truth  # noqa: E402
from measure import commit, machine  # noqa: E402

SHARED = HERE.parent.parent / "shared" / "data"
REAL_MOBILE = Path(os.environ.get("SKPCD_REAL_MOBILE", SHARED / "real_mobile"))
EXTRA = Path(os.environ.get("SKPCD_EXTRA_REAL", HERE.parent.parent / "extra_real"))
REAL_LABELLED = Path(
    os.environ.get("SKPCD_REAL_LABELLED_DIR", SHARED / "real_labelled")
)
MIN_SIZE = 50
BOXED = {10: "car", 30: "person", 81: "sign", 99: "other"}
METHODS = ("auto", "previous", "smrf mobile", "CSF + sklearn DBSCAN", "Open3D")


def segment(method, xyz):
    """``(labels, ground, eps, kind)`` of one method on one scene."""
    from skpcd.segmentation import (
        GROUND_PRESETS,
        GroundFilter,
        estimate_eps,
        segment_scene,
    )

    if method in ("auto", "previous", "smrf mobile"):
        ground = {"auto": "auto", "previous": "csf", "smrf mobile": "mobile"}[method]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = segment_scene(xyz, ground=ground, n_jobs=2)
        kind = r.scan.kind if r.scan is not None else "-"
        return r.labels, r.ground, r.eps, kind
    if method == "CSF + sklearn DBSCAN":
        from sklearn.cluster import DBSCAN

        g = GroundFilter(**GROUND_PRESETS["csf"]).fit_predict(xyz)
    else:
        import open3d as o3d

        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz - xyz.min(0)))
        o3d.utility.random.seed(0)
        _, inliers = pcd.segment_plane(0.2, 3, 1000)
        g = np.zeros(len(xyz), dtype=bool)
        g[np.asarray(inliers)] = True
    rest = np.flatnonzero(~g)
    labels = np.full(len(xyz), -1, dtype=np.int64)
    if len(rest) < 2:
        return labels, g, 0.0, "-"
    eps = estimate_eps(xyz[rest], random_state=0, n_jobs=2)
    if method == "CSF + sklearn DBSCAN":
        sub = DBSCAN(eps=eps, min_samples=5, n_jobs=2).fit(xyz[rest]).labels_
    else:
        pts = o3d.geometry.PointCloud(
            o3d.utility.Vector3dVector(xyz[rest] - xyz.min(0))
        )
        sub = np.asarray(pts.cluster_dbscan(eps, 5, print_progress=False))
    sizes = np.bincount(sub[sub >= 0]) if (sub >= 0).any() else np.zeros(0, int)
    keep = np.flatnonzero(sizes >= MIN_SIZE)
    new = np.full(len(sizes) + 1, -1)
    new[keep] = np.arange(len(keep))
    labels[rest] = new[sub]
    return labels, g, float(eps), "-"


def objects_score(labels, objects):
    """kept, whole, purity over the objects (a list of index arrays)."""
    kept = whole = 0
    purity = []
    for idx in objects:
        lab = labels[idx]
        if (lab >= 0).mean() >= 0.5:
            kept += 1
        if (lab >= 0).any():
            best = np.bincount(lab[lab >= 0]).argmax()
            if (lab == best).sum() >= 0.8 * len(idx):
                whole += 1
            seg = np.flatnonzero(labels == best)
            purity.append(np.isin(seg, idx, assume_unique=True).mean())
    n = max(len(objects), 1)
    return {
        "objects": len(objects),
        "kept": kept / n,
        "whole": whole / n,
        "purity": float(np.mean(purity)) if purity else float("nan"),
    }


def ground_score(ground, truth):
    hit = (ground & truth).sum()
    return {
        "ground_recall": float(hit / max(truth.sum(), 1)),
        "ground_precision": float(hit / max(ground.sum(), 1)),
        "ground_error": float((ground != truth).mean()),
    }


def real_mobile():
    import laspy

    for path in sorted((REAL_MOBILE / "scans").glob("*.las")):
        f = laspy.read(path)
        xyz = np.column_stack([f.x, f.y, f.z])
        sem, inst = np.asarray(f.semantic), np.asarray(f.instance)
        objects, classes = [], []
        for i in np.unique(inst[inst > 0]):
            idx = np.flatnonzero(inst == i)
            if len(idx) >= 20:
                objects.append(idx)
                classes.append(BOXED.get(int(np.bincount(sem[idx]).argmax()), "other"))
        yield path.stem, xyz, objects, classes


def score_real_mobile(method, xyz, objects, classes):
    labels, ground, eps, kind = segment(method, xyz)
    out = objects_score(labels, objects)
    for c in sorted(set(classes)):
        pts = np.concatenate([o for o, k in zip(objects, classes) if k == c])
        out[f"{c}_as_ground"] = float(ground[pts].mean())
    out.update(eps=eps, kind=kind, segments=int(labels.max()) + 1)
    return out


def isprs():
    for path in sorted((EXTRA / "isprs_filter").glob("samp*.npz")):
        z = np.load(path)
        yield path.stem, z["xyz"], z["ground"].astype(bool)


def kept_aside():
    """Labelled sweeps: name, xyz, ground truth, {class: mask}, objects."""
    sets = {
        "semantickitti07": (
            {40, 44, 48, 49, 72},
            {
                "car": {10},
                "vegetation": {70},
                "trunk": {71},
                "fence": {51},
                "pole": {80, 81},
                "person": {30},
            },
        ),
        "pandaset": (
            {6, 7, 8, 9, 10, 11, 12},
            {"car": {13, 14}, "vegetation": {5}, "pole": {36}, "person": {30, 31}},
        ),
        "nuscenes": (
            {24, 25, 26, 27},
            {"car": {17}, "vegetation": {30}, "person": {2, 3, 4, 5, 6, 7, 8}},
        ),
    }
    for path in sorted((EXTRA / "mobile_labelled").glob("*.npz")):
        z = np.load(path)
        source = next(k for k in sets if path.stem.startswith(k))
        ground_codes, class_codes = sets[source]
        label = z["label"].astype(np.int64)
        xyz = z["xyz"]
        if source == "nuscenes":  # the car itself and the unlabelled
            keep = (label != 31) & (label != 0)
            xyz, label = xyz[keep], label[keep]
        truth = np.isin(label, list(ground_codes))
        masks = {c: np.isin(label, list(v)) for c, v in class_codes.items()}
        objects = []
        if "instance" in z.files and source == "semantickitti07":
            inst = z["instance"].astype(np.int64)
            for i in np.unique(inst[(inst > 0) & ~truth]):
                idx = np.flatnonzero((inst == i) & ~truth)
                if len(idx) >= 20:
                    objects.append(idx)
        yield path.stem, xyz, truth, masks, objects


def real_scans_of_each_kind():
    """(name, group, kind it is, xyz) of every real scan at hand; the
    sweeps are grouped by folder and source."""
    import laspy

    for path in sorted((REAL_LABELLED / "scans").glob("*.la[sz]")):
        f = laspy.read(path)
        xyz = np.column_stack([f.x, f.y, f.z])
        yield path.stem, f"real_labelled {path.stem.split('_')[0]}", "spinning", xyz
    for name, xyz, _, _ in real_mobile():
        yield name, f"real_mobile {name.split('_')[0]}", "spinning", xyz
    for path in sorted((EXTRA / "sweeps").glob("*.npz")):  # 16 to 128 beams
        yield path.stem, path.stem, "spinning", np.load(path)["xyz"]
    for name, xyz, _ in isprs():
        yield name, name, "airborne", xyz
    autzen = EXTRA / "aerial" / "autzen_trim.npz"
    if autzen.exists():
        xyz = np.load(autzen)["xyz"] * 0.3048
        yield "autzen_trim", "autzen_trim", "airborne", xyz
    for path in sorted((EXTRA / "profiler").glob("*.npz")):
        z = np.load(path)
        yield path.stem, path.stem, "profiler", z["xyz"]
        if "gps_time" in z.files:  # stretches of the line scanner
            t = z["gps_time"] - z["gps_time"].min()
            for a, b in ((0.0, 0.1), (0.0, 0.2), (0.3, 0.65)):
                keep = (t >= a) & (t < b)
                name = f"{path.stem} {a:g}-{b:g} s"
                yield name, name, "profiler", z["xyz"][keep]
    for path in sorted((EXTRA / "terrestrial").iterdir()):
        if path.suffix == ".npz":
            xyz = np.load(path)["xyz"]
        elif path.suffix in (".las", ".laz"):
            f = laspy.read(path)
            xyz = np.column_stack([f.x, f.y, f.z])
        else:
            continue
        yield path.stem, path.stem, "terrestrial", xyz


def scan_kinds():
    """The kind found on each real scan, now and with the rule before the
    azimuth coverage (a concentrated scan was a spinning one)."""
    from skpcd.segmentation import describe_scan

    rows = []
    for name, group, truth, xyz in real_scans_of_each_kind():
        scan = describe_scan(xyz)
        before = "spinning" if scan.azimuth_coverage is not None else scan.kind
        rows.append({
            "scan": name, "group": group, "is": truth, "points": len(xyz),
            "found": scan.kind, "before": before, "reason": scan.reason,
            "vertical": scan.vertical, "concentration": scan.concentration,
            "azimuth_coverage": scan.azimuth_coverage,
        })  # fmt: skip
        print(name, truth, scan.kind, flush=True)
    return {"rows": rows, "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
            "commit": commit(), "machine": machine()}  # fmt: skip


def kinds_lines(kinds):
    """The table of the kinds found: one row a scan, the 83 real sweeps as
    one row a source."""
    lines = [
        "",
        "kind found on each real scan (scan_kinds(); "
        f"{kinds['date']}, commit {kinds['commit']}): now and before the azimuth "
        "coverage; sweeps grouped by source (ranges over them)",
        f"{'scan':<44}{'is':>12}{'points':>16}{'found':>10}{'before':>10}"
        f"{'vertical':>11}{'concentr.':>11}{'azimuth':>11}",
    ]
    groups = {}
    for r in kinds["rows"]:
        groups.setdefault(r["group"], []).append(r)

    def span(rs, k, fmt):
        v = [r[k] for r in rs if r[k] is not None]
        if not v:
            return "-"
        lo, hi = min(v), max(v)
        return f"{lo:{fmt}}" if lo == hi else f"{lo:{fmt}}-{hi:{fmt}}"

    for key, rs in groups.items():
        found = ",".join(sorted({r["found"] for r in rs}))
        before = ",".join(sorted({r["before"] for r in rs}))
        name = f"{key} ({len(rs)})" if len(rs) > 1 else key
        lines.append(
            f"{name[:43]:<44}{rs[0]['is']:>12}{span(rs, 'points', 'd'):>16}"
            f"{found:>10}{before:>10}{span(rs, 'vertical', '.2f'):>11}"
            f"{span(rs, 'concentration', '.2f'):>11}"
            f"{span(rs, 'azimuth_coverage', '.2f'):>11}"
        )
    return lines


def simulated():
    from skpcd.datasets import make_street_scene

    patterns = {
        "profiler": ("mobile", {"angular_step": 0.2, "rotation_rate": 100.0}),
        "spinning": ("spinning", {"sensor": "hdl64"}),
        "robot": ("ugv", {"height": 0.6}),
        "aerial": ("aerial", None),
    }
    for name, (scanner, params) in patterns.items():
        s = make_street_scene(
            50.0, scanner=scanner, scanner_params=params, random_state=1, n_jobs=2
        )
        cls = s.labels.astype(str)
        truth = cls == "ground"
        objects = []
        for i in np.unique(s.instances[~np.isin(cls, ["ground", "facade", "wire"])]):
            idx = np.flatnonzero(s.instances == i)
            if len(idx) >= 20:
                objects.append(idx)
        yield name, s.points, truth, objects


def run(methods):
    results = {
        "real_mobile": {}, "aerial": {}, "kept_aside": {}, "dales": {}, "simulated": {},
    }  # fmt: skip
    for name, xyz, objects, classes in real_mobile():
        for m in methods:
            t = time.perf_counter()
            r = score_real_mobile(m, xyz, objects, classes)
            r["seconds"] = time.perf_counter() - t
            results["real_mobile"].setdefault(m, {})[name] = r
        print(
            name,
            {m: round(results["real_mobile"][m][name]["whole"], 2) for m in methods},
        )
    for name, xyz, truth in isprs():
        for m in methods:
            if m == "Open3D" or m == "CSF + sklearn DBSCAN":
                labels, ground, eps, kind = segment(m, xyz)
            else:
                labels, ground, eps, kind = segment(m, xyz)
            r = ground_score(ground, truth)
            r.update(kind=kind, eps=eps)
            results["aerial"].setdefault(m, {})[name] = r
        print(
            name,
            {m: round(results["aerial"][m][name]["ground_error"], 3) for m in methods},
        )
    autzen = EXTRA / "aerial" / "autzen_trim.npz"
    if autzen.exists():
        xyz = np.load(autzen)["xyz"] * 0.3048  # international feet to metres
        for m in ("auto", "previous"):
            labels, ground, eps, kind = segment(m, xyz)
            from skpcd.segmentation._scene_clusters import largest_box

            ext, _ = largest_box(xyz, labels)
            results["aerial"].setdefault(m, {})["autzen_trim"] = {
                "kind": kind, "eps": eps, "segments": int(labels.max()) + 1,
                "largest_segment_m": [float(v) for v in ext],
            }  # fmt: skip
    for name, xyz, truth, masks, objects in kept_aside():
        for m in methods:
            labels, ground, eps, kind = segment(m, xyz)
            r = ground_score(ground, truth)
            for c, mask in masks.items():
                if mask.any():
                    r[f"{c}_as_ground"] = float(ground[mask].mean())
            if objects:
                r.update(objects_score(labels, objects))
            r.update(kind=kind, eps=eps)
            results["kept_aside"].setdefault(m, {})[name] = r
        print(
            name,
            {
                m: round(results["kept_aside"][m][name]["ground_precision"], 3)
                for m in methods
            },
        )
    for kind, seed, xyz, cls, truth in dales_scenes_with_truth():
        objects = [np.flatnonzero(truth == i) for i in np.unique(truth[truth >= 0])]
        for m in methods:
            labels, ground, eps, found = segment(m, xyz)
            r = ground_score(ground, truth == -1)
            r.update(objects_score(labels, objects))
            r.update(kind=found, eps=eps)
            results["dales"].setdefault(m, {})[f"{kind.split()[-1]}_{seed}"] = r
        print(
            kind,
            seed,
            {
                m: round(results["dales"][m][f"{kind.split()[-1]}_{seed}"]["whole"], 2)
                for m in methods
            },
        )
    for name, xyz, truth, objects in simulated():
        for m in methods:
            labels, ground, eps, kind = segment(m, xyz)
            r = ground_score(ground, truth)
            r.update(objects_score(labels, objects))
            r.update(kind=kind, eps=eps)
            results["simulated"].setdefault(m, {})[name] = r
        print(
            name, {m: round(results["simulated"][m][name]["whole"], 2) for m in methods}
        )
    return results


def mean_rows(per, keys):
    rows = list(per.values())
    return {
        k: float(np.nanmean([r[k] for r in rows if k in r]))
        if any(k in r for r in rows)
        else float("nan")
        for k in keys
    }


def kinds_found(per):
    """How many scenes of ``per`` were found of each kind."""
    kinds = {}
    for r in per.values():
        kinds[r["kind"]] = kinds.get(r["kind"], 0) + 1
    return kinds


def summary_line(method, per, keys, fmt):
    """One row of a table: the method, the mean of each key over the scenes
    of ``per``, the kinds found."""
    row = mean_rows(per, keys)
    found = ", ".join(f"{k} {v}" for k, v in kinds_found(per).items())
    return (
        f"{method:<22}" + "".join(f"{row[k]:>17{fmt}}" for k in keys) + f"{found:>20}"
    )


def per_scan_lines(per_method, methods, key):
    """One row a scan: ``key`` for each of ``methods`` (the defaults before
    and after, scan by scan)."""
    scans = [
        k for k in per_method[methods[0]] if key in per_method[methods[0]][k]
    ]  # fmt: skip
    lines = [f"  {key + ' by scan':<22}" + "".join(f"{m:>12}" for m in methods)]
    for scan in scans:
        values = [per_method[m].get(scan, {}).get(key, float("nan")) for m in methods]
        lines.append(f"  {scan:<22}" + "".join(f"{v:>12.4f}" for v in values))
    return lines


def write(results, out):
    lines = [
        "segment_scene defaults by kind of scan (benchmarks/bench_scan_kinds.py)",
        f"{results['date']}, commit {results['commit']}, {results['machine']}",
    ]
    keys = (
        "kept",
        "whole",
        "purity",
        "car_as_ground",
        "person_as_ground",
        "other_as_ground",
    )
    lines += [
        "",
        "real car-mounted sweeps (../shared/data/real_mobile, 12 scans, boxes only): "
        "mean over scans; X_as_ground = share of the boxed X points taken as ground",
        f"{'method':<22}" + "".join(f"{k:>17}" for k in keys) + f"{'kinds found':>20}",
    ]
    for m, per in results["real_mobile"].items():
        lines.append(summary_line(m, per, keys, ".3f"))
    lines += per_scan_lines(results["real_mobile"], ("auto", "previous"), "whole")
    lines += per_scan_lines(results["real_mobile"], ("auto", "previous"), "purity")
    keys = ("ground_error", "ground_recall", "ground_precision")
    lines += ["", "real airborne: ISPRS filter test, 15 samples (mean)"]
    lines.append(
        f"{'method':<22}" + "".join(f"{k:>17}" for k in keys) + f"{'kinds found':>20}"
    )
    for m, per in results["aerial"].items():
        samples = {k: v for k, v in per.items() if k.startswith("samp")}
        lines.append(summary_line(m, samples, keys, ".4f"))
    lines += per_scan_lines(results["aerial"], ("auto", "previous"), "ground_error")
    for m, per in results["aerial"].items():
        if "autzen_trim" in per:
            a = per["autzen_trim"]
            lines.append(
                f"autzen_trim (PDAL, in metres) {m}: {a['kind']}, "
                f"eps {a['eps']:.2f} m, "
                f"{a['segments']} segments, largest {a['largest_segment_m'][0]:.0f} x "
                f"{a['largest_segment_m'][1]:.0f} m"
            )
    keys = (
        "ground_recall", "ground_precision", "car_as_ground",
        "vegetation_as_ground", "pole_as_ground", "whole", "purity",
    )  # fmt: skip
    lines += ["", "kept aside, scored once: real labelled sweeps (mean per source)"]
    for source in ("semantickitti07", "pandaset", "nuscenes"):
        lines.append(f"{source}")
        lines.append(
            f"  {'method':<20}" + "".join(f"{k:>15}" for k in keys) + f"{'kinds':>16}"
        )
        for m, per in results["kept_aside"].items():
            mine = {k: v for k, v in per.items() if k.startswith(source)}
            if not mine:
                continue
            row = mean_rows(mine, keys)
            kinds = sorted({r["kind"] for r in mine.values()})
            lines.append(
                f"  {m:<20}"
                + "".join(f"{row[k]:>15.3f}" for k in keys)
                + f"{','.join(kinds):>16}"
            )
    keys = ("ground_recall", "ground_precision", "kept", "whole", "purity")
    lines += [
        "",
        "real DALES objects on a synthetic terrain (make_scene as in bench_ground.py; "
        "aerial-like and mobile-like samplings, mean over seeds)",
    ]
    for m, per in results["dales"].items():
        for sampling in ("aerial", "mobile"):
            mine = {k: v for k, v in per.items() if k.startswith(sampling)}
            row = mean_rows(mine, keys)
            found = ", ".join(f"{k} {v}" for k, v in kinds_found(mine).items())
            lines.append(
                f"{sampling:<10}{m:<22}"
                + "".join(f"{k} {row[k]:.3f}  " for k in keys)
                + f"kinds {found}"
            )
    lines += ["", "simulated streets, one per pattern (exact truth)"]
    for m, per in results["simulated"].items():
        for name, r in per.items():
            lines.append(
                f"{name:<10}{m:<22}"
                + "".join(f"{k} {r[k]:.3f}  " for k in keys)
                + f"kind {r['kind']}"
            )
    if "kinds" in results:
        lines += kinds_lines(results["kinds"])
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    print("\n".join(lines))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--methods", nargs="*", default=list(METHODS), choices=METHODS)
    p.add_argument("--out", type=Path, default=HERE / "results" / "scan_kinds.json")
    p.add_argument(
        "--kinds-only",
        action="store_true",
        help="measure only the kind found on each real scan and add it to the "
        "results already in --out",
    )
    args = p.parse_args()
    if args.kinds_only:
        results = json.loads(args.out.read_text())
        results["kinds"] = scan_kinds()
        write(results, args.out)
        return
    started = commit()  # the code measured, before any later commit
    results = run(args.methods)
    results.update(
        date=time.strftime("%Y-%m-%dT%H:%M:%S"), commit=started, machine=machine()
    )
    results["kinds"] = scan_kinds()
    write(results, args.out)


if __name__ == "__main__":
    main()
