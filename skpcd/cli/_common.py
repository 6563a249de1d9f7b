"""What every ``skpcd`` command shares: options, output checks, reading
labelled folders, and the way a command ends (errors, warnings, interrupts).
"""

import signal
import sys
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import PointCloudFileError

# What --quiet silences.
QUIET_HELP = "no progress bars, no line saying that numba kernels compile"

# Seconds to wait for a Dask scheduler before giving up.
SCHEDULER_TIMEOUT = 10


class CommandError(SystemExit):
    """A command cannot run as asked: one line on stderr, status 1."""

    def __init__(self, command, message):
        super().__init__(f"skpcd {command}: {message}")


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``finally`` (the
    atomic outputs' clean-up among them) runs, as for Ctrl-C."""


def _raise_terminated(signum, frame):
    raise Terminated(signum)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as one line, without the Python source line."""
    print(f"skpcd: warning: {message}", file=file or sys.stderr)


def run(command, func, args):
    """Run ``func(args)`` as the command ``command``.

    Bad input files end with one line on stderr and status 1; an output
    that cannot be written (full disk, no permission) likewise; Ctrl-C and
    SIGTERM end with one line and status 130 / 143, after the partial
    outputs are removed. A first run that compiles numba kernels says so on
    stderr, once (:func:`~skpcd.utils._compile.compile_notice`; not with
    ``--quiet``).
    """
    from skpcd.utils._compile import compile_notice  # imports numba: not for --help

    previous = signal.getsignal(signal.SIGTERM)
    in_main = _is_main_thread()
    if in_main:
        signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        quiet = bool(getattr(args, "quiet", False))
        with warnings.catch_warnings(), compile_notice(f"skpcd {command}", quiet=quiet):
            warnings.showwarning = _show_warning
            return func(args)
    except (PointCloudFileError, FileExistsError) as exc:
        print(f"skpcd {command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # writing: full disk, permissions, ...
        where = f" {exc.filename}" if exc.filename else ""
        print(
            f"skpcd {command}: error:{where} {exc.strerror or exc}; nothing was "
            "written in its place",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt:
        print(f"skpcd {command}: interrupted; no partial output left", file=sys.stderr)
        return 130
    except Terminated:
        print(f"skpcd {command}: terminated; no partial output left", file=sys.stderr)
        return 143
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


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
    without ``--overwrite``, is a folder, lies in no folder, or is one of
    ``inputs`` (whatever the flags)."""
    out = Path(path)
    if out.is_dir():
        raise CommandError(command, f"{out} is a folder; give a file name")
    if not out.parent.is_dir():
        raise CommandError(
            command, f"the folder {out.parent} of {out.name} does not exist"
        )
    check_not_an_input(out, command, inputs)
    if out.exists() and not args.overwrite:
        raise CommandError(command, f"{out} exists; pass --overwrite to replace it")
    return out


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
            args.command, f"{args.folder} has no labels.csv; pass --labels CSV"
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
