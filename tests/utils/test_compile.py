"""The one line on stderr when kernels compile (skpcd.utils._compile)."""

import os
import subprocess
import sys
import textwrap

import pytest
from numba.core import event

from skpcd.features._vertical_kernels import geometric_median
from skpcd.utils import _compile
from skpcd.utils._compile import QUIET_ENV, compile_notice, entry_point

START = "skpcd: compiling numba kernels for"
END = "skpcd: kernels compiled in"


def _compile_event(dispatcher=geometric_median):
    """What numba broadcasts around a compilation (a cache miss)."""
    data = {"dispatcher": dispatcher, "args": (), "return_type": None}
    event.start_event("numba:compile", data=data)
    event.start_event("numba:compile", data=data)  # a callee, nested
    event.end_event("numba:compile", data=data)
    event.end_event("numba:compile", data=data)


@pytest.fixture(autouse=True)
def fresh_process(monkeypatch):
    """As in a new process: no compilation outside entry points said yet."""
    monkeypatch.setattr(_compile._LISTENER, "_lone", None)


@pytest.fixture
def loud(monkeypatch):
    monkeypatch.delenv(QUIET_ENV, raising=False)


def test_one_message_per_call_that_compiles(capsys, loud):
    with compile_notice("PFHTransformer"):
        _compile_event()
        _compile_event()
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2
    assert err[0] == (
        f"{START} PFHTransformer (first use in this environment; cached afterwards)..."
    )
    assert err[1].startswith(END) and err[1].endswith(" s")


def test_nothing_compiled_nothing_said(capsys, loud):
    with compile_notice("PFHTransformer"):
        pass
    assert capsys.readouterr().err == ""


def test_nested_entry_points_share_the_outermost_message(capsys, loud):
    class Inner:
        @entry_point
        def transform(self):
            _compile_event()

    with compile_notice("skpcd evaluate"):
        Inner().transform()
        Inner().transform()
    err = capsys.readouterr().err
    assert err.count(START) == 1 and err.count(END) == 1
    assert f"{START} skpcd evaluate " in err
    Inner().transform()  # on its own: named after the class
    assert f"{START} Inner " in capsys.readouterr().err


def test_other_libraries_kernels_are_not_announced(capsys, loud):
    class Foreign:
        py_func = len  # a builtin: module "builtins"

    with compile_notice("PFHTransformer"):
        _compile_event(Foreign())
    assert capsys.readouterr().err == ""


def test_compilation_outside_entry_points(capsys, loud):
    _compile_event()
    _compile_event()
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "skpcd: compiling numba kernels (first use in this environment; cached "
        "afterwards)..."
    ]


def test_silenced(capsys, monkeypatch):
    with compile_notice("PFHTransformer", quiet=True):
        _compile_event()
    monkeypatch.setenv(QUIET_ENV, "1")
    with compile_notice("PFHTransformer"):
        _compile_event()
    _compile_event()
    assert capsys.readouterr().err == ""


_CALL = textwrap.dedent(
    """
    from skpcd.datasets import make_urban_objects
    from skpcd.features import VerticalProfile

    clouds, _ = make_urban_objects(n_per_class=1, random_state=0)
    VerticalProfile().fit_transform(clouds)
    VerticalProfile().fit_transform(clouds)
    """
)


def _run(cache_dir, **extra):
    """stderr of the call in a new process, numba's cache in ``cache_dir``."""
    env = {k: v for k, v in os.environ.items() if k != QUIET_ENV}
    env.update(NUMBA_CACHE_DIR=str(cache_dir), **extra)
    done = subprocess.run(
        [sys.executable, "-c", _CALL],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return done.stderr


def test_cold_cache_says_it_once_warm_cache_says_nothing(tmp_path):
    cold = _run(tmp_path / "cache")
    assert cold.count(START) == 1, cold
    assert f"{START} VerticalProfile " in cold
    assert cold.count(END) == 1, cold
    warm = _run(tmp_path / "cache")
    assert START not in warm and END not in warm, warm
    quiet = _run(tmp_path / "other", **{QUIET_ENV: "1"})
    assert START not in quiet and END not in quiet, quiet


@pytest.mark.parametrize("quiet", [False, True])
def test_command_line_says_it_once_unless_quiet(capsys, loud, quiet):
    from argparse import Namespace

    from skpcd.cli._process import run

    def command(args):
        _compile_event()
        _compile_event()
        return 0

    assert run("evaluate", command, Namespace(quiet=quiet)) == 0
    err = capsys.readouterr().err
    assert err.count(f"{START} skpcd evaluate ") == (0 if quiet else 1)
    assert err.count(END) == (0 if quiet else 1)
