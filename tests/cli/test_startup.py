"""Start-up of the command line: ``skpcd --version`` and every ``--help``
load neither scikit-learn nor numba (the parser is built from the CLI's own
modules), and the choices the parser writes out are the library's."""

import json
import subprocess
import sys

import pytest

from skpcd.cli import _evaluate, _segment

# Runs the command as ``python -m skpcd`` does (its exit status kept), then
# prints on stderr the top-level packages it loaded.
_LOADED = """
import json, runpy, sys
sys.argv = ["skpcd", *sys.argv[1:]]
try:
    runpy.run_module("skpcd", run_name="__main__", alter_sys=True)
finally:
    top = sorted({name.split(".")[0] for name in sys.modules})
    print("LOADED " + json.dumps(top), file=sys.stderr)
"""

HEAVY = ("sklearn", "numba", "scipy", "pandas", "joblib", "laspy")

COMMANDS = ("info", "evaluate", "score", "fit", "predict", "describe", "segment")


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
    from skpcd.segmentation.ground import GROUND_PRESETS

    assert set(_segment.GROUND_CHOICES) == {"auto", *GROUND_PRESETS, "none"}
    assert _segment.GROUND_CHOICES[0] == "auto"


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
