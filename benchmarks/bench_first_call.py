"""The first call after an installation: cold and warm numba cache.

numba compiles skpcd's kernels on their first call and caches them on disk;
a new environment pays the compilation once. Every measurement here runs
in a fresh process with its own ``NUMBA_CACHE_DIR`` (cold: an empty one;
warm: the one a cold run just filled), timed from outside, interpreter
start and imports included, as a user waits for it:

* ``evaluate``: ``python -m skpcd evaluate``, the README's first command
  (the default pipeline cross-validated on ``make_urban_objects``);
* ``pfh`` and ``fpfh``: ``PFHTransformer(n_neighbors=10)`` and
  ``FPFHTransformer(n_neighbors=10)`` on one cloud of 500 points
  (``make_point_clouds``), the whole process and the call alone.

Best of ``--repeat`` runs each (a new empty cache for every cold run).
With ``--before PATH`` (a checkout of an older commit, e.g. made with
``git worktree add /tmp/before COMMIT``) the same runs are made with
``PYTHONPATH=PATH``, and the table compares the two. Python's bytecode of
both trees is compiled first (``compileall``), as ``pip install`` does.

Usage::

    python benchmarks/bench_first_call.py --before /tmp/before \\
        --out benchmarks/results/first_call.json
"""

import argparse
import compileall
import datetime
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from measure import write_results

ROOT = Path(__file__).resolve().parents[1]

_DESCRIPTOR = """
import time
t0 = time.perf_counter()
from skpcd.datasets import make_point_clouds
from skpcd.features import {name}
clouds = make_point_clouds(1, n_points=500, random_state=0)
t1 = time.perf_counter()
{name}(n_neighbors=10).fit_transform(clouds)
print("CALL", time.perf_counter() - t1, "IMPORT", t1 - t0)
"""

CASES = {
    "evaluate": ["-m", "skpcd", "evaluate"],
    "pfh": ["-c", _DESCRIPTOR.format(name="PFHTransformer")],
    "fpfh": ["-c", _DESCRIPTOR.format(name="FPFHTransformer")],
}


def _commit(tree):
    def git(*a):
        out = subprocess.run(
            ["git", "-C", str(tree), *a], capture_output=True, text=True, check=False
        )
        return out.stdout.strip()

    dirty = " (with uncommitted changes)" if git("status", "--porcelain") else ""
    return git("rev-parse", "--short", "HEAD") + dirty


def run_once(tree, case, cache_dir):
    """Wall seconds of one run, the call's own seconds, and what it said."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.pop("SKPCD_QUIET_COMPILE", None)
    env.update(NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(tree))
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, *CASES[case]],
        cwd=tempfile.gettempdir(),  # not the tree: PYTHONPATH decides
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    wall = time.perf_counter() - t0
    call = re.search(r"CALL (\S+)", done.stdout)
    said = re.search(r"kernels compiled in (\S+) s", done.stderr)
    return {
        "wall_s": wall,
        "call_s": float(call.group(1)) if call else None,
        "compile_s_said": float(said.group(1)) if said else None,
        "said_compiling": "compiling numba kernels" in done.stderr,
        "load_before": load,
    }


def measure(tree, repeat):
    """Cold and warm runs of every case, best of ``repeat`` (by wall time)."""
    compileall.compile_dir(str(Path(tree) / "skpcd"), quiet=1)
    rows = {}
    with tempfile.TemporaryDirectory(prefix="first_call_") as tmp:
        for case in CASES:
            cold, warm = [], []
            for r in range(repeat):
                cache = Path(tmp) / f"{case}{r}"
                cold.append(run_once(tree, case, cache))
                warm.append(run_once(tree, case, cache))
            rows[case] = {
                "cold": min(cold, key=lambda x: x["wall_s"]),
                "warm": min(warm, key=lambda x: x["wall_s"]),
                "cold_runs_s": [x["wall_s"] for x in cold],
                "warm_runs_s": [x["wall_s"] for x in warm],
            }
    return rows


def _fmt(x):
    return "-" if x is None else f"{x:.1f}"


def report(results):
    trees = list(results["trees"])
    lines = [
        "skpcd first call, cold and warm numba cache (benchmarks/bench_first_call.py)",
        f"{results['date']}, load average {results['load_start']:.2f} at the start "
        f"and {results['load_end']:.2f} at the end; best of {results['repeat']}; "
        "seconds of wall clock, a fresh process each (imports included)",
    ]
    for name in trees:
        lines.append(f"{name}: {results['trees'][name]['commit']}")
    lines.append("")
    head = f"{'case':<16}" + "".join(f"{t + ' s':>12}" for t in trees)
    if len(trees) == 2:
        head += f"{'speedup':>9}"
    lines.append(head)
    for case in CASES:
        for state in ("cold", "warm"):
            vals = [results["trees"][t]["rows"][case][state]["wall_s"] for t in trees]
            line = f"{case + ' ' + state:<16}" + "".join(f"{v:>12.1f}" for v in vals)
            if len(vals) == 2:
                line += f"{vals[0] / vals[1]:>8.2f}x"
            lines.append(line)
    lines.append("")
    lines.append("the descriptor call alone (no import), and compilation as announced")
    for name in trees:
        rows = results["trees"][name]["rows"]
        for case in ("pfh", "fpfh"):
            c, w = rows[case]["cold"], rows[case]["warm"]
            lines.append(
                f"{name:<8}{case:<6} call cold {_fmt(c['call_s'])} s, warm "
                f"{w['call_s']:.2f} s"
            )
        said = [
            f"{case} {_fmt(rows[case]['cold']['compile_s_said'])} s" for case in CASES
        ]
        lines.append(f"{name:<8}'kernels compiled in' (cold): " + ", ".join(said))
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", help="an older checkout to compare with")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", help="JSON results (and the table beside, .txt)")
    args = parser.parse_args()
    trees = {}
    if args.before:
        trees["before"] = Path(args.before).resolve()
    trees["after" if args.before else "this"] = ROOT
    results = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(
            timespec="seconds"
        ),
        "machine": f"{os.cpu_count()} CPUs, {sys.platform}",
        "repeat": args.repeat,
        "load_start": os.getloadavg()[0],
        "trees": {},
    }
    for name, tree in trees.items():
        results["trees"][name] = {
            "path": str(tree),
            "commit": _commit(tree),
            "rows": measure(tree, args.repeat),
        }
    results["load_end"] = os.getloadavg()[0]
    text = report(results)
    print(text, end="")
    if args.out:
        write_results(args.out, results, text)


if __name__ == "__main__":
    main()
