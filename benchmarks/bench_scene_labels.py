"""Per-point scores of whole real scans: skpcd identify against the truth.

On the real street scans labelled point by point of ``../shared/data/real_labelled``
(SemanticKITTI, HDL-64E; nuScenes-lidarseg, HDL-32E, one scene; PandaSet, Pandar64;
``$SKPCD_REAL_LABELLED_DIR`` to point elsewhere), each scored scan goes through the
commands a user runs, as subprocesses of this environment's ``skpcd``::

    skpcd identify SCAN -o OUT.laz [--model MODEL] --n-jobs -1
    skpcd score-scan OUT.laz ... --truth semantic --map MAP --classes C -o report.json

and, for the fitted models, ``skpcd fit SCANS --labels-from semantic --class-map MAP
-o MODEL.skpcd --n-jobs -1``. The models, for every source scored:

- ``shipped``: the street model shipped with skpcd (identify without ``--model``),
  fitted on simulated streets only: zero-shot;
- ``from <source>``: fitted on all the scans of another source (one row per source);
- ``same source``: fitted on other scans of the same source, grouped so that no
  near-duplicate of a scored scan is in its training set: SemanticKITTI by sequence
  (``--kitti-folds`` contiguous folds of its sequences), PandaSet by sequence (3 folds,
  one sequence each), nuScenes (one scene) by keyframe: the core keyframes in two
  contiguous halves, each scored by a model fitted on the other half less the
  keyframes within ``--gap`` keyframes of a scored one. The folds' predictions are
  pooled into one score.

Only the ``core`` scans of ``scans.csv`` are scored (the README of the data marks
near-duplicate frames ``core=0``); the models are fitted on every scan of their
training sources (in the folds, of their training groups). The classes scored are
ground, building, vegetation, car, person, pole_like and traffic_sign where the
source's truth has them (``benchmarks/maps/street_classes.csv``); on nuScenes, which
has no separate building, fence, pole or sign classes, ground, vegetation, car,
person and their union ``manmade`` (``benchmarks/maps/street_classes_nuscenes.csv``,
which the nuScenes models are also fitted with). The other true classes (fence,
other) stay in the truth, so that their points count against a class predicted on
them, but are not averaged. Every row also carries the scores under the nuScenes map
(``manmade_union``), the one comparison that holds across the three sources.

Scores are pooled over the scored scans of a source (per-class IoU, their mean, the
overall accuracy), with the spread of the per-scan mIoU (over the classes each scan
holds). Times are the wall and CPU seconds of each ``skpcd identify`` process
(interpreter start, imports and writing the LAZ included), with the load average
around them: the machine has 2 cores and may be shared, so they are indicative.

    python benchmarks/bench_scene_labels.py                   # 20-30 minutes
    python benchmarks/bench_scene_labels.py --sources pandaset --train-sources \\
        nuscenes --out /tmp/scene_labels.json                 # a quick check

Results: ``benchmarks/results/scene_labels.{json,txt}``.
"""

import argparse
import csv
import json
import os
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from measure import loadavg, provenance, write_results  # noqa: E402

DATA = Path(
    os.environ.get(
        "SKPCD_REAL_LABELLED_DIR", ROOT.parent / "shared" / "data" / "real_labelled"
    )
)
STREET_MAP = HERE / "maps" / "street_classes.csv"
NUSCENES_MAP = HERE / "maps" / "street_classes_nuscenes.csv"
SOURCES = ("semantickitti", "nuscenes", "pandaset")
NAMES = {
    "semantickitti": "SemanticKITTI",
    "nuscenes": "nuScenes",
    "pandaset": "PandaSet",
}
# the map of each source's truth, and of the models fitted on it
MAPS = {"semantickitti": STREET_MAP, "nuscenes": NUSCENES_MAP, "pandaset": STREET_MAP}
SCORED = {
    STREET_MAP: (
        "ground",
        "building",
        "vegetation",
        "car",
        "person",
        "pole_like",
        "traffic_sign",
    ),
    NUSCENES_MAP: ("ground", "vegetation", "car", "person", "manmade"),
}
MODELS = ("shipped", "other", "same")


