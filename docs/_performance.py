"""The tables of the Performance page, read from ``benchmarks/results/*.json``.

Every measured figure the documentation shows is in a table of this module, written
at build time from the result file a benchmark script left, with the file, the commit
and the machine that file records (or "not recorded" where it records none). The page
``docs/performance.rst`` places the tables with the directive ``performance-table``,
defined here and registered by ``docs/conf.py`` (``extensions``); ``render`` gives a
table's reStructuredText without Sphinx, for the tests
(``tests/test_performance_page.py``).

A table is a list of rows of cells: a cell is either a :class:`Text` taken from the
file (a name, a setting) or a :class:`Number`, which keeps the values of the file it
was computed from, so that a test can check the figure against the file. A missing or
malformed file, or a missing key, raises :class:`ResultsError` naming the file and the
key: the docs build then fails, rather than showing a table with a hole.
"""

import json
from dataclasses import dataclass
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
NOT_RECORDED = "not recorded"


class ResultsError(ValueError):
    """A result file is missing, is not JSON, or lacks a key a table reads."""


class Text(str):
    """A cell copied from the result file (a name, a setting, an error)."""


class Number(str):
    """A figure as shown, with the values of the result file it comes from.

    ``values`` are the numbers read from the file; the figure is ``values[0] *
    scale``, their ratio ``values[0] / values[1]`` (``op="ratio"``) or their mean
    times ``scale`` (``op="mean"``), rounded to ``digits`` decimals.
    """

    def __new__(cls, values, digits, scale=1.0, op="scale"):
        values = tuple(float(v) for v in values)
        if op == "ratio":
            figure = values[0] / values[1]
        elif op == "mean":
            figure = sum(values) / len(values) * scale
        else:
            figure = values[0] * scale
        self = super().__new__(cls, f"{figure:,.{digits}f}".replace(",", " "))
        self.values, self.digits, self.scale, self.op = values, digits, scale, op
        self.figure = figure
        return self


def num(value, digits=2, scale=1.0):
    """A figure read from the file: ``value * scale`` to ``digits`` decimals."""
    return Number([value], digits, scale)


def pct(value, digits=1):
    """A share stored as a fraction, shown in per cent."""
    return Number([value], digits, 100.0)


def ratio(numerator, denominator, digits=2):
    """The ratio of two values of the file (a speed-up)."""
    return Number([numerator, denominator], digits, op="ratio")


def mean_pct(values, digits=1):
    """The mean of shares stored as fractions (draws of one setting), in per cent."""
    return Number(values, digits, 100.0, op="mean")


MIB = 1.0 / 2**20


# ---------------------------------------------------------------------------
# Reading the files


def load(name, results=RESULTS):
    """The parsed result file ``name`` of the folder ``results``.

    Raises
    ------
    ResultsError
        When the file is missing or is not JSON; the message names the file.
    """
    path = Path(results) / name
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ResultsError(f"{path}: no such result file") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ResultsError(f"{path}: not JSON ({exc})") from None


class _Reader:
    """``data[key]`` that names the file and the key path when a key is missing."""

    def __init__(self, data, name, path=()):
        self.data, self.name, self.path = data, name, path

    def __getitem__(self, key):
        try:
            value = self.data[key]
        except (KeyError, IndexError, TypeError):
            where = "".join(f"[{k!r}]" for k in (*self.path, key))
            raise ResultsError(
                f"benchmarks/results/{self.name}: no {where} in the file"
            ) from None
        if isinstance(value, dict | list):
            return _Reader(value, self.name, (*self.path, key))
        return value

    def get(self, key, default=None):
        try:
            return self[key]
        except ResultsError:
            return default

    def items(self):
        return [(k, self[k]) for k in self.data]

    def __iter__(self):
        return (self[i] for i in range(len(self.data)))

    def __len__(self):
        return len(self.data)


def _machine_text(machine):
    if isinstance(machine, _Reader):
        cpu = machine.get("cpu_model") or machine.get("cpu")
        cores = machine.get("nproc") or machine.get("cores")
        parts = [str(p) for p in (cpu, cores and f"{cores} cores") if p]
        return ", ".join(parts) or NOT_RECORDED
    return str(machine) if machine else NOT_RECORDED


