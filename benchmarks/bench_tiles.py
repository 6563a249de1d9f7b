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

With ``--memory SCAN [SCAN ...]``, the memory of the whole tiled job
``skpcd segment SCAN -o FOLDER --tile-size 100`` (its defaults otherwise),
each scan in a fresh process: the anonymous memory (``RssAnon``: what
cannot be dropped; the memory-mapped result arrays and the page cache are
not in it) sampled every 20 ms, its peak in each phase of the job (the
scan's kind told from a sample, the spill of the scan to tile files, the
ground, the eps estimate, the tiles' segmentation, the stitching of their
segments, the writing of the segment files), and the peak RSS of the
process (``VmHWM``, mapped files included). ``--streets SCAN`` first
writes, beside SCAN, copies of it end to end along x (300 m apart: every
100 m tile of a copy holds the same points as in the first), so that the
memory at a fixed tile content can be read against the scan's size::

    python benchmarks/bench_tiles.py --memory scan_10M.las scan_25M.las \
        scan_50M.las --streets scan_10M.las --out benchmarks/results/tiles_memory.json

(the scans of ``bench_throughput.make_scans``; the SCAN of ``--streets``
must span less than 200 m along x). Results:
``benchmarks/results/tiles_memory.{json,txt}``.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import numpy as np
from measure import provenance, write_results
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


# --- the memory of a tiled job, phase by phase -----------------------------

# The compute step of each pass of the tiled path, and the phase it is in.
PHASES = {
    "_ground_tile": "ground",
    "_cloth_tile": "ground",
    "_bases_tile": "ground",
    "_eps_tile": "eps",
    "_far_tile": "eps",
    "_cluster_tile": "tiles",
    "_structures_tile": "tiles",
}
ORDER = ("kind", "spill", "ground", "eps", "tiles", "stitch", "write")
MEMORY_TILE = 100.0


def _status():
    """RssAnon, RssFile and VmHWM of this process, in MiB."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("RssAnon", "RssFile", "VmHWM"):
                out[key] = int(value.split()[0]) / 1024
    return out


class PhaseSampler:
    """The peak RssAnon and RssFile of each phase, sampled in a thread."""

    def __init__(self):
        self.phase = "start"
        self.peaks = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def sample(self):
        s = _status()
        peak = self.peaks.setdefault(self.phase, {"anon_mib": 0.0, "file_mib": 0.0})
        peak["anon_mib"] = max(peak["anon_mib"], s["RssAnon"])
        peak["file_mib"] = max(peak["file_mib"], s["RssFile"])

    def enter(self, phase):
        self.sample()
        self.phase = phase
        self.sample()

    def _loop(self):
        while not self._stop.wait(0.02):
            self.sample()

    def start(self):
        self._thread.start()

    def stop(self):
        self._stop.set()
        self._thread.join()
        self.sample()


def _watch_phases(sampler, facts):
    """Patch the tiled path so that ``sampler`` knows the phase it is in;
    ``facts`` gets the tiles' sizes."""
    import skpcd.segmentation as segmentation
    import skpcd.segmentation.tiling._segment as seg

    tile_scene, csf, stitch, map_tiles = (
        seg.tile_scene, seg._csf_tiled, seg._stitch, seg.map_tiles
    )  # fmt: skip
    segment_scene = segmentation.segment_scene

    def spill(*args, **kwargs):
        sampler.enter("spill")
        scene = tile_scene(*args, **kwargs)
        facts["n_points"] = int(scene.n_points)
        facts["n_tiles"] = int((scene.owned_counts() > 0).sum())
        facts["largest_tile"] = int(scene.counts.max())
        return scene

    def cloth(*args, **kwargs):
        sampler.enter("ground")
        return csf(*args, **kwargs)

    def mapped(scene, tiles, prepare, pargs, compute, *args, **kwargs):
        def run():
            sampler.enter(PHASES[compute.__name__])
            yield from map_tiles(scene, tiles, prepare, pargs, compute, *args, **kwargs)

        return run()

    def stitched(tiled, *args, **kwargs):
        def run():
            yield from tiled
            sampler.enter("stitch")

        return stitch(run(), *args, **kwargs)

    def scene(*args, **kwargs):
        sampler.enter("kind")
        result = segment_scene(*args, **kwargs)
        sampler.enter("write")
        return result

    seg.tile_scene, seg._csf_tiled, seg._stitch, seg.map_tiles = (
        spill, cloth, stitched, mapped
    )  # fmt: skip
    segmentation.segment_scene = scene


