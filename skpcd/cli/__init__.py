"""The ``skpcd`` command line: a thin shell over the library.

One module per command (or pair of commands), each with ``add_parser(s)``
and ``run_*`` functions: ``_info`` (info), ``_evaluate`` (evaluate, score),
``_model`` (fit, predict), ``_describe`` (describe), ``_segment`` (segment,
identify); ``_common`` holds the shared options, the output checks and the
way a command ends (:func:`skpcd.cli._common.run`).
"""

import argparse
import sys

from skpcd.cli import _describe, _evaluate, _info, _model, _review, _segment
from skpcd.cli._common import on_cluster, run
from skpcd.cli._evaluate import format_report

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
    _describe.add_parser(sub)
    _segment.add_parsers(sub)
    _review.add_parser(sub)
    return parser


def main(argv=None):
    """Run the ``skpcd`` command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments; ``sys.argv[1:]`` when None.

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
    if getattr(args, "scheduler", None):
        return run(args.command, lambda a: on_cluster(a, a.func), args)
    return run(args.command, args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