def provenance(data):
    """Commit, machine and date a result file records, or "not recorded".

    Looked up at the top of the file and in its ``meta`` block, where the
    benchmark scripts write them.
    """
    meta = data.get("meta") or _Reader({}, data.name)

    def first(key):
        for block in (data, meta):
            value = block.get(key)
            if value:
                return value
        return None

    commit = first("commit")
    if isinstance(commit, _Reader):  # {"head": ..., "skpcd_dirty": ...}
        commit = commit.get("head")
    return {
        "commit": str(commit) if commit else NOT_RECORDED,
        "machine": _machine_text(first("machine")),
        "date": str(first("date") or NOT_RECORDED),
    }


# ---------------------------------------------------------------------------
# The tables, one function each: (header, rows, provenance)


def _descriptor_speedups(data):
    rows = [
        [Text(r["name"]), num(r["ratio"], 1), num(r["cpu_ratio"], 1)]
        for r in data["ratios"]
    ]
    header = ["comparison", "wall-clock ratio", "CPU-time ratio"]
    return header, rows, provenance(data)


def _descriptor_times(data):
    rows = [
        [
            Text(c["case"]),
            Text(c["layout"]),
            num(c["n_points"], 0),
            Text(c["tool"]),
            num(c["wall"], 2),
            num(c["cpu"], 2),
        ]
        for c in data["cases"]
    ]
    header = ["case", "layout", "points", "tool", "wall s", "CPU s"]
    return header, rows, provenance(data)


def _descriptor_memory(data):
    rows = [
        [
            Text(c["case"]),
            Text(c["layout"]),
            Text(c["tool"]),
            num(c["in_bytes"], 0, MIB),
            num(c["out_bytes"], 0, MIB),
            num(c["mem_extra_mb"], 0),
        ]
        for c in data["cases"]
        if c.get("mem_extra_mb") is not None
    ]
    header = ["case", "layout", "tool", "input MiB", "output MiB", "peak MiB"]
    return header, rows, provenance(data)


def _threads(data):
    rows = []
    for stage, runs in data["stages"].items():
        one, two = runs["1"]["best"], runs["2"]["best"]
        rows.append([Text(stage), num(one, 2), num(two, 2), ratio(one, two)])
    header = ["stage", "1 thread, s", "2 threads, s", "speed-up"]
    return header, rows, provenance(data)


def _point_order(data):
    rows = [
        [Text(r["estimator"]), Text(r["variant"]), num(r["seconds"], 2)]
        for r in data["rows"]
    ]
    rows += [
        [Text("FPFHTransformer, peak memory"), Text(p["variant"]), num(p["peak_mb"], 0)]
        for p in data["peak"]
    ]
    header = ["estimator", "point order", "seconds (peak: MiB)"]
    return header, rows, provenance(data)


def _first_call(data):
    rows = []
    for tree, block in data["trees"].items():
        for call, row in block["rows"].items():
            said = row["cold"].get("compile_s_said")
            rows.append(
                [
                    Text(f"{tree} ({block['commit']})"),
                    Text(call),
                    num(row["cold"]["wall_s"], 1),
                    num(said, 1) if said is not None else Text(NOT_RECORDED),
                    num(row["warm"]["wall_s"], 1),
                ]
            )
    header = ["tree (commit)", "call", "cold cache, s", "compiling, s", "warm cache, s"]
    commits = ", ".join(
        f"{tree} {block['commit']}" for tree, block in data["trees"].items()
    )
    return header, rows, {**provenance(data), "commit": commits}


def _ground(data):
    rows = [
        [
            Text(scene),
            Text(method),
            pct(row["ground_recall"], 2),
            pct(row["object_loss"], 1),
            num(row["seconds"], 2),
        ]
        for scene, methods in data["quality"].items()
        for method, row in methods.items()
    ]
    header = ["scene", "ground filter", "ground recall %", "object loss %", "seconds"]
    return header, rows, provenance(data)


def _ground_memory(data):
    rows = [
        [
            Text(r["method"]),
            num(r["points"], 0),
            num(r["seconds"], 2),
            num(r["peak_mb"], 0),
            num(r["bytes_per_point"], 0),
        ]
        for r in data["memory"]["runs"]
    ]
    header = ["ground filter", "points", "seconds", "peak MiB", "bytes per point"]
    return header, rows, provenance(data)


def _clustering(data):
    rows = [
        _clustering_row(run, run[eps], tool)
        for run in data["runs"]
        for eps in ("auto", "wide")
        for tool in ("dbscan", "sklearn", "open3d")
    ]
    header = ["points", "eps (m)", "tool", "seconds", "peak MiB"]
    return header, rows, provenance(data)