def skpcd_command():
    """This environment's ``skpcd`` console script."""
    script = Path(sys.executable).with_name("skpcd")
    if script.exists():
        return [str(script)]
    found = shutil.which("skpcd")
    if found is None:
        sys.exit("no skpcd command in this environment: pip install -e .")
    return [found]


def scans_table(data=DATA):
    """The rows of ``scans.csv``, by source (``kind``), in file order."""
    with open(data / "scans.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    out = {s: [] for s in SOURCES}
    for r in rows:
        out[r["kind"]].append(
            {
                "file": r["file"],
                "path": data / "scans" / r["file"],
                "sequence": r["sequence"],
                "frame": r["frame"],
                "core": r["core"] == "1",
                "points": int(r["points"]),
            }
        )
    return out


def rel(path):
    """A path as the results file shows it: within the repository, or its name."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def map_record(path):
    """A class map as the results file holds it."""
    from skpcd.io import read_class_map

    m = read_class_map(path)
    return {
        "file": rel(path),
        "by_code": {str(k): v for k, v in sorted(m.by_code.items())},
        "by_name": dict(m.by_name),
    }


def classes_present(scans, class_map):
    """Points of each class in the truth of ``scans`` under ``class_map``."""
    from skpcd.io import read_point_labels

    counts = {}
    for scan in scans:
        labels = read_point_labels(
            scan["path"], "semantic", instances=None, class_map=class_map
        ).labels
        names, n = np.unique(labels, return_counts=True)
        for name, k in zip(names.tolist(), n.tolist()):
            counts[name] = counts.get(name, 0) + k
    return dict(sorted(counts.items()))


def run(cmd, log):
    """Run ``cmd``; its wall and CPU seconds and the load before and after."""
    load = loadavg()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(log, "a") as f:
        f.write(f"$ {shlex.join(map(str, cmd))}\n{done.stdout}{done.stderr}\n")
    if done.returncode != 0:
        raise RuntimeError(
            f"{shlex.join(map(str, cmd))} failed ({done.returncode}):\n"
            f"{done.stdout}{done.stderr}"
        )
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "load": load,
        "stdout": done.stdout,
    }


class Bench:
    """The models fitted and the scans identified, in a work folder."""

    def __init__(self, args):
        self.args = args
        self.skpcd = skpcd_command()
        self.work = Path(args.work)
        self.log = self.work / "commands.log"
        self.fits = {}

    def fit(self, key, scans, class_map):
        """``skpcd fit`` on ``scans``; the model's path (fitted once per key)."""
        if key in self.fits:
            return self.fits[key]["model"]
        model = self.work / "models" / f"{key}.skpcd"
        model.parent.mkdir(parents=True, exist_ok=True)
        cmd = [
            *self.skpcd,
            "fit",
            *[s["path"] for s in scans],
            "--labels-from",
            "semantic",
            "--class-map",
            class_map,
            "-o",
            model,
            "--n-jobs",
            str(self.args.n_jobs),
            "--overwrite",
        ]
        print(f"fit       {key}: {len(scans)} scans", flush=True)
        t = run(cmd, self.log)
        from skpcd.io import load_model

        _, info = load_model(model, return_info=True)
        meta = info["metadata"]
        self.fits[key] = {
            "model": model,
            "scans": [s["file"] for s in scans],
            "class_map": rel(class_map),
            "n_segments": meta["n_segments"],
            "classes": meta["classes"],
            "pipeline": meta["pipeline"],
            "objects": next(
                (ln for ln in t["stdout"].splitlines() if ln.startswith("objects")),
                "",
            ),
            "wall_s": t["wall_s"],
            "cpu_s": t["cpu_s"],
            "load": t["load"],
        }
        print(f"          {t['wall_s']:.0f} s, {meta['classes']}", flush=True)
        return model

    def identify(self, key, scan, model):
        """``skpcd identify`` of one scan; the output's path and the times."""
        out = self.work / "pred" / key / scan["file"]
        out.parent.mkdir(parents=True, exist_ok=True)
        cmd = [*self.skpcd, "identify", scan["path"], "-o", out]
        cmd += [] if model is None else ["--model", model]
        cmd += ["--n-jobs", str(self.args.n_jobs), "--overwrite"]
        t = run(cmd, self.log)
        del t["stdout"]
        return out, {"scan": scan["file"], "points": scan["points"], **t}

    def score(self, preds, class_map, classes, name):
        """``skpcd score-scan`` of the predictions, pooled; its JSON report."""
        report = self.work / "scores" / f"{name}.json"
        report.parent.mkdir(parents=True, exist_ok=True)
        cmd = [
            *self.skpcd,
            "score-scan",
            *preds,
            "--truth",
            "semantic",
            "--map",
            class_map,
            "--classes",
            ",".join(classes),
            "-o",
            report,
            "--overwrite",
            "--quiet",
        ]
        run(cmd, self.log)
        return json.loads(report.read_text())


def folds(source, scans, args):
    """``(name, scored core scans, training scans)`` of the same-source rows."""
    if source == "nuscenes":  # one scene: two halves of its keyframes
        frame = {s["file"]: int(s["frame"]) for s in scans}
        core = [s for s in scans if s["core"]]
        k = (len(core) + 1) // 2
        halves = [core[:k], core[k:]]
        start_b = frame[halves[1][0]["file"]]  # the first keyframe of half two
        out = []
        for half, scored in enumerate(halves):
            near = [frame[c["file"]] for c in scored]
            train = [
                s
                for s in scans
                if (frame[s["file"]] < start_b) == (half == 1)
                and min(abs(frame[s["file"]] - f) for f in near) > args.gap
            ]
            kept = [frame[s["file"]] for s in train]
            name = f"keyframes {min(near):02d}-{max(near):02d}"
            out.append(
                (
                    name,
                    scored,
                    train,
                    f"scored: core {name}; fitted on keyframes {min(kept):02d}-"
                    f"{max(kept):02d} (the other half, less those within "
                    f"{args.gap} keyframes of a scored one)",
                )
            )
        return out
    sequences = sorted({s["sequence"] for s in scans})
    n = args.kitti_folds if source == "semantickitti" else len(sequences)
    out = []
    for group in np.array_split(np.array(sequences), n):
        group = set(group.tolist())
        scored = [s for s in scans if s["core"] and s["sequence"] in group]
        train = [s for s in scans if s["sequence"] not in group]
        name = "sequences " + ",".join(sorted(group))
        out.append(
            (
                name,
                scored,
                train,
                f"scored: core scans of {name}; fitted on every scan of sequences "
                + ",".join(sorted({s["sequence"] for s in train})),
            )
        )
    return out


def summary(report, classes):
    """The pooled scores and the per-scan spread of a score-scan report."""
    pooled = report["pooled"]
    per_scan = [s["miou"] for s in report["scans"]]
    return {
        "classes": classes,
        "miou": pooled["miou"],
        "accuracy": pooled["accuracy"],
        "iou": pooled["iou"],
        "precision": pooled["precision"],
        "recall": pooled["recall"],
        "support": pooled["support"],
        "n_points": pooled["n_points"],
        "n_ignored": pooled["n_ignored"],
        "predicted": pooled["predicted"],
        "confusion": pooled["confusion"],
        "per_scan": [
            {
                "scan": Path(s["prediction"]).name,
                "miou": s["miou"],
                "accuracy": s["accuracy"],
                "classes": s["classes"],
            }
            for s in report["scans"]
        ],
        "per_scan_miou": {
            "min": float(np.min(per_scan)),
            "median": float(np.median(per_scan)),
            "max": float(np.max(per_scan)),
            "std": float(np.std(per_scan)),
        },
    }


def time_summary(times):
    wall = [t["wall_s"] for t in times]
    cpu = [t["cpu_s"] for t in times]
    loads = [t["load"][0] for t in times]
    return {
        "wall_s_median": float(np.median(wall)),
        "wall_s_min": float(np.min(wall)),
        "wall_s_max": float(np.max(wall)),
        "cpu_s_median": float(np.median(cpu)),
        "load_1min_min": float(np.min(loads)),
        "load_1min_max": float(np.max(loads)),
        "scans": times,
    }


def score_row(bench, source, key, parts, truth):
    """One row: identify every scored scan with its model (``parts``: ``(scans,
    model)`` pairs), score the predictions pooled under the source's map and
    under the nuScenes map."""
    preds, times = [], []
    for scans, model in parts:
        for scan in scans:
            out, t = bench.identify(key, scan, model)
            preds.append(out)
            times.append(t)
    row = {}
    for label, class_map in (("scores", MAPS[source]), ("manmade_union", NUSCENES_MAP)):
        classes = [c for c in SCORED[class_map] if truth[rel(class_map)].get(c, 0) > 0]
        name = f"{source}_{key}_{Path(class_map).stem}"
        row[label] = summary(bench.score(preds, class_map, classes, name), classes)
    row["time"] = time_summary(times)
    s = row["scores"]
    print(
        f"{NAMES[source]:13s} {key:26s} mIoU {s['miou']:.3f} acc "
        f"{s['accuracy']:.3f} union {row['manmade_union']['miou']:.3f} "
        f"{row['time']['wall_s_median']:.1f} s/scan",
        flush=True,
    )
    return row


def text_report(results):
    lines = [
        "Per-point scores of real labelled scans: skpcd identify, scored by skpcd "
        "score-scan",
        f"commit {results['commit']}; {results['machine']}; {results['date']}",
        f"load average (1, 5, 15 min) at the start {results['load_start']}, "
        f"at the end {results['load_end']}; times are indicative",
        f"data: {results['data']}",
        "",
    ]
    for source, block in results["sources"].items():
        classes = block["classes"]
        lines += [
            f"{NAMES[source]} ({block['sensor']}): {len(block['scored_scans'])} "
            f"core scans scored, map {block['map']}",
            "classes scored: " + ", ".join(classes),
        ]
        short = [c[:8] for c in classes]
        head = (
            f"{'model':26s} {'mIoU':>6s} {'acc':>6s} "
            + " ".join(f"{c:>8s}" for c in short)
            + f" {'scan mIoU min/med/max':>22s} {'union':>6s} {'s/scan':>6s}"
        )
        lines += [head]
        for key, row in block["models"].items():
            s, u, t = row["scores"], row["manmade_union"], row["time"]
            spread = s["per_scan_miou"]
            lines.append(
                f"{key:26s} {s['miou']:6.3f} {s['accuracy']:6.3f} "
                + " ".join(f"{s['iou'][c]:8.3f}" for c in classes)
                + f" {spread['min']:6.3f}/{spread['median']:.3f}/{spread['max']:.3f}"
                + f" {u['miou']:6.3f} {t['wall_s_median']:6.1f}"
            )
        for key, row in block["models"].items():
            if row.get("training"):
                lines.append(f"  {key}: {row['training']}")
        lines.append("")
    lines += [
        "union: mIoU under the nuScenes map (ground, vegetation, car, person, "
        "manmade = building+fence+pole+sign+other-structure), comparable across "
        "sources",
        "s/scan: median wall seconds of one skpcd identify process (interpreter, "
        "imports, segmentation, classification, writing the LAZ)",
        "",
        "fits:",
    ]
    for key, fit in results["fits"].items():
        lines.append(
            f"  {key}: {len(fit['scans'])} scans, {fit['n_segments']} objects "
            f"{fit['classes']}, {fit['wall_s']:.0f} s (load {fit['load'][0]})"
        )
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sources",
        default=",".join(SOURCES),
        help="the sources scored (default all: " + ",".join(SOURCES) + ")",
    )
    ap.add_argument(
        "--train-sources",
        default=",".join(SOURCES),
        help="the sources the 'from <source>' models are fitted on (default all)",
    )
    ap.add_argument(
        "--models",
        default=",".join(MODELS),
        help="shipped, other (fitted on another source), same (fitted on other "
        "scans of the same source); default all",
    )
    ap.add_argument(
        "--kitti-folds",
        type=int,
        default=5,
        help="SemanticKITTI same-source folds of contiguous sequences (default 5)",
    )
    ap.add_argument(
        "--gap",
        type=int,
        default=4,
        help="nuScenes same-source: keyframes this near a scored one are not "
        "fitted on (default 4, 2 s)",
    )
    ap.add_argument("--n-jobs", type=int, default=-1)
    ap.add_argument("--work", help="folder for models and predictions (default: temp)")
    ap.add_argument("--out", default=str(HERE / "results" / "scene_labels.json"))
    args = ap.parse_args(argv)
    sources = args.sources.split(",")
    train_sources = args.train_sources.split(",")
    models = args.models.split(",")
    for name in (*sources, *train_sources):
        if name not in SOURCES:
            ap.error(f"unknown source {name!r}; known: {', '.join(SOURCES)}")
    for name in models:
        if name not in MODELS:
            ap.error(f"unknown model {name!r}; known: {', '.join(MODELS)}")
    temp = None
    if args.work is None:
        temp = tempfile.TemporaryDirectory(prefix="scene_labels_")
        args.work = temp.name
    Path(args.work).mkdir(parents=True, exist_ok=True)

    table = scans_table()
    bench = Bench(args)
    results = {
        **provenance(),
        "load_start": loadavg(),
        "command": shlex.join(["python", rel(__file__), *(argv or sys.argv[1:])]),
        "data": f"{DATA} (README.md there: frames, class mappings, licences)",
        "skpcd": shlex.join(bench.skpcd),
        "n_jobs": args.n_jobs,
        "maps": {rel(m): map_record(m) for m in (STREET_MAP, NUSCENES_MAP)},
        "scored_classes": {rel(m): list(c) for m, c in SCORED.items()},
        "sources": {},
        "fits": {},
    }
    sensors = {
        "semantickitti": "HDL-64E",
        "nuscenes": "HDL-32E",
        "pandaset": "Pandar64",
    }
    start = time.perf_counter()
    for source in sources:
        scans = table[source]
        core = [s for s in scans if s["core"]]
        truth = {rel(m): classes_present(core, m) for m in dict.fromkeys(MAPS.values())}
        classes = [c for c in SCORED[MAPS[source]] if truth[rel(MAPS[source])].get(c)]
        block = results["sources"][source] = {
            "sensor": sensors[source],
            "map": rel(MAPS[source]),
            "classes": classes,
            "truth_points": truth,
            "scored_scans": [s["file"] for s in core],
            "training_scans": len(scans),
            "models": {},
        }
        rows = block["models"]
        if "shipped" in models:
            rows["shipped"] = score_row(bench, source, "shipped", [(core, None)], truth)
            rows["shipped"]["training"] = "the shipped street model (simulated only)"
        if "other" in models:
            for other in train_sources:
                if other == source:
                    continue
                model = bench.fit(f"all_{other}", table[other], MAPS[other])
                key = f"from {NAMES[other]}"
                rows[key] = score_row(bench, source, key, [(core, model)], truth)
                rows[key]["training"] = (
                    f"fitted on all {len(table[other])} scans of {NAMES[other]} "
                    f"(map {rel(MAPS[other])})"
                )
        if "same" in models:
            parts, said = [], []
            for name, scored, train, text in folds(source, scans, args):
                fit_key = f"{source}_{name.replace(' ', '_').replace(',', '+')}"
                parts.append((scored, bench.fit(fit_key, train, MAPS[source])))
                said.append(text)
            rows["same source"] = score_row(bench, source, "same source", parts, truth)
            rows["same source"]["training"] = "; ".join(said)
            rows["same source"]["folds"] = said
            if source == "nuscenes":
                rows["same source"]["note"] = (
                    "nuScenes is one scene: the two halves are 10 s of driving "
                    "apart at most, and a model fitted on one half has seen some "
                    "of the other half's objects from farther away"
                )
    results["fits"] = {
        k: {kk: (rel(v) if kk == "model" else v) for kk, v in f.items()}
        for k, f in bench.fits.items()
    }
    for fit in results["fits"].values():
        fit.pop("model")
    results["load_end"] = loadavg()
    results["seconds_total"] = round(time.perf_counter() - start, 1)
    text = text_report(results)
    write_results(args.out, results, text)
    print()
    print(text)
    if temp is not None:
        temp.cleanup()


if __name__ == "__main__":
    main()
