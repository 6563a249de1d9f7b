"""Ctrl-C and SIGTERM end ``skpcd`` within about a second whatever it is
doing (importing, decoding a LAZ file, the C++ cloth simulation, writing
segments, swapping an output folder in): one line on stderr, status 130 /
143, nothing left behind, a previous run untouched.

Each moment is tried several times at random delays (a fault seen in 1 of
4 tries is caught with high probability by the slow variant, and often by
the quick one); the process is ``python -m skpcd`` itself, with one stage
made long by a wrapper, so that the signal lands inside it."""

import os
import random
import resource
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from skpcd.cli import main
from skpcd.io._atomic import PARTIAL_MARK
from tests.cli._started import start_until

REAL_SCAN = "/work/shared/data/real_mobile/scans/kitti_object_000000.las"
# longest time from the signal to the end of the command
WITHIN = 2.0

# The command as ``python -m skpcd`` runs it, one stage made long by a
# wrapper that first creates the file MARKER (argv: MARKER STAGE ARGS...).
_SCRIPT = textwrap.dedent(
    """
    import os, sys, time
    marker, stage, argv = sys.argv[1], sys.argv[2], sys.argv[3:]

    def mark():
        if not os.path.exists(marker):
            open(marker, "w").close()

    if stage == "csf":  # the C++ simulation, many times over: uninterruptible
        import CSF
        original = CSF.CSF.do_filtering

        def long_csf(self, *args, **kwargs):
            mark()
            for _ in range(200):
                original(self, *args, **kwargs)

        CSF.CSF.do_filtering = long_csf
    elif stage == "laz":  # a signal while the LAZ points are decoded
        from laspy._compression.lazrsbackend import LazrsPointReader
        original = LazrsPointReader.read_n_points

        def slow_decoding(self, n):
            mark()
            time.sleep(0.4)
            return original(self, n)

        LazrsPointReader.read_n_points = slow_decoding
    elif stage == "write":  # segment files written one by one
        import skpcd.io._segment_folder as folder
        original = folder.write_point_cloud

        def slow_write(*args, **kwargs):
            mark()
            time.sleep(0.05)
            return original(*args, **kwargs)

        folder.write_point_cloud = slow_write
    sys.argv = ["skpcd", *argv]
    if stage == "import":
        mark()
    from skpcd.cli import main
    sys.exit(main())
    """
)


def _leftovers(*folders):
    """Temporary outputs and run folders left anywhere we look."""
    left = []
    for folder in folders:
        left += [
            p.name for p in folder.iterdir() if p.name.startswith((".skpcd", "skpcd-"))
        ]
    return left


def _interrupt(tmp_path, stage, argv, how, delay):
    """Run the command, send ``how`` ``delay`` seconds after the stage
    began; returns (status, stderr lines, seconds from signal to exit)."""
    marker = tmp_path / "began"
    marker.unlink(missing_ok=True)
    temp = tmp_path / "temp"
    temp.mkdir(exist_ok=True)
    proc = start_until(
        [sys.executable, "-c", _SCRIPT, str(marker), stage, *map(str, argv)],
        marker,
        {"TMPDIR": str(temp)},
        "the stage never began",
    )
    time.sleep(delay)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT if how == "SIGINT" else signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    return proc.returncode, err.strip().splitlines(), time.monotonic() - sent


def _check(status, err, took, how, *folders):
    expected = 130 if how == "SIGINT" else 143
    word = "interrupted" if how == "SIGINT" else "terminated"
    assert status == expected, err
    assert len(err) == 1 and word in err[0], err
    assert "no partial output left" in err[0] or "nothing written" in err[0], err
    assert took < WITHIN, f"{took:.1f} s from the signal to the end"
    assert _leftovers(*folders) == []


def _tries(n):
    rng = random.Random(n)
    return [("SIGINT", "SIGTERM")[i % 2] for i in range(n)], rng


@pytest.fixture
def scene(tmp_path, scene_file):
    """The simulated scene of the CLI tests (a few thousand points)."""
    path = tmp_path / "input" / "scene.ply"
    path.parent.mkdir()
    scene_file(path)
    return path


def _segment(scene, out, *extra):
    return [
        "segment",
        str(scene),
        "-o",
        str(out),
        "--min-size",
        "30",
        "--quiet",
        *extra,
    ]


# --- the moments -------------------------------------------------------------------