def _clustering_row(run, block, tool):
    row = block.get(tool)
    head = [num(run["n_points"], 0), num(block["eps"], 2), Text(tool)]
    if row is None or row.get("seconds") is None:
        reason = row.get("error") if row is not None else None
        return [*head, Text(reason or NOT_RECORDED), Text("")]
    return [*head, num(row["seconds"], 2), num(row["peak_mb"], 0)]


def _street_segmentation(data):
    rows = []
    for t in data["timing"]:
        head = [num(t["points"], 0), Text(t["stage"])]
        if t.get("seconds") is None:
            rows.append([*head, Text(t.get("error") or NOT_RECORDED), Text("")])
        else:
            rows.append([*head, num(t["seconds"], 2), num(t["peak_mb"], 0)])
    header = ["points", "stage", "seconds", "peak MiB"]
    return header, rows, provenance(data)


def _throughput_segment(data):
    rows = []
    for r in data["segment"]["best"]:
        failed = r.get("error") is not None
        rows.append(
            [
                Text(f"{r['size']:g} M") if failed else num(r["points"], 0),
                Text(r["tool"]),
                num(r["seconds"], 1),
                num(r["peak_mb"], 0),
                Text("failed (memory cap)" if failed else "done"),
            ]
        )
    header = ["points", "job", "seconds", "peak MiB", "result"]
    return header, rows, _throughput_provenance(data, "segment")


def _throughput_identify(data):
    rows = [
        [
            Text(r["dataset"]),
            Text(r["pipeline"]),
            num(r["n_jobs"], 0),
            num(r["fit_segments_per_s"], 0),
            num(r["predict_segments_per_s"], 0),
        ]
        for r in data["identify"]["best"]
    ]
    header = ["data", "pipeline", "threads", "fit, segments/s", "predict, segments/s"]
    return header, rows, _throughput_provenance(data, "identify")


def _throughput_provenance(data, part):
    runs = [r for r in data["runs"] if r["part"] == part]
    commits = sorted({str(r["commit"]) for r in runs if r.get("commit")})
    dates = sorted(str(r["date"]) for r in runs if r.get("date"))
    return {
        **provenance(data),
        "commit": ", ".join(commits) or NOT_RECORDED,
        "date": f"{dates[0]} to {dates[-1]}" if dates else NOT_RECORDED,
    }


def _segments(data):
    rows = [
        [
            Text(r["step"]),
            num(r["n_jobs"], 0),
            num(r["seconds"], 2),
            num(r["segments_per_s"], 0),
        ]
        for r in data["rows"]
    ]
    header = ["step", "threads", "seconds", "segments/s"]
    return header, rows, provenance(data)


def _simulation(data):
    rows = [
        [
            Text(r["pattern"]),
            num(r["n_jobs"], 0),
            num(r["pulses"], 0),
            num(r["returns"], 0),
            num(r["scan_wall_s"], 2),
            num(r["scan_cpu_s"], 2),
        ]
        for r in data["rows"]
    ]
    header = ["pattern", "threads", "pulses", "returns", "wall s", "CPU s"]
    return header, rows, provenance(data)


def _scaling_segments(data):
    part = data["segments"]
    rows = []
    for config, row in part["best"].items():
        workers = [num(w["above_warm_mb"], 0) for w in row["workers"]]
        rows.append(
            [
                Text(config),
                num(row["seconds"], 0),
                num(row["n_segments"], 0),
                num(row["driver_above_warm_mb"], 0),
                _joined(workers),
            ]
        )
    header = ["configuration", "seconds", "segments", "driver MiB", "worker MiB"]
    return header, rows, {**provenance(data), "date": str(part["date"])}


def _scaling_scene(data):
    part = data["scene"]
    rows = []
    for config, row in part["best"].items():
        workers = [num(w["above_warm_mb"], 0) for w in row["workers"]]
        rows.append(
            [
                Text(config),
                num(row["n_points"], 0),
                num(row["seconds"], 0),
                num(row["driver_above_warm_mb"], 0),
                _joined(workers),
            ]
        )
    header = [
        "scan:configuration@tile",
        "points",
        "seconds",
        "driver MiB",
        "worker MiB",
    ]
    commits = f"{part['commit']['head']}, rerun {part['rerun']['commit']['head']}"
    return header, rows, {**provenance(data), "commit": commits, "date": part["date"]}


