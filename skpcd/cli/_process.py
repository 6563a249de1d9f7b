"""How a command runs and ends: in a supervised work process that Ctrl-C
and SIGTERM reach within a second, its partial outputs recorded in a journal
and removed when it is cut short, and its errors, warnings and interrupts
said in one line (:func:`run`, :func:`supervised`)."""

import contextlib
import functools
import io
import os
import signal
import sys
import threading
import warnings

from skpcd.cli._common import CommandError, cli_spelling
from skpcd.exceptions import PointCloudFileError


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that every ``finally`` (the
    atomic outputs' clean-up among them) runs, as for Ctrl-C. A
    KeyboardInterrupt, so that code letting Ctrl-C through (a reader's
    error wrapping) lets it through too."""


# seconds the work process has, after an interrupt, to clean up and end
# by itself before it is killed (and its partial outputs removed for it)
GRACE = 0.5


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


# Seconds after which an interrupt that landed where Python ignores
# exceptions is delivered again.
_REDELIVER = 0.01


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

    def on_lost(unraisable):
        # the interrupt was raised where Python ignores exceptions (a
        # callback of the import machinery, a finaliser): it would only be
        # printed, and the run go on; deliver it again a moment later,
        # when this frame is gone
        if isinstance(unraisable.exc_value, KeyboardInterrupt) and received:
            signum = received.pop()
            threading.Timer(_REDELIVER, os.kill, (os.getpid(), signum)).start()
            return
        lost_hook(unraisable)

    in_main = _is_main_thread()
    previous, lost_hook = {}, sys.unraisablehook
    if in_main:
        for signum in _catchable():
            previous[signum] = signal.signal(signum, on_signal)
        sys.unraisablehook = on_lost
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
        sys.unraisablehook = lost_hook


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
