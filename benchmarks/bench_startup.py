"""Start-up of the command line: ``skpcd`` commands against importing
scikit-learn, and the first run after an installation.

Issue 28 asks that a command on a 30 k point scan take at most 2.5 times as
long as ``python -c "import sklearn.ensemble"`` on the same machine, that
``skpcd --version`` and ``--help`` load neither scikit-learn nor numba, and
that the first run say what it compiles and compile only what it runs.
Every figure here is a fresh process timed from outside, interpreter start
and imports included, as a user waits for it:

* ``sklearn``: ``python -c "import sklearn.ensemble"``, the yardstick;
* ``version``, ``help``: ``python -m skpcd --version`` and ``python -m
  skpcd segment --help``, with the heavy packages they import (``-X
  importtime``);
* ``segment``, ``identify``: ``python -m skpcd segment SCAN -o FOLDER`` and
  ``python -m skpcd identify SCAN -o OUT.las`` (the shipped street model)
  with their defaults and ``--quiet``, numba's cache warm;
* ``segment cold``: ``skpcd segment`` (without ``--quiet``) with an empty
  ``NUMBA_CACHE_DIR``, what it says on stderr about compiling and how many
  kernels it compiled (numba's index files written).

SCAN is a real sweep (KITTI, Velodyne HDL-64E) cut to the 30 000 points
nearest the sensor. The warm cases run in rounds, each round every case of
every tree in turn, so that the ratio to ``sklearn`` of each round is
measured at one load of the machine; the table gives the median over the
rounds of CPU seconds (user + system, the children's rusage), wall seconds
and those ratios. With ``--before COMMIT`` the same runs are made on that
commit (``git archive`` into a temporary folder, ``PYTHONPATH``), and with
``--after COMMIT`` the other side too, each tree with its own numba cache,
warmed first.

Usage::

    python benchmarks/bench_startup.py --before 8786a4e --after HEAD \\
        --out benchmarks/results/startup.json

The machine is a shared 2-core VM: the load average at the start and the
end is recorded; ratios measured in one round are what to quote.
"""

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from measure import loadavg, provenance, write_results  # noqa: E402

SCANS = Path(
    os.environ.get("SKPCD_REAL_MOBILE", HERE.parents[1] / "shared/data/real_mobile")
)
SWEEP = SCANS / "scans" / "kitti_object_000000.las"
N_POINTS = 30_000
HEAVY = ("sklearn", "numba", "scipy", "pandas", "joblib", "laspy")
WARM = ("sklearn", "version", "help", "segment", "identify")


def cut_scan(sweep, n_points, out):
    """The ``n_points`` points of ``sweep`` nearest the sensor (in x, y),
    in file order, written to ``out`` with every dimension."""
    import laspy
    import numpy as np

    las = laspy.read(sweep)
    distance = np.hypot(las.x, las.y)
    keep = np.sort(np.argsort(distance, kind="stable")[:n_points])
    cut = laspy.LasData(las.header)
    cut.points = las.points[keep]
    cut.write(out)
    return out


def commands(scan, work):
    """The command line of each case, after ``python``."""
    quiet = ("--overwrite", "--quiet")
    return {
        "sklearn": ["-c", "import sklearn.ensemble"],
        "version": ["-m", "skpcd", "--version"],
        "help": ["-m", "skpcd", "segment", "--help"],
        "segment": [
            "-m",
            "skpcd",
            "segment",
            str(scan),
            "-o",
            str(work / "seg"),
            *quiet,
        ],
        "identify": [
            "-m",
            "skpcd",
            "identify",
            str(scan),
            "-o",
            str(work / "id.las"),
            *quiet,
        ],
    }