def memory_worker(spec):
    """One scan's job in this process, the phases watched; prints a JSON row."""
    from skpcd.cli import main as cli

    sampler, facts = PhaseSampler(), {}
    _watch_phases(sampler, facts)
    base = _status()
    sampler.start()
    with tempfile.TemporaryDirectory(dir=spec["temp"]) as out:
        rc = cli(
            ["segment", spec["scan"], "-o", out, "--tile-size", str(spec["tile"])]
            + spec["options"]
        )
    sampler.stop()
    phases = {p: sampler.peaks[p] for p in ORDER if p in sampler.peaks}
    row = {
        "scan": Path(spec["scan"]).name,
        "rc": rc,
        **facts,
        "base_anon_mib": base["RssAnon"],
        "peak_anon_mib": max(p["anon_mib"] for p in phases.values()),
        "vmhwm_mib": _status()["VmHWM"],
        "phases": phases,
    }
    print(json.dumps(row))


def straight_street(scan, copies):
    """``scan`` and ``copies - 1`` copies of it end to end along x, 300 m
    apart, written beside it (LAS, chunk by chunk; kept when there)."""
    import laspy

    path = Path(scan).with_name(f"{Path(scan).stem}_x{copies}.las")
    if path.exists():
        return path
    with laspy.open(scan) as reader:
        header = reader.header
        shift = round(300.0 / header.scales[0])
        if header.maxs[0] - header.mins[0] >= 200.0:
            sys.exit(f"{scan} spans 200 m or more along x: its tiles would differ")
        out = laspy.LasHeader(point_format=header.point_format, version=header.version)
        out.scales, out.offsets = header.scales, header.offsets
    part = path.with_name(f".{path.name}.part")
    with laspy.open(part, mode="w", header=out) as writer:
        for copy in range(copies):
            with laspy.open(scan) as reader:
                for points in reader.chunk_iterator(2_000_000):
                    points.X = points.X + copy * shift
                    writer.write_points(points)
    os.replace(part, path)
    return path


def memory_text(results):
    """The text summary of the memory runs."""
    job = f"skpcd segment --tile-size {results['tile_size']:g} {results['options']}"
    lines = [
        job.strip() + ": memory by phase (benchmarks/bench_tiles.py --memory)",
        f"  {results['date']}, commit {results['commit']}, {results['machine']}",
        "  RssAnon peak per phase, MiB (a fresh process each, imports "
        f"{results['runs'][0]['base_anon_mib']:.0f} MiB); VmHWM: peak RSS, mapped "
        "result files included",
        "",
        f"{'scan':22} {'points':>10} {'tiles':>5} {'largest':>9}  "
        + " ".join(f"{p:>7}" for p in ORDER)
        + f"  {'peak':>7} {'VmHWM':>7}",
    ]
    for r in results["runs"]:
        lines.append(
            f"{r['scan']:22} {r['n_points']:>10} {r['n_tiles']:>5} "
            f"{r['largest_tile']:>9}  "
            + " ".join(
                f"{r['phases'][p]['anon_mib']:>7.0f}" if p in r["phases"] else " " * 7
                for p in ORDER
            )
            + f"  {r['peak_anon_mib']:>7.0f} {r['vmhwm_mib']:>7.0f}"
        )
    lines += [
        "",
        "largest: points of the largest buffered tile; *_xK: the first scan's "
        "street K times end to end (the same tiles, K times)",
    ]
    return "\n".join(lines) + "\n"


def memory_main(args):
    scans = [Path(s) for s in args.memory]
    if args.streets:
        scans += [straight_street(args.streets, k) for k in (3, 5)]
    results = {
        **provenance(),
        "tile_size": args.tile_size,
        "options": args.options,
        "runs": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for scan in scans:
            spec = {"scan": str(scan), "tile": args.tile_size, "temp": tmp}
            spec["options"] = args.options.split()
            run = subprocess.run(
                [sys.executable, __file__, "--memory-worker", json.dumps(spec)],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            row = json.loads(run.stdout.strip().splitlines()[-1])
            results["runs"].append(row)
            print(json.dumps(row), flush=True)
    write_results(args.out, results, memory_text(results))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tile-size", type=float, default=None)
    parser.add_argument("--eps", type=float, default=0.5)
    parser.add_argument("--out", type=Path, default=Path("/tmp/tiles.json"))
    parser.add_argument(
        "--memory", nargs="+", metavar="SCAN", help="the memory of tiled jobs"
    )
    parser.add_argument(
        "--streets", metavar="SCAN", help="with --memory: copies of SCAN end to end"
    )
    parser.add_argument(
        "--options", default="", help="with --memory: more options of skpcd segment"
    )
    parser.add_argument("--memory-worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.memory_worker:
        memory_worker(json.loads(args.memory_worker))
        return
    if args.memory:
        args.tile_size = args.tile_size or MEMORY_TILE
        memory_main(args)
        return
    args.tile_size = args.tile_size or 30.0
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
