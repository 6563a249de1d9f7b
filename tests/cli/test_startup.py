"""Start-up of the command line: ``skpcd --version`` and every ``--help``
load neither scikit-learn nor numba (the parser is built from the CLI's own
modules), the choices the parser writes out are the library's, and a first
run says which stages it compiled, compiling only those it runs."""

import importlib.util
import json
import os
import re
import subprocess
import sys
import types
from argparse import Namespace

import numpy as np
import pytest
from numba.core import event

from skpcd.cli import _evaluate, _segment, _segmentation_options
from skpcd.cli._process import run
from skpcd.utils._compile import QUIET_ENV, STAGES

# Runs the command in this process (its exit status kept; ``python -m
# skpcd`` would run the work in a child process), then prints on stderr the
# top-level packages it loaded.
_LOADED = """
import json, sys
from skpcd.cli import main
try:
    sys.exit(main(sys.argv[1:]))
finally:
    top = sorted({name.split(".")[0] for name in sys.modules})
    print("LOADED " + json.dumps(top), file=sys.stderr)
"""

HEAVY = ("sklearn", "numba", "scipy", "pandas", "joblib", "laspy", "tqdm")

COMMANDS = (
    "info",
    "evaluate",
    "score",
    "fit",
    "predict",
    "describe",
    "segment",
    "simulate",
)


def _loaded(*args):
    done = subprocess.run(
        [sys.executable, "-c", _LOADED, *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    (line,) = [s for s in done.stderr.splitlines() if s.startswith("LOADED ")]
    return done, set(json.loads(line.removeprefix("LOADED ")))


@pytest.mark.parametrize(
    "args",
    [["--version"], ["--help"], *([c, "--help"] for c in (*COMMANDS, "identify"))],
    ids=lambda a: " ".join(a),
)
def test_version_and_help_load_no_heavy_library(args):
    done, loaded = _loaded(*args)
    assert done.returncode == 0, done.stderr
    assert "skpcd" in done.stdout
    assert sorted(loaded & set(HEAVY)) == []


def test_the_check_sees_a_heavy_import():
    # a command that runs loads the library: the check above is not vacuous
    done, loaded = _loaded("score", "no-such-model.skpcd", "no-such-folder")
    assert done.returncode != 0
    assert "numba" in loaded


def test_ground_choices_are_the_presets():
    from skpcd.segmentation.ground import FROM_FILE, GROUND_PRESETS

    choices = _segmentation_options.GROUND_CHOICES
    assert set(choices) == {"auto", *GROUND_PRESETS, FROM_FILE, "none"}
    assert choices[0] == "auto"


def test_segment_formats_are_the_library_s():
    from skpcd.io._segment_folder import SEGMENT_FORMATS

    assert _segment.SEGMENT_FORMATS == SEGMENT_FORMATS


def test_pipelines_are_the_library_s():
    from skpcd.classification import PIPELINES

    assert _evaluate.PIPELINES == PIPELINES


def test_scanner_choices_are_simulation_augmented_s():
    from skpcd.classification import SimulationAugmented
    from skpcd.cli import build_parser

    fit = build_parser()._subparsers._group_actions[0].choices["fit"]
    (scanner,) = [a for a in fit._actions if a.dest == "scanner"]
    (options,) = SimulationAugmented._parameter_constraints["scanner"]
    assert set(scanner.choices) == options.options


# --- the first run: what compiles ---------------------------------------

START = "skpcd: compiling numba kernels for skpcd segment (first use"
END = "skpcd: kernels compiled in "


def _stages(err):
    """The stages named by the closing line of ``err`` (stderr), in order."""
    (line,) = [line for line in err.splitlines() if line.startswith(END)]
    assert re.fullmatch(END + r"[0-9.]+ s: .+ [0-9.]+ s", line), line
    return re.findall(r"([^,]+?) [0-9.]+ s(?:, |$)", line.partition(" s: ")[2])


def _kernel(module):
    """A stand-in for a numba dispatcher of a kernel defined in ``module``."""

    def kernel():
        pass

    kernel.__module__ = module
    return types.SimpleNamespace(py_func=kernel)


def _compiles(dispatcher):
    """What numba broadcasts around a compilation (a cache miss)."""
    data = {"dispatcher": dispatcher, "args": (), "return_type": None}
    event.start_event("numba:compile", data=data)
    event.start_event("numba:compile", data=data)  # a callee, nested
    event.end_event("numba:compile", data=data)
    event.end_event("numba:compile", data=data)


@pytest.fixture
def loud(monkeypatch):
    monkeypatch.delenv(QUIET_ENV, raising=False)


def test_the_closing_line_names_the_stages_compiled(capsys, loud):
    grid = _kernel("skpcd.neighbors._grid_kernels")

    def command(args):
        _compiles(grid)
        _compiles(_kernel("skpcd.segmentation._cluster_kernels"))
        _compiles(grid)
        _compiles(_kernel("skpcd.segmentation.tiling._octree_kernels"))
        return 0

    assert run("segment", command, Namespace(quiet=False)) == 0
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 2 and err.startswith(START)
    assert _stages(err) == ["neighbour search", "clustering", "octree"]


def test_every_stage_named_is_a_module():
    for module in STAGES:
        assert importlib.util.find_spec(module) is not None, module


@pytest.mark.slow
def test_a_first_run_compiles_only_the_stages_it_runs(tmp_path):
    # no ground filter, no structures: neither their kernels nor those of
    # the descriptors, the classifier or the simulator may compile
    rng = np.random.default_rng(0)
    blobs = [rng.normal(c, 0.2, (300, 3)) for c in ([0, 0, 1], [5, 0, 1], [0, 5, 1])]
    scene = tmp_path / "scene.xyz"
    np.savetxt(scene, np.vstack(blobs))
    env = {k: v for k, v in os.environ.items() if k != QUIET_ENV}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    args = ["segment", str(scene), "-o", str(tmp_path / "out"), "--ground", "none"]
    args += ["--no-structures", "--method", "euclidean", "--eps", "0.5"]
    done = subprocess.run(
        [sys.executable, "-m", "skpcd", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    assert done.stderr.count(START) == 1, done.stderr
    stages = set(_stages(done.stderr))
    assert "clustering" in stages
    ran_not = {"structures", "PFH/FPFH", "improved PFH", "normals", "street simulator"}
    assert not stages & ran_not
    assert not any(s.startswith("ground") for s in stages)


@pytest.mark.parametrize(
    "env, want", [(None, "False"), ("1", "True")], ids=["default", "user's choice"]
)
def test_commands_run_on_small_pages_unless_the_user_says(tmp_path, env, want):
    """A command turns off numpy's transparent huge pages (each new large
    array zeroed 2 MB at a time), unless NUMPY_MADVISE_HUGEPAGE is set."""
    pytest.importorskip("numpy._core.multiarray")
    environ = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if env is not None:
        environ["NUMPY_MADVISE_HUGEPAGE"] = env
    # a command, then numpy's huge-page flag (returned as it was when set)
    code = (
        "from numpy._core.multiarray import _set_madvise_hugepage as flag\n"
        "from skpcd.cli import main\n"
        f"main(['simulate', '-o', {str(tmp_path / 'sim')!r}, '--quiet'])\n"
        "print(flag(False))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=environ,
        timeout=300, check=True,
    )  # fmt: skip
    assert done.stdout.strip().splitlines()[-1] == want