def run_once(args, env, cwd):
    """Wall and CPU seconds of one run of ``python ARGS``, and its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, *args],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f"python {' '.join(args)} failed:\n{done.stderr}")
    return {"wall_s": wall, "cpu_s": cpu, "stderr": done.stderr}


def environment(tree, cache):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.pop("SKPCD_QUIET_COMPILE", None)
    env.update(PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache))
    return env


def heavy_imports(tree, args, cwd):
    """The heavy top-level packages ``python ARGS`` imports (-X importtime)."""
    done = run_once(["-X", "importtime", *args], environment(tree, cwd / "none"), cwd)
    names = re.findall(r"^import time:.*\|\s*([\w.]+)\s*$", done["stderr"], re.M)
    return sorted({n.split(".")[0] for n in names} & set(HEAVY))


def cold_run(tree, args, cache, cwd):
    """``python ARGS`` with an empty numba cache: time, what it said, and the
    kernels it compiled (index files written)."""
    done = run_once(args, environment(tree, cache), cwd)
    said = [line for line in done["stderr"].splitlines() if "kernels" in line]
    return {
        "wall_s": done["wall_s"],
        "cpu_s": done["cpu_s"],
        "said": said,
        "index_files": len(list(cache.rglob("*.nbi"))),
    }


def short(commit):
    """``commit`` (a name or hash) as a short hash."""
    return subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", commit],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def checkout(commit, folder):
    """The files of ``commit`` (``git archive``) in ``folder``."""
    folder.mkdir()
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", commit], capture_output=True, check=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def measure(trees, scan, rounds, work):
    cmds = commands(scan, work)
    caches = {name: work / f"cache-{name}" for name in trees}
    for name, tree in trees.items():  # numba's cache filled for the warm runs
        run_once(cmds["segment"], environment(tree, caches[name]), work)
        run_once(cmds["identify"], environment(tree, caches[name]), work)
    runs = {name: {case: [] for case in WARM} for name in trees}
    for _ in range(rounds):
        for name, tree in trees.items():
            for case in WARM:
                done = run_once(cmds[case], environment(tree, caches[name]), work)
                done.pop("stderr")
                runs[name][case].append(done)
    rows = {}
    for name, tree in trees.items():
        base = runs[name]["sklearn"]
        row = {}
        for case in WARM:
            mine = runs[name][case]
            row[case] = {
                "cpu_s": statistics.median(r["cpu_s"] for r in mine),
                "wall_s": statistics.median(r["wall_s"] for r in mine),
                "cpu_ratio": statistics.median(
                    r["cpu_s"] / b["cpu_s"] for r, b in zip(mine, base)
                ),
                "wall_ratio": statistics.median(
                    r["wall_s"] / b["wall_s"] for r, b in zip(mine, base)
                ),
                "runs": mine,
            }
        row["version"]["heavy_imports"] = heavy_imports(tree, cmds["version"], work)
        row["help"]["heavy_imports"] = heavy_imports(tree, cmds["help"], work)
        loud = [a for a in cmds["segment"] if a != "--quiet"]
        row["segment_cold"] = cold_run(tree, loud, work / f"cold-{name}", work)
        rows[name] = row
    return rows


def report(results):
    trees = list(results["trees"])
    lines = [
        "skpcd start-up: commands against `import sklearn.ensemble`, and the first "
        "run (benchmarks/bench_startup.py)",
        f"{results['date']} at {results['commit']}; {results['machine']}",
        f"load average {results['load_start']} at the start, {results['load_end']} "
        f"at the end; median of {results['rounds']} rounds, every case of every "
        "tree in each round; a fresh process each, imports included",
        f"scan: {results['scan']}",
    ]
    for name in trees:
        lines.append(f"{name}: {results['trees'][name]['commit']}")
    lines.append("")
    lines.append(
        f"{'case':<10}{'tree':<8}{'cpu s':>8}{'wall s':>8}{'cpu/sklearn':>13}"
        f"{'wall/sklearn':>14}  heavy imports"
    )
    for case in WARM:
        for name in trees:
            r = results["trees"][name]["rows"][case]
            heavy = r.get("heavy_imports")
            lines.append(
                f"{case:<10}{name:<8}{r['cpu_s']:>8.2f}{r['wall_s']:>8.2f}"
                f"{r['cpu_ratio']:>12.2f}x{r['wall_ratio']:>13.2f}x  "
                + ("" if heavy is None else ", ".join(heavy) or "none")
            )
    lines.append("")
    lines.append("first run, empty numba cache: skpcd segment on the scan")
    for name in trees:
        c = results["trees"][name]["rows"]["segment_cold"]
        lines.append(
            f"{name:<8}{c['cpu_s']:.1f} s cpu, {c['wall_s']:.1f} s wall, "
            f"{c['index_files']} kernels compiled (index files); it said:"
        )
        lines.extend(f"    {line}" for line in c["said"])
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", help="an older commit to compare with")
    parser.add_argument(
        "--after", help="the commit to measure (default: the checkout as it is)"
    )
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--sweep", default=str(SWEEP), help="the LAS sweep to cut")
    parser.add_argument("--out", help="JSON results (and the table beside, .txt)")
    args = parser.parse_args()
    commits = {
        name: short(commit)
        for name, commit in (("before", args.before), ("after", args.after))
        if commit
    }
    load_start = loadavg()
    with tempfile.TemporaryDirectory(prefix="startup_") as tmp:
        work = Path(tmp)
        scan = cut_scan(args.sweep, N_POINTS, work / "scan_30k.las")
        trees = {}
        if args.before:
            trees["before"] = checkout(commits["before"], work / "before")
        after = checkout(commits["after"], work / "after") if args.after else ROOT
        trees["after" if args.before else "this"] = after
        rows = measure(trees, scan, args.rounds, work)
    results = {
        **provenance(),
        "load_start": load_start,
        "load_end": loadavg(),
        "rounds": args.rounds,
        "scan": f"{Path(args.sweep).name}, the {N_POINTS} points nearest the sensor",
        "trees": {
            name: {
                "commit": commits.get(name) or provenance()["commit"],
                "rows": rows[name],
            }
            for name in rows
        },
    }
    text = report(results)
    print(text, end="")
    if args.out:
        write_results(args.out, results, text)


if __name__ == "__main__":
    main()
