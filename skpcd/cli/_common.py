"""What every ``skpcd`` command shares: options, output checks, reading
labelled folders, and the way a command ends (errors, warnings, interrupts).
"""

import contextlib
import functools
import io
import os
import re
import signal
import sys
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import PointCloudFileError

# What --quiet silences.
QUIET_HELP = (
    "print only errors and warnings: no progress, no line saying that numba "
    "kernels compile, and no summary of what was written to the output"
)

# Seconds to wait for a Dask scheduler before giving up.
SCHEDULER_TIMEOUT = 10


class CommandError(SystemExit):
    """A command cannot run as asked: one line on stderr, status 1."""

    def __init__(self, command, message):
        super().__init__(f"skpcd {command}: {message}")


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that every ``finally`` (the
    atomic outputs' clean-up among them) runs, as for Ctrl-C. A
    KeyboardInterrupt, so that code letting Ctrl-C through (a reader's
    error wrapping) lets it through too."""


# seconds the work process has, after an interrupt, to clean up and end
# by itself before it is killed (and its partial outputs removed for it)
GRACE = 0.5

# keyword of the library -> (attribute of the command's arguments, option)
_OPTIONS = {
    "overwrite": ("overwrite", "--overwrite"),
    "ground": ("ground", "--ground"),
    "structures": ("structures", "--no-structures"),
    "tile_size": ("tile_size", "--tile-size"),
    "tile_buffer": ("tile_buffer", "--tile-buffer"),
    "eps": ("eps", "--eps"),
    "eps_scale": ("eps_scale", "--eps-scale"),
    "min_samples": ("min_samples", "--min-samples"),
    "min_cluster_size": ("min_size", "--min-size"),
    "max_cluster_size": ("max_size", "--max-size"),
    "n_jobs": ("n_jobs", "--n-jobs"),
    "keep_fields": ("keep_fields", "--keep-fields"),
    "random_state": ("random_state", "--random-state"),
    "sensor": ("sensor", "--sensor"),
    "method": ("method", "--method"),
    "trust_pickle": ("trust_pickle", "--trust-pickle"),
    "skip_unreadable": ("skip_unreadable", "--skip-unreadable"),
}
# (not inside a path: no slash or dot-extension next to the word)
_KEYWORD = re.compile(
    r"(?<![\w/.\\-])(?P<name>[a-z][a-z_]*)="
    r"(?P<value>'[^']*'|\"[^\"]*\"|-?[\w.]*\w)(?![/\\])"
)
_PARAMETER = re.compile(r"\bThe '(?P<name>\w+)' parameter of \w+")
_BARE = re.compile(r"(?<![\w/.\\-])(?P<name>[a-z]+_[a-z_]+)(?![\w=/\\-]|\.\w)")


def cli_spelling(message, args):
    """``message`` of the library with its keyword arguments spelled as
    the options of the command ``args`` was parsed for.

    ``pass overwrite=True`` becomes ``pass --overwrite``, ``ground='mobile'``
    ``--ground mobile``, ``structures=False`` ``--no-structures``,
    ``tile_size`` ``--tile-size``, "The 'eps' parameter of segment_scene"
    "The --eps option"; a keyword the command has no option for is left
    as it is.
    """

    def option(name):
        dest, flag = _OPTIONS.get(name, (None, None))
        return flag if dest is not None and hasattr(args, dest) else None

    def keyword(match):
        flag = option(match["name"])
        if flag is None:
            return match[0]
        value = match["value"].strip("'\"")
        if flag.startswith("--no-"):
            return flag if value == "False" else f"no {flag}"
        if value in ("True", "False"):
            return flag if value == "True" else f"no {flag}"
        return f"{flag} {value}"

    def parameter(match):
        flag = option(match["name"])
        return match[0] if flag is None else f"The {flag} option"

    def bare(match):
        return option(match["name"]) or match[0]

    message = _KEYWORD.sub(keyword, str(message))
    message = _PARAMETER.sub(parameter, message)
    return _BARE.sub(bare, message)


def _show_warning(message, category, filename, lineno, file=None, line=None, *, args):
    """Warnings as one line, without the Python source line, in the
    command's spelling."""
    print(f"skpcd: warning: {cli_spelling(message, args)}", file=file or sys.stderr)


def _catchable():
    """SIGINT and SIGTERM, but not one ignored when the command started
    (``nohup``, a background job of a script): that one stays ignored."""
    return [
        signum
        for signum in (signal.SIGINT, signal.SIGTERM)
        if signal.getsignal(signum) is not signal.SIG_IGN
    ]


def interrupt_line(command, signum):
    """The line that ends an interrupted command, and its status."""
    if signum == signal.SIGTERM:
        return f"skpcd {command}: terminated; no partial output left", 143
    return f"skpcd {command}: interrupted; no partial output left", 130


def _small_pages():
    """numpy's large arrays on 4 kB pages for the rest of the command,
    unless ``NUMPY_MADVISE_HUGEPAGE`` says otherwise. A command allocates
    and frees arrays of millions of points again and again; on transparent
    huge pages the kernel zeroes each new array 2 MB at a time (on the 10 M
    point street: 2.7 s of system time of ``skpcd segment``, 1 s of its 18
    s, against 0.7 s more user time on small pages)."""
    if "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        return
    try:
        from numpy._core.multiarray import _set_madvise_hugepage
    except ImportError:  # numpy 1.x
        try:
            from numpy.core.multiarray import _set_madvise_hugepage
        except ImportError:
            return
    _set_madvise_hugepage(False)


def run(command, func, args):
    """Run ``func(args)`` as the command ``command``.

    Bad input files end with one line on stderr and status 1; an output
    that cannot be written (full disk, no permission) likewise, naming the
    output; Ctrl-C and SIGTERM end with one line and status 130 / 143,
    after the partial outputs are removed (a second signal while they are
    removed is ignored). Messages of the library name the command's options
    (:func:`cli_spelling`). A first run that compiles numba kernels says so
    on stderr, once (:func:`~skpcd.utils._compile.compile_notice`); long
    stages draw progress on a terminal. ``--quiet`` silences both.
    """
    from skpcd._interrupts import interrupt

    received = []

    def on_signal(signum, frame):
        if received:  # already ending: let the clean-up finish
            return
        received.append(signum)
        interrupt(
            Terminated(signum) if signum == signal.SIGTERM else KeyboardInterrupt()
        )

    in_main = _is_main_thread()
    previous = {}
    if in_main:
        for signum in _catchable():
            previous[signum] = signal.signal(signum, on_signal)
    try:
        # numba, tqdm: imported here, not for --help
        from skpcd.utils._compile import compile_notice
        from skpcd.utils._progress import reporting, silenced

        _small_pages()
        quiet = bool(getattr(args, "quiet", False))
        # a command writing its result to -o prints only a summary: not with
        # --quiet (evaluate's report, its result, stays)
        summary = quiet and getattr(args, "output", None) is not None
        with (
            warnings.catch_warnings(),
            compile_notice(f"skpcd {command}", quiet=quiet),
            silenced(quiet),
            reporting(),
            _no_stdout(summary),
        ):
            warnings.showwarning = functools.partial(_show_warning, args=args)
            return func(args)
    except CommandError as exc:
        exc.code = cli_spelling(exc.code, args)
        raise
    except (PointCloudFileError, FileExistsError) as exc:
        print(f"skpcd {command}: error: {cli_spelling(exc, args)}", file=sys.stderr)
        return 1
    except OSError as exc:  # writing: full disk, permissions, ...
        where = f" {exc.filename}:" if exc.filename else ""
        print(
            f"skpcd {command}: error:{where} {exc.strerror or exc}; nothing was "
            "written in its place",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt as exc:
        line, status = interrupt_line(
            command, signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT
        )
        print(line, file=sys.stderr)
        return status
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class _Discard(io.TextIOBase):
    """A text stream that keeps nothing. It has no file descriptor, so code
    silencing descriptor 1 itself (the C++ messages of the cloth
    simulation) still finds the real one."""

    def writable(self):
        return True

    def write(self, text):
        return len(text)


@contextlib.contextmanager
def _no_stdout(active):
    """Standard output thrown away while ``active``."""
    if not active:
        yield
        return
    with contextlib.redirect_stdout(_Discard()):
        yield


class _Stop(BaseException):
    """The supervising process received SIGINT or SIGTERM."""


def supervised(command, work):
    """``work()`` run in a child process, answered within a second on
    Ctrl-C or SIGTERM whatever the child is doing.

    The child does the work (``work()``'s return value is its status) and
    records its temporary outputs in a journal
    (:mod:`skpcd._interrupts`). On SIGINT or SIGTERM this process passes the
    signal on and waits :data:`GRACE` seconds for the child to clean up and
    end; a child still busy (in the C++ cloth simulation, a numba kernel)
    is killed, its temporary outputs are removed from the journal, and one
    line says so. Temporary files of the child in the default temporary
    folder go too: it gets a folder of its own. A child that dies of
    anything else (a crash) is reported in one line, status 1. Once the
    child has ended, SIGINT and SIGTERM are ignored (the command exits with
    the work's status). Without ``os.fork`` (Windows) the work runs in
    this process.

    Returns
    -------
    status : int
        The child's status; 130 or 143 when interrupted.
    """
    if not hasattr(os, "fork"):  # pragma: no cover - POSIX CI
        return work()
    import tempfile

    caught = []

    def on_signal(signum, frame):
        caught.append(signum)
        if len(caught) == 1:
            raise _Stop

    journal = tempfile.TemporaryFile(prefix="skpcd-journal-")
    scratch = tempfile.mkdtemp(prefix="skpcd-run-")
    catchable = _catchable()
    for signum in catchable:
        signal.signal(signum, on_signal)
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        pid = os.fork()
        if pid == 0:
            _child(work, journal.fileno(), scratch, catchable)
        try:
            status = os.waitpid(pid, 0)[1]
        except _Stop:
            status = _stop(pid, caught[0])
    except _Stop:  # before the child was started
        status = None
    try:
        return _outcome(command, status, caught)
    finally:
        _remove_partials(journal, scratch)
        # the work has ended: a signal now would only kill the exit
        for signum in catchable:
            signal.signal(signum, signal.SIG_IGN)


def _child(work, journal_fd, scratch, catchable):
    """The work process: ``work()``, then exit at once with its status
    (no interpreter teardown while numba's or joblib's threads run)."""
    import tempfile
    import traceback

    from skpcd._interrupts import start_journal

    status = 1
    try:
        for signum in catchable:
            signal.signal(signum, signal.default_int_handler)
        _end_with_parent()
        start_journal(journal_fd)
        tempfile.tempdir = scratch
        os.environ["TMPDIR"] = scratch
        status = work()
    except SystemExit as exc:  # CommandError and argparse's own
        if exc.code is None or isinstance(exc.code, int):
            status = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            status = 1
    except (KeyboardInterrupt, _Stop):  # before run() took over the signals
        status = 1  # silent: the supervising process says it
    except BaseException:
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(status)


def _end_with_parent():
    """On Linux, SIGTERM to this (work) process when the supervising one
    dies, even of SIGKILL: the work then cleans up and ends instead of
    running on unseen."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = os.getppid()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PDEATHSIG
    if os.getppid() != parent:  # it died before prctl
        os.kill(os.getpid(), signal.SIGTERM)


def _stop(pid, signum):
    """Pass ``signum`` on to the child, give it :data:`GRACE` seconds to
    end, then kill it; returns its wait status."""
    import time

    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signum)
    deadline = time.monotonic() + GRACE
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        time.sleep(0.01)
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    return os.waitpid(pid, 0)[1]


def _outcome(command, status, caught):
    """The command's status from the child's wait status, with the line
    the child could not print itself."""
    code = None if status is None else os.waitstatus_to_exitcode(status)
    if caught:
        line, expected = interrupt_line(command, caught[0])
        if code in (130, 143):  # the child ended by itself and said so
            return code
        print(line, file=sys.stderr)
        return expected
    if code < 0:
        name = signal.Signals(-code).name
        print(
            f"skpcd {command}: error: the work process died ({name}); no partial "
            "output left",
            file=sys.stderr,
        )
        return 1
    return code


def _remove_partials(journal, scratch):
    """Remove what the journal names (newest first) and the child's
    temporary folder."""
    import shutil

    from skpcd._interrupts import discard, journal_entries

    for entry in reversed(journal_entries(journal.fileno())):
        with contextlib.suppress(OSError):
            discard(entry)
    journal.close()
    shutil.rmtree(scratch, ignore_errors=True)


def _is_main_thread():
    import threading

    return threading.current_thread() is threading.main_thread()


# --- options -----------------------------------------------------------


def add_n_jobs(parser):
    parser.add_argument(
        "--n-jobs",
        type=int,
        default=-1,
        help="threads (default -1: all cores; results do not depend on it)",
    )


def add_output_options(parser):
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an output written by an earlier run (never an input)",
    )
    parser.add_argument("--quiet", action="store_true", help=QUIET_HELP)


def add_scheduler(parser):
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing Dask cluster: the scheduler's address, e.g. "
        "tcp://host:8786 (needs pip install 'skpcd[dask]')",
    )


def add_trust_pickle(parser):
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help="also load a model saved as a pickle (joblib: older skpcd releases, "
        "save_model(format='joblib')). DANGER: unpickling runs code from the "
        "file; only for files you made yourself or fully trust",
    )


def add_skip_unreadable(parser):
    parser.add_argument(
        "--skip-unreadable",
        action="store_true",
        help="skip files of the folder that cannot be read as point clouds "
        "(a notes.txt...), listing them, instead of stopping",
    )


# --- outputs -----------------------------------------------------------


def check_output(path, args, command, *, inputs=()):
    """The output file ``path``, refused before any work when it exists
    without ``--overwrite``, is a folder, lies in no folder, is one of
    ``inputs`` (whatever the flags), would be read as a segment of the
    FOLDER the command reads (``args.folder``: a CSV in it, say), or
    cannot be written (a read-only folder, a full disk: an OSError naming
    it)."""
    out = Path(path)
    if out.is_dir():
        raise CommandError(command, f"{out} is a folder; give a file name")
    if not out.parent.is_dir():
        raise CommandError(
            command, f"the folder {out.parent} of {out.name} does not exist"
        )
    check_not_an_input(out, command, inputs)
    folder = getattr(args, "folder", None)
    if folder is not None and _read_as_a_segment(out, folder):
        if out.exists():
            raise CommandError(command, f"the output {out} is an input file")
        raise CommandError(
            command,
            f"the output {out} is inside {folder}, the folder of segments "
            "read: the next run would read it as a segment; write it elsewhere",
        )
    if out.exists() and not args.overwrite:
        raise CommandError(command, f"{out} exists; pass --overwrite to replace it")
    from skpcd.io._atomic import check_writable

    check_writable(out)
    return out


def _read_as_a_segment(out, folder):
    """Whether reading the folder of segments ``folder`` would read the
    file ``out`` (a point-cloud extension, in the folder itself, not
    hidden, not labels.csv or segments.csv)."""
    from skpcd.io._api import SUPPORTED_EXTENSIONS
    from skpcd.io._segment_folder import SEGMENTS_SUMMARY

    return (
        Path(folder).is_dir()
        and out.resolve().parent == Path(folder).resolve()
        and out.suffix.lower() in SUPPORTED_EXTENSIONS
        and not out.name.startswith(".")
        and out.name not in ("labels.csv", SEGMENTS_SUMMARY)
    )


def check_not_an_input(out, command, inputs):
    """Refuse an output that is one of the files read, even with --overwrite."""
    target = Path(out).resolve()
    for path in inputs:
        if path is not None and Path(path).resolve() == target:
            raise CommandError(command, f"the output {out} is an input file")


def side_file(out, what):
    """The name of a file written beside the output ``out``:
    ``labelled.ply`` -> ``labelled.ply.classes.csv``."""
    out = Path(out)
    return out.with_name(f"{out.name}.{what}")


# --- inputs ------------------------------------------------------------


def check_folder(folder, command):
    """A FOLDER argument that must exist (a glob pattern passes through)."""
    import glob

    if not glob.has_magic(str(folder)) and not Path(folder).exists():
        raise CommandError(command, f"{folder} does not exist")
    return folder


def read_folder(args, labels=None):
    """``read_segments`` of ``args.folder``, skipping unreadable files when
    ``--skip-unreadable``; returns ``(clouds, y, names, files)``."""
    from skpcd.io import read_segments

    check_folder(args.folder, args.command)
    errors = "skip" if getattr(args, "skip_unreadable", False) else "raise"
    clouds, y, names = read_segments(
        args.folder, labels, verbose=not args.quiet, errors=errors
    )
    files = [Path(args.folder) / n for n in names] if Path(args.folder).is_dir() else []
    return clouds, y, names, files


def labels_path(args):
    """``--labels``, or FOLDER/labels.csv; a clear error when neither exists."""
    check_folder(args.folder, args.command)
    if args.labels is not None:
        return Path(args.labels)
    default = Path(args.folder) / "labels.csv"
    if not default.is_file():
        raise CommandError(
            args.command,
            f"{args.folder} has no labels.csv; pass --labels CSV"
            + (
                ", or --labels-from FIELD for scans labelled point by point"
                if args.command == "fit"
                else ""
            ),
        )
    return default


def load_labelled(args):
    """The labelled segments of ``args.folder`` (or the embedded data):
    ``(clouds, y, source, files)``."""
    if args.folder is None:
        from skpcd.datasets import make_urban_objects

        clouds, labels = make_urban_objects(n_per_class=40, random_state=0)
        source = "embedded synthetic urban objects (make_urban_objects)"
        return clouds, labels, source, []
    labels = labels_path(args)
    clouds, y, _, files = read_folder(args, labels)
    return clouds, y, str(args.folder), [labels, *files]


def load_model_for(args, command):
    """The model of ``args.model``, refused when it cannot predict; the
    shipped street model, said in one line on stderr, when none is given."""
    from skpcd.io import load_model

    if args.model is None:
        from skpcd.classification import load_street_model

        model, info = load_street_model(return_info=True)
        args.model = "the shipped street model"
        print(
            f"skpcd {command}: no model given, using the shipped street model "
            f"{info['metadata']['model_version']} (simulated streets only; "
            "pass a model written by skpcd fit for your own classes)",
            file=sys.stderr,
        )
        return model
    model = load_model(args.model, trust_pickle=args.trust_pickle)
    if not hasattr(model, "predict"):
        raise CommandError(
            command,
            f"{args.model} holds a {type(model).__name__}, not a fitted model; "
            "write one with skpcd fit",
        )
    return model


def predict_or_explain(model, clouds, args, command):
    """``predict_with_confidence`` with a model that cannot take clouds
    turned into a clear error."""
    from skpcd.classification import predict_with_confidence

    try:
        return predict_with_confidence(model, clouds)
    except ValueError as exc:  # e.g. a model of 2-D features, not of clouds
        raise CommandError(
            command,
            f"the model in {args.model} cannot label these segments "
            f"({type(model).__name__}: {exc}); write one with skpcd fit",
        ) from exc


def unique_counts(values):
    """``"a 3, b 1"``: the values and how often each appears."""
    labels, counts = np.unique(np.asarray(values).astype(str), return_counts=True)
    return ", ".join(f"{c} {n}" for c, n in zip(labels, counts))


def on_cluster(args, func):
    """Run ``func(args)`` inside ``joblib.parallel_config(backend="dask")``
    with a client of the scheduler at ``args.scheduler``."""
    try:
        from distributed import Client
    except ImportError as exc:
        raise CommandError(
            args.command,
            "--scheduler needs dask.distributed: pip install 'skpcd[dask]'",
        ) from exc
    import joblib

    try:
        client = Client(args.scheduler, timeout=SCHEDULER_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise CommandError(
            args.command,
            f"cannot reach the Dask scheduler at {args.scheduler} "
            f"({type(exc).__name__}: {exc})",
        ) from exc
    with client, joblib.parallel_config(backend="dask"):
        return func(args)
