"""What the benchmark scripts share: where and when a run happened (commit,
machine, load), the best time of a few runs, and how much memory a call took at
its peak (Linux).

Each script records :func:`commit` and :func:`machine` in its results file, so
that the Performance page can say where each figure came from.
"""

import datetime
import gc
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

__all__ = [
    "best_of",
    "commit",
    "cpu_model",
    "import_open3d",
    "loadavg",
    "machine",
    "maxrss_mb",
    "provenance",
    "reset_peak",
    "rss_now_mb",
    "write_results",
]


def _git(*args):
    """The output of a git command run in this checkout."""
    return subprocess.run(
        ["git", *args], capture_output=True, text=True, cwd=HERE, check=True
    ).stdout.strip()


def commit():
    """The checkout's short commit, marked when it has uncommitted changes."""
    try:
        out = _git("rev-parse", "--short", "HEAD")
        dirty = _git("status", "--porcelain", "--untracked-files=no")
        return out + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def cpu_model():
    """The CPU's model name (``/proc/cpuinfo``), or what ``platform`` says."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine():
    """The CPU, its cores and the system, in one line."""
    return (
        f"{cpu_model()}, {os.cpu_count()} cores, "
        f"{platform.system()} {platform.release()}"
    )


def loadavg():
    """The 1, 5 and 15 minute load averages."""
    with open("/proc/loadavg") as f:
        return [float(x) for x in f.read().split()[:3]]


def import_open3d():
    """Import Open3D; its plotly viewer imports ``dash`` at import time.

    When dash is not installed (installing it also installs a pytest plugin
    that breaks pytest in the same environment), a stub module stands in for
    it: the benchmark never opens a viewer.
    """
    try:
        import dash  # noqa: F401
    except ImportError:
        import types

        stub = types.ModuleType("dash")
        stub.html = stub.dcc = types.ModuleType("dash.stub")
        stub.Dash = object
        sys.modules.setdefault("dash", stub)
    import open3d

    return open3d


def maxrss_mb():
    """Peak RSS in MB since the last :func:`reset_peak`.

    VmHWM, which clear_refs resets; ``ru_maxrss`` keeps the peak of the
    whole process (data loading included) and would overstate the call's.
    """
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def rss_now_mb():
    """The current RSS in MB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def reset_peak():
    """Reset the peak RSS to the current RSS; returns the current RSS in MB.

    Imports (LLVM) and data loading have transient peaks that would hide the
    peak of the measured call; writing 5 to /proc/self/clear_refs resets the
    high-water mark that ru_maxrss reports (Linux >= 4.0).
    """
    gc.collect()
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
    return rss_now_mb()


def provenance():
    """``{"commit", "machine", "date"}`` of a run, for the top of a results
    file (the Performance page reads them there)."""
    return {
        "commit": commit(),
        "machine": machine(),
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
    }


def best_of(repeat, func):
    """``(result, seconds)``: the last result and the fastest of ``repeat`` runs."""
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = func()
        best = min(best, time.perf_counter() - t)
    return out, best


def write_results(out, results, text):
    """Write ``results`` as JSON to ``out`` and ``text`` beside it (``.txt``),
    each through a temporary file renamed when whole, so that an interrupted
    run leaves the previous results, not half a file."""
    import json

    out = Path(out)
    for path, content in (
        (out, json.dumps(results, indent=1) + "\n"),
        (out.with_suffix(".txt"), text),
    ):
        tmp = path.with_name(f".{path.name}.part")
        tmp.write_text(content)
        os.replace(tmp, path)