def _while_importing(tmp_path, scene, n):
    # from 50 ms after the interpreter started to import skpcd (the few
    # milliseconds before skpcd.cli set its handlers follow Python's
    # defaults), through the parser, the fork and the heavy imports
    hows, rng = _tries(n)
    out = tmp_path / "segs"
    for how in hows:
        result = _interrupt(
            tmp_path, "import", _segment(scene, out), how, rng.uniform(0.05, 1.5)
        )
        _check(*result, how, tmp_path, tmp_path / "temp")
        assert not out.exists()


def _while_decoding_laz(tmp_path, n):
    import laspy

    laz = tmp_path / "sweep.laz"
    laspy.read(REAL_SCAN).write(laz)
    hows, rng = _tries(n)
    out = tmp_path / "segs"
    for how in hows:
        argv = _segment(laz, out)
        result = _interrupt(tmp_path, "laz", argv, how, rng.uniform(0, 0.3))
        _check(*result, how, tmp_path, tmp_path / "temp")
        assert "LAZ" not in result[1][0]  # not taken for a corrupt input


def _while_simulating_the_cloth(tmp_path, scene, n):
    hows, rng = _tries(n)
    out = tmp_path / "segs"
    for how in hows:
        argv = _segment(scene, out, "--ground", "csf")
        result = _interrupt(tmp_path, "csf", argv, how, rng.uniform(0.05, 0.5))
        _check(*result, how, tmp_path, tmp_path / "temp")
        assert not out.exists()


def _while_writing(tmp_path, scene, n, *, overwrite):
    out = tmp_path / "segs"
    before = None
    if overwrite:  # a previous run, which an interrupted one must not touch
        assert main(_segment(scene, out, "--eps", "1.0")) == 0
        before = {p.name: p.read_bytes() for p in out.iterdir()}
    hows, rng = _tries(n)
    extra = ["--eps", "0.3", "--overwrite"] if overwrite else ["--eps", "1.0"]
    for how in hows:
        # up to the end of the writing, the swap of the folders and beyond
        delay = rng.uniform(0, 1.2 if overwrite else 0.4)
        status, err, took = _interrupt(
            tmp_path, "write", _segment(scene, out, *extra), how, delay
        )
        if status == 0:  # ended before the signal: a whole new run
            assert err == [] and _leftovers(tmp_path, tmp_path / "temp") == []
            names = sorted(p.name for p in out.iterdir())
            assert "segments.csv" in names and "segmentation.json" in names
            if overwrite:  # back to the previous run for the next try
                assert main(_segment(scene, out, "--eps", "1.0", "--overwrite")) == 0
            continue
        _check(status, err, took, how, tmp_path, tmp_path / "temp")
        if overwrite:
            assert {p.name: p.read_bytes() for p in out.iterdir()} == before
        else:
            assert not out.exists()


# --- quick: in the suite -------------------------------------------------------------


def test_an_interrupt_while_importing(tmp_path, scene):
    # before: a traceback (SIGINT) or no message at all (SIGTERM)
    _while_importing(tmp_path, scene, 6)


def test_an_interrupt_while_decoding_a_laz_file(tmp_path):
    # before: SIGTERM was "the LAZ decoder failed (Terminated: 15)", status 1
    _while_decoding_laz(tmp_path, 2)


def test_an_interrupt_during_the_cloth_simulation(tmp_path, scene):
    # before: the command waited for the C++ simulation to end (23-62 s)
    _while_simulating_the_cloth(tmp_path, scene, 2)


def test_an_interrupt_while_writing_segments(tmp_path, scene):
    _while_writing(tmp_path, scene, 2, overwrite=False)


def test_an_interrupt_while_overwriting_keeps_the_previous_run(tmp_path, scene):
    # before: once an empty .skpcd-partial-...-old-segs folder and "Bad
    # file descriptor"
    _while_writing(tmp_path, scene, 3, overwrite=True)


