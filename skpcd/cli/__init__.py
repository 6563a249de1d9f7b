"""The ``skpcd`` command line: a thin shell over the library.

One module per command (or pair of commands), each with ``add_parser(s)``
and ``run_*`` functions: ``_info`` (info), ``_evaluate`` (evaluate, score),
``_model`` (fit, predict), ``_scan_labels`` (score-scan, and the options
of fit on labelled scans), ``_describe`` (describe), ``_segment`` (segment,
and the segmentation identify shares), ``_identify`` (identify), ``_simulate``
(simulate); ``_common`` holds the shared options,
the output checks; ``_process`` the way a command runs and ends
(:func:`skpcd.cli._process.run`).
"""

import os
import signal
import sys


def _end_before_start(signum, frame):
    """Ctrl-C or SIGTERM before the command started: one line, nothing
    was written."""
    status = 143 if signum == signal.SIGTERM else 130
    what = "terminated" if status == 143 else "interrupted"
    os.write(2, f"skpcd: {what} before starting; nothing written\n".encode())
    os._exit(status)


def _is_the_command():
    """Whether this process is the ``skpcd`` command (the console script
    or ``python -m skpcd``), not a program importing the CLI."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return name == "skpcd" or getattr(spec, "name", None) == "skpcd.__main__"


# The command answers Ctrl-C and SIGTERM from its first imports on (numpy
# and the parser are loaded below); main() takes over from here. A signal
# ignored when the command started (a background job) stays ignored.
if _is_the_command():
    for _signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(_signum) is not signal.SIG_IGN:
            signal.signal(_signum, _end_before_start)

import argparse  # noqa: E402

from skpcd.cli import (  # noqa: E402
    _describe,
    _evaluate,
    _identify,
    _info,
    _model,
    _review,
    _scan_labels,
    _segment,
    _simulate,
)
from skpcd.cli._common import on_cluster  # noqa: E402
from skpcd.cli._evaluate import format_report  # noqa: E402
from skpcd.cli._process import run, supervised  # noqa: E402

__all__ = ["build_parser", "format_report", "main"]


def build_parser():
    """The argument parser of the ``skpcd`` command, one subparser per command.

    Returns
    -------
    parser : argparse.ArgumentParser
        The parser; each subparser sets ``func`` to the function to run.
    """
    from skpcd import __version__

    parser = argparse.ArgumentParser(
        prog="skpcd",
        description="Segment LiDAR scans and identify the objects in them.",
    )
    parser.add_argument("--version", action="version", version=f"skpcd {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _info.add_parser(sub)
    _evaluate.add_parsers(sub)
    _model.add_parsers(sub)
    _scan_labels.add_parser(sub)
    _describe.add_parser(sub)
    _segment.add_parser(sub)
    _identify.add_parser(sub)
    _review.add_parser(sub)
    _simulate.add_parser(sub)
    return parser


def main(argv=None):
    """Run the ``skpcd`` command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments; ``sys.argv[1:]`` when None. When None (the ``skpcd``
        command itself) the work runs in a child process, so that Ctrl-C
        and SIGTERM end the command within a second whatever it is doing
        (:func:`skpcd.cli._process.supervised`); with ``argv`` given it
        runs in this process.

    Returns
    -------
    status : int
        0 on success; 1 when an input file cannot be used or an output
        cannot be written; 130 on Ctrl-C and 143 on SIGTERM (no partial
        output is left). A command that cannot run as asked raises
        :class:`SystemExit` with a one-line message (status 1 from the
        shell).
    """
    args = build_parser().parse_args(argv)
    func = args.func
    if getattr(args, "scheduler", None):
        func = lambda a: on_cluster(a, args.func)  # noqa: E731
    if argv is None:
        return supervised(args.command, lambda: run(args.command, func, args))
    return run(args.command, func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