def _joined(numbers):
    """Several figures in one cell (one per Dask worker), or an empty cell."""
    if not numbers:
        return Text("")
    return numbers[0] if len(numbers) == 1 else _Several(numbers)


class _Several(Text):
    """Figures of one cell, shown with " / " between them."""

    def __new__(cls, numbers):
        self = super().__new__(cls, " / ".join(numbers))
        self.numbers = tuple(numbers)
        return self


def _identification(data):
    rows = [
        [
            Text(r["features"]),
            Text(r["classifier"]),
            pct(r["accuracy_mean"], 1),
            pct(r["accuracy_std"], 1),
        ]
        for r in data["best"]
    ]
    nested = data["nested"]
    rows.append(
        [
            Text("nested CV of the choice"),
            Text(""),
            pct(nested["accuracy_mean"], 1),
            pct(nested["accuracy_std"], 1),
        ]
    )
    header = ["features", "classifier", "accuracy %", "std %"]
    return header, rows, provenance(data)


def _street_identification(data):
    datasets = list(data["data"].data)
    rows = [
        [Text(name)] + [pct(cv[d]["macro_f1"], 1) for d in datasets]
        for name, cv in data["cv"].items()
    ]
    header = ["pipeline", *(f"{d}, macro F1 %" for d in datasets)]
    return header, rows, provenance(data)


def _few_shot(data):
    draws = {}  # (k, method) -> balanced accuracies of the draws, in file order
    for r in data["rows"]:
        draws.setdefault((str(r["k"]), r["method"]), []).append(r["balanced_accuracy"])
    rows = [
        [Text(k), Text(method), mean_pct(scores)]
        for (k, method), scores in draws.items()
    ]
    header = ["labels per class", "method", "balanced accuracy %"]
    return header, rows, provenance(data)


def _stages(data):
    rows = []
    for stage, clocks in data["stages"].items():
        row = [Text(stage)]
        for clock in ("wall", "cpu"):
            before, after = clocks[clock]["before"], clocks[clock]["after"]
            row += [num(before, 3), num(after, 3), ratio(after, before)]
        rows.append(row)
    header = [
        "stage", "wall before, s", "wall after, s", "wall after / before",
        "CPU before, s", "CPU after, s", "CPU after / before",
    ]  # fmt: skip
    where = provenance(data)
    commits = data["commit"]
    where["commit"] = f"{commits['before']} (before), {commits['after']} (after)"
    return header, rows, where


def _tiles(data):
    rows = []
    for r in data["scans"]:
        csf, street, st = r["csf"], r["street"], r["structures"]
        rows.append(
            [
                Text(r["scan"]),
                num(r["points"], 0),
                num(csf["ground_differ"], 0),
                Text("same" if csf["labels_identical"] else "differ"),
                num(street["ground_differ"], 0),
                Text("same" if street["labels_identical"] else "differ"),
                num(st["ari"], 5),
                pct(st["mismatch"], 3),
            ]
        )
    header = [
        "sweep",
        "points",
        "csf: ground flags differing",
        "csf: labels",
        "street: ground flags differing",
        "street: labels",
        "with structures: adjusted Rand index",
        "with structures: points in another segment %",
    ]
    return header, rows, provenance(data)


def _tiles_memory(data):
    phases = ("kind", "spill", "ground", "eps", "tiles", "stitch", "write")

    def anon(run, phase):
        seen = run["phases"].get(phase)
        return Text("") if seen is None else num(seen["anon_mib"], 0)

    def row(run):
        sizes = [num(run[k], 0) for k in ("n_points", "n_tiles", "largest_tile")]
        peaks = [anon(run, p) for p in phases]
        return [Text(run["scan"]), *sizes, *peaks, num(run["vmhwm_mib"], 0)]

    rows = [row(r) for r in data["runs"]]
    head = ["scan", "points", "tiles", "largest buffered tile, points"]
    header = [*head, *(f"{p}, MiB" for p in phases), "peak RSS, MiB"]
    return header, rows, provenance(data)


