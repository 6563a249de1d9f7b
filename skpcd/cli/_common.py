"""What every ``skpcd`` command shares: options, output checks, reading
labelled folders, its errors and the library's messages in the command's
spelling. How a command runs and ends is in :mod:`skpcd.cli._process`.
"""

import re
import sys
from pathlib import Path

import numpy as np

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