def test_sigterm_inside_the_laz_decoder_is_not_a_corrupt_file(tmp_path, capsys):
    """In one process, deterministically: SIGTERM arrives while lazrs
    decodes (its handler's exception raised inside the reader's error
    wrapping)."""
    import laspy
    from laspy._compression.lazrsbackend import LazrsPointReader

    laz = tmp_path / "sweep.laz"
    laspy.read(REAL_SCAN).write(laz)
    original = LazrsPointReader.read_n_points

    def signalled(self, n):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1)  # the handler runs here, inside the decoding
        return original(self, n)

    previous = signal.getsignal(signal.SIGTERM)
    LazrsPointReader.read_n_points = signalled
    try:
        status = main(_segment(str(laz), str(tmp_path / "segs")))
    finally:
        LazrsPointReader.read_n_points = original
        signal.signal(signal.SIGTERM, previous)
    assert status == 143
    assert capsys.readouterr().err.strip().splitlines() == [
        "skpcd segment: terminated; no partial output left"
    ]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_where_python_ignores_exceptions_still_ends_the_run(
    signum, capsys
):
    """In one process, deterministically: the signal arrives inside a weakref
    callback (as inside the import machinery's module locks), where Python
    prints an exception and goes on; the run still ends, in one line."""
    import argparse
    import weakref

    from skpcd.cli._process import run

    class Thing:
        pass

    def work(args):
        thing = Thing()

        def callback(ref):
            os.kill(os.getpid(), signum)
            time.sleep(0.2)  # the handler runs here, inside the callback

        ref = weakref.ref(thing, callback)
        del thing  # the callback runs now
        time.sleep(5)  # the interrupt, delivered again, ends this
        return 0 if ref is not None else 1

    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    started = time.monotonic()
    try:
        status = run("segment", work, argparse.Namespace(quiet=True))
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    assert time.monotonic() - started < 4
    assert status == (130 if signum == signal.SIGINT else 143)
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"skpcd segment: {word}"), err


def test_a_crash_of_the_work_process_is_one_line_and_leaves_nothing(tmp_path, scene):
    """The work dies of a signal it did not expect (as the SIGSEGV seen at
    exit): the command says so in one line and removes the partial output."""
    script = textwrap.dedent(
        f"""
        import os, signal, sys
        import skpcd.io._segment_folder as folder
        original = folder.write_point_cloud
        calls = []
        def crash(*args, **kwargs):
            calls.append(1)
            if len(calls) == 3:
                os.kill(os.getpid(), signal.SIGSEGV)
            return original(*args, **kwargs)
        folder.write_point_cloud = crash
        sys.argv = ["skpcd", *{_segment(str(scene), str(tmp_path / "segs"))!r}]
        from skpcd.cli import main
        sys.exit(main())
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONFAULTHANDLER"},
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_CORE, (0, 0)),
    )
    assert done.returncode == 1, done.stderr
    assert done.stderr.strip().splitlines() == [
        "skpcd segment: error: the work process died (SIGSEGV); no partial output left"
    ]
    assert _leftovers(tmp_path) == [] and not (tmp_path / "segs").exists()


def test_a_folder_swap_cut_between_its_renames_is_undone(tmp_path):
    """What the command does for a killed work process: the journal names
    the temporary folders, and discarding them puts the previous run back
    when the swap was cut after moving it aside."""
    from skpcd._interrupts import discard, journal_entries, note, start_journal

    final = tmp_path / "segs"
    old = tmp_path / f"{PARTIAL_MARK}1-old-segs"
    new = tmp_path / f"{PARTIAL_MARK}1-segs"
    old.mkdir()
    (old / "a.ply").write_text("previous run")
    new.mkdir()
    (new / "b.ply").write_text("half of a new run")
    with open(tmp_path / "journal", "w+b") as journal:
        start_journal(journal.fileno())
        try:
            entry = note("folder", new, final=final, old=old)
        finally:
            start_journal(None)
        assert journal_entries(journal.fileno()) == [entry]
    discard(entry)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["journal", "segs"]
    assert [p.name for p in final.iterdir()] == ["a.ply"]
    discard(entry)  # twice: nothing more happens
    assert (final / "a.ply").read_text() == "previous run"


# --- slow: enough tries to catch a fault of 1 in 4 ------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    "moment", ["import", "laz", "csf", "write", "overwrite"], ids=str
)
def test_many_interrupts_at_random_moments(tmp_path, scene, moment):
    n = 12
    if moment == "import":
        _while_importing(tmp_path, scene, n)
    elif moment == "laz":
        _while_decoding_laz(tmp_path, n)
    elif moment == "csf":
        _while_simulating_the_cloth(tmp_path, scene, n)
    else:
        _while_writing(tmp_path, scene, n, overwrite=moment == "overwrite")