def _startup(data):
    rows = []
    for tree in ("before", "after"):
        for case, r in data["trees"][tree]["rows"].items():
            if case == "segment_cold":  # the first run: the first_call table's
                continue
            rows.append([
                Text(case), Text(tree), num(r["cpu_s"], 2), num(r["wall_s"], 2),
                num(r["cpu_ratio"], 2), num(r["wall_ratio"], 2),
            ])  # fmt: skip
    header = ["case", "tree", "CPU, s", "wall, s", "CPU / sklearn", "wall / sklearn"]
    where = provenance(data)
    trees = data["trees"]
    where["commit"] = (
        f"{trees['before']['commit']} (before), {trees['after']['commit']} (after)"
    )
    return header, rows, where


def _review(data):
    fcp = [r["fcp_ms"] for r in data["rounds"]]
    rows = [[
        num(data["n_segments"], 0), num(data["n_points"], 0), num(data["page_mb"], 1),
        num(sorted(fcp)[len(fcp) // 2], 0), num(max(fcp), 0),
    ]]  # fmt: skip
    header = [
        "segments", "points", "page, MB", "first paint median, ms",
        "first paint worst, ms",
    ]  # fmt: skip
    return header, rows, provenance(data)


def _sim_to_real(data):
    rows = [
        [
            Text(name),
            num(r["n_train"], 0),
            pct(r["balanced_accuracy"], 1),
            pct(r["balanced_accuracy_std"], 1),
        ]
        for name, r in data["recipes"].items()
    ]
    header = ["simulated training set", "objects", "balanced accuracy %", "std %"]
    return header, rows, provenance(data)


#: the classes of the labelled-scan table, in its column order (a source scores
#: those its truth has: nuScenes only ground, vegetation, car, person and manmade)
SCENE_CLASSES = (
    "ground",
    "building",
    "vegetation",
    "car",
    "person",
    "pole_like",
    "traffic_sign",
    "manmade",
)


def _scene_labels(data):
    rows = []
    for source, block in data["sources"].items():
        scored = list(block["classes"])
        for model, row in block["models"].items():
            scores = row["scores"]
            rows.append(
                [
                    Text(f"{source} ({block['sensor']})"),
                    Text(model),
                    pct(scores["miou"], 1),
                    *(
                        pct(scores["iou"][c], 1) if c in scored else Text("")
                        for c in SCENE_CLASSES
                    ),
                    pct(row["manmade_union"]["miou"], 1),
                    num(row["time"]["wall_s_median"], 1),
                ]
            )
    header = [
        "source (sensor)",
        "model",
        "mIoU %",
        *(f"{c} IoU %" for c in SCENE_CLASSES),
        "mIoU %, manmade as one class",
        "identify, s per scan",
    ]
    return header, rows, provenance(data)


def _maybe(value, digits):
    """A figure, or an empty cell where the file holds none (null)."""
    return Text("") if value is None else num(value, digits)


def _sweeps(data):
    rows = []
    for _, block in data["summary"]["real_labelled"].items():
        for method, r in block["methods"].items():
            rows.append(
                [
                    Text(block["sensor"]),
                    Text(method),
                    num(r["seconds"], 3),
                    num(r["x_open3d"], 1),
                    num(r["x_open3d_every_point"], 1),
                    *(
                        _maybe(r[k], 3)
                        for k in ("ground_precision", "ground_recall", "miou",
                                  "kept", "whole", "purity")
                    ),
                ]
            )  # fmt: skip
    for source, block in data["summary"]["real_mobile"].items():
        for method, r in block["methods"].items():
            rows.append(
                [
                    Text(f"real_mobile {source}"),
                    Text(method),
                    num(r["seconds"], 3),
                    Text(""),
                    Text(""),
                    Text(""),
                    Text(""),
                    Text(""),
                    *(_maybe(r[k], 3) for k in ("kept", "whole", "purity")),
                ]
            )
    header = [
        "sweeps (sensor)", "segmentation", "s per sweep", "x Open3D",
        "x Open3D cluster_dbscan",
        "ground precision", "ground recall", "mIoU", "objects kept", "whole",
        "purity",
    ]  # fmt: skip
    return header, rows, provenance(data)


def _sweeps_streamed(data):
    rows = []
    summary = data["summary"]
    for source, block in summary["streamed"].items():
        sensor = summary["real_labelled"][source]["sensor"]
        for method, r in block.items():
            held = r["held_back_by"]
            rows.append(
                [
                    Text(sensor),
                    Text(method),
                    *(num(r[k], 3) for k in ("segment", "classify", "write", "total")),
                    num(r["sweeps_per_s"], 1),
                    Text("-") if held is None else Text(held),
                ]
            )
    for r in summary["command"]:
        rows.append(
            [
                Text(summary["real_labelled"][r["source"]]["sensor"]),
                Text(f"skpcd identify --method {r['method']}"),
                Text(""),
                Text(""),
                Text(""),
                num(r["seconds"], 3),
                num(r["sweeps_per_s"], 1),
                Text(""),
            ]
        )
    header = [
        "sweeps (sensor)", "segmentation", "segment, s", "classify, s", "write, s",
        "total, s", "sweeps per s", "held back by",
    ]  # fmt: skip
    return header, rows, provenance(data)


@dataclass(frozen=True)
class Table:
    """One table of the page: the result file and the function reading it."""

    source: str
    read: object
    caption: str


TABLES = {
    "descriptor_speedups": Table(
        "descriptors.json",
        _descriptor_speedups,
        "Speed of skpcd's PFH and FPFH against PCL 1.13 and Open3D (the reference "
        "time over skpcd's; for the radius rows, skpcd's points per second over "
        "PCL's).",
    ),
    "descriptor_times": Table(
        "descriptors.json",
        _descriptor_times,
        "Neighbour search, normals and descriptor end to end, best of the runs.",
    ),
    "descriptor_memory": Table(
        "descriptors.json",
        _descriptor_memory,
        "skpcd's peak memory above the warm process, against its input and output.",
    ),
    "threads": Table(
        "threads.json",
        _threads,
        "Each stage on one thread and on two, best of the runs.",
    ),
    "point_order": Table(
        "point_order.json",
        _point_order,
        "The DALES objects as one cloud, in recorded order and shuffled.",
    ),
    "first_call": Table(
        "first_call.json",
        _first_call,
        "A fresh process with an empty numba cache (cold) and with the cache that "
        "run filled (warm), imports included.",
    ),
    "ground": Table(
        "ground.json",
        _ground,
        "Ground recall and object loss (share of the objects' points taken as "
        "ground), summed over the scenes.",
    ),
    "ground_memory": Table(
        "ground.json", _ground_memory, "Time and peak memory of the ground filters."
    ),
    "clustering": Table(
        "segmentation.json",
        _clustering,
        "Clustering the points above the ground with the same eps.",
    ),
    "street_segmentation": Table(
        "street_segmentation.json",
        _street_segmentation,
        "The stages of a street scan's segmentation and the reference clusterings.",
    ),
    "throughput_segment": Table(
        "throughput.json",
        _throughput_segment,
        "The whole job from a LAS file to its outputs, a process each (imports "
        "included).",
    ),
    "throughput_identify": Table(
        "throughput.json",
        _throughput_identify,
        "Fit on all segments of a data set, then predict the same segments.",
    ),
    "segments": Table(
        "segments.json", _segments, "Segment-level steps on the 399 DALES objects."
    ),
    "simulation": Table(
        "simulation.json", _simulation, "Scanning a simulated 100 m street."
    ),
    "scaling_segments": Table(
        "scaling.json",
        _scaling_segments,
        "Descriptors of 100 000 segments: local, and on a Dask LocalCluster.",
    ),
    "scaling_scene": Table(
        "scaling.json",
        _scaling_scene,
        "Tiled segmentation of a large LAS scan: local, and on a Dask LocalCluster.",
    ),
    "identification": Table(
        "identification.json",
        _identification,
        "Pipelines built from skpcd's pieces on the 399 DALES objects (real aerial "
        "LiDAR), 5-fold cross-validation repeated 3 times.",
    ),
    "street_identification": Table(
        "street_identification.json",
        _street_identification,
        "The candidates for the default pipeline on DALES and on simulated street "
        "objects.",
    ),
    "few_shot": Table(
        "few_shot_objects.json",
        _few_shot,
        "Real car-mounted sweeps: the shipped street model with no label, and a "
        "few real labels per class with and without simulated objects (mean over "
        "the draws of the labels).",
    ),
    "stages": Table(
        "stages.json",
        _stages,
        "Each stage before and after a change that should not change speed (best "
        "wall-clock and best CPU times of all the process's threads; a fresh "
        "process each, the two checkouts alternating).",
    ),
    "tiles": Table(
        "tiles.json",
        _tiles,
        "Tiled (30 m tiles) against in-memory segmentation of the 12 real "
        "car-mounted sweeps, eps 0.5 m: without the structures step (ground "
        "presets csf and street), then with it.",
    ),
    "tiles_memory": Table(
        "tiles_memory.json",
        _tiles_memory,
        "skpcd segment --tile-size 100 (its defaults otherwise), a process each: "
        "the peak anonymous memory (RssAnon) in each phase, then the peak RSS with "
        "the memory-mapped result files; the ``_x3`` and ``_x5`` scans are the 10 M "
        "point street three and five times end to end (the same tiles).",
    ),
    "startup": Table(
        "startup.json",
        _startup,
        "A command in a fresh process, interpreter start and imports included, "
        'against python -c "import sklearn.ensemble" measured in the same '
        "rounds: --version, segment --help, and segment and identify on the 30,000 "
        "points of a real KITTI sweep nearest the sensor (median of the rounds).",
    ),
    "review": Table(
        "review.json",
        _review,
        "The review page (skpcd review) of simulated street segments, predicted "
        "by the shipped model, opened from file:// in a fresh headless Chromium "
        "each load: first contentful paint.",
    ),
    "sweeps": Table(
        "sweeps.json",
        _sweeps,
        "Single real sweeps, warm, in one process, best of three runs (mean over "
        "the sweeps): the segmentation in the range image (one thread), the 3-D "
        "path of segment_scene (one thread and all) and Open3D (its plane and "
        "cluster_dbscan on the rest with the 3-D path's eps, its threads; its "
        "cluster_dbscan alone on every point); x: Open3D's time over the "
        "method's; quality beside the times.",
    ),
    "sweeps_streamed": Table(
        "sweeps.json",
        _sweeps_streamed,
        "Whole identification of a sweep, streamed with the model loaded once: "
        "each stage (segment, classify every segment with the shipped model, "
        "write the labelled LAZ), and the stage that keeps it from the sensor's "
        "10 sweeps a second; then skpcd identify over a folder of the sweeps, "
        "seconds of each sweep after the first (start-up and model loading "
        "excluded).",
    ),
    "sim_to_real": Table(
        "sim_to_real.json",
        _sim_to_real,
        "Trained on simulated objects only, scored on the real car-mounted sweeps.",
    ),
    "scene_labels": Table(
        "scene_labels.json",
        _scene_labels,
        "Whole real scans labelled point by point, through skpcd identify: IoU per "
        "class and its mean over the classes the source has (blank: not scored "
        "there), pooled over the scored scans; the mIoU with building, fence, pole, "
        "sign and other structures as one class, manmade, as nuScenes labels them; "
        "the median wall time of one identify process (indicative: a shared 2-core "
        "machine).",
    ),
}


def table(key, results=RESULTS):
    """``(header, rows, provenance)`` of the table ``key`` from the result files."""
    spec = TABLES[key]
    data = _Reader(load(spec.source, results), spec.source)
    return spec.read(data)


def render(key, results=RESULTS):
    """The table ``key`` as reStructuredText lines: caption, source and a list-table."""
    spec = TABLES[key]
    header, rows, where = table(key, results)
    lines = [
        spec.caption,
        "",
        f"From ``benchmarks/results/{spec.source}``; commit: {where['commit']}; "
        f"machine: {where['machine']}; date: {where['date']}.",
        "",
        ".. list-table::",
        "   :header-rows: 1",
        "",
    ]
    for row in [header, *rows]:
        for i, cell in enumerate(row):
            text = str(cell).replace("*", r"\*") or " "
            lines.append(f"   {'*' if i == 0 else ' '} - {text}")
    return lines


# ---------------------------------------------------------------------------
# Sphinx


def _directive():
    from docutils import nodes
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    class PerformanceTable(SphinxDirective):
        """``.. performance-table:: KEY``: the table KEY of ``TABLES``."""

        required_arguments = 1

        def run(self):
            key = self.arguments[0]
            if key not in TABLES:
                raise self.error(f"no performance table {key!r}; known: {list(TABLES)}")
            self.env.note_dependency(str(RESULTS / TABLES[key].source))
            container = nodes.container(classes=["performance-table"])
            self.state.nested_parse(
                StringList(render(key), source=f"benchmarks/results/{key}"),
                self.content_offset,
                container,
            )
            return [container]

    return PerformanceTable


def setup(app):
    """Register the ``performance-table`` directive (a Sphinx extension)."""
    app.add_directive("performance-table", _directive())
    return {"parallel_read_safe": True, "parallel_write_safe": True}
