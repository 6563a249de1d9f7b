"""Interrupts that leave nothing behind, whatever the process is doing.

Two pieces, both light (no numpy, no scikit-learn: the ``skpcd`` command
loads this module before any heavy library):

- a journal of the temporary outputs a run creates (:func:`note`), kept in
  a file that another process can read, and :func:`discard`, which removes
  one of them, or puts an old output back when a swap was cut halfway. The
  ``skpcd`` command runs its work in a child process and, when the child
  dies or is killed, discards whatever the journal names; an interrupt
  therefore needs no cooperation from code that cannot be interrupted (the
  C++ cloth simulation, a numba kernel).
- :func:`deferred`, a section during which an interrupt delivered through
  :func:`interrupt` waits until the section ends (the renames that swap an
  output folder in, the removal of a partial output).
"""

import contextlib
import json
import os
import shutil

__all__ = ["deferred", "discard", "interrupt", "journal_entries", "note"]

# file descriptor of the journal of temporary outputs (None: no journal)
_journal_fd = None
# nesting depth of deferred() sections, and the interrupt waiting for them
_depth = 0
_pending = []


def start_journal(fd):
    """Record every temporary output of this process in the file ``fd``."""
    global _journal_fd
    _journal_fd = fd


def note(kind, path, *, final=None, old=None):
    """Record, before creating it, the temporary output ``path``.

    Parameters
    ----------
    kind : {"file", "folder"}
        A temporary file, or a temporary folder (its contents included).
    path : path-like
        The temporary name.
    final : path-like, default=None
        For a folder swapped in place of another: the final name.
    old : path-like, default=None
        For a folder swapped in place of another: the name the previous
        folder takes during the swap.

    Returns
    -------
    entry : dict
        What :func:`discard` takes.
    """
    entry = {"kind": kind, "path": os.fspath(path)}
    if final is not None:
        entry["final"], entry["old"] = os.fspath(final), os.fspath(old)
    if _journal_fd is not None:
        # one write of less than a page: never seen half written. A journal
        # that cannot be written (its temporary folder full) does not stop
        # the output: only a killed run would leave this one behind.
        with contextlib.suppress(OSError):
            os.write(_journal_fd, (json.dumps(entry) + "\n").encode())
    return entry


def journal_entries(fd):
    """The entries :func:`note` wrote to the journal ``fd``, in order."""
    data, offset = b"", 0
    while chunk := os.pread(fd, 1 << 16, offset):
        data += chunk
        offset += len(chunk)
    lines = data.decode(errors="replace").splitlines()
    entries = []
    for line in lines:
        with contextlib.suppress(ValueError):
            entries.append(json.loads(line))
    return entries


def discard(entry):
    """Remove the temporary output of ``entry`` (see :func:`note`).

    A folder swap cut between its two renames (the previous output moved
    aside, the new one not yet in place) is undone: the previous output
    goes back to its name. Safe to call twice, and after the output was
    completed (its temporary name then no longer exists).
    """
    path = entry["path"]
    if entry["kind"] == "file":
        # only a file that exists: on a read-only file system unlinking a
        # missing one fails with EROFS, not FileNotFoundError
        if os.path.lexists(path):
            with contextlib.suppress(FileNotFoundError, NotADirectoryError):
                os.unlink(path)
        return
    old = entry.get("old")
    if old is not None and os.path.isdir(old):
        if not os.path.lexists(entry["final"]):
            os.replace(old, entry["final"])
        else:
            shutil.rmtree(old, ignore_errors=True)
    shutil.rmtree(path, ignore_errors=True)


@contextlib.contextmanager
def deferred():
    """A section that an interrupt delivered through :func:`interrupt`
    does not cut: the interrupt is raised when the outermost section ends.
    """
    global _depth
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0 and _pending:
            # the interrupt wins over an error of the section
            raise _pending.pop()


def interrupt(exc):
    """Raise ``exc`` now, or at the end of the current :func:`deferred`
    section (a signal handler's way to interrupt)."""
    if _depth:
        if not _pending:
            _pending.append(exc)
        return
    raise exc
