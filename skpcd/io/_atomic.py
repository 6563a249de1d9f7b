"""Outputs that appear whole or not at all.

Every file skpcd writes goes through :func:`atomic_path` (one file) or
:func:`atomic_folder` (a folder of files written by one run): the data is
written beside its final name, under a hidden name that no reader of skpcd
takes for a result, and renamed into place only when complete. An exception,
Ctrl-C or SIGTERM (the CLI turns it into an exception) removes the partial
output and leaves what was there before untouched; every temporary name is
also recorded in the journal of :mod:`skpcd._interrupts`, so that the
``skpcd`` command removes it even when its work process is killed.
:func:`check_writable` finds an output that cannot be written before any
work; an error while writing names the final output, not the temporary one.
"""

import contextlib
import os
import tempfile
from pathlib import Path

from skpcd._interrupts import deferred, discard, note
from skpcd.exceptions import PointCloudFileError

__all__ = [
    "PARTIAL_MARK",
    "atomic_folder",
    "atomic_path",
    "check_folder_output",
    "check_writable",
    "scratch_folder",
]

# part of the name of every temporary output (files and folders)
PARTIAL_MARK = ".skpcd-partial-"


def _partial_name(path):
    """A hidden name beside ``path`` with the same extension (the writers
    pick the format from it)."""
    return path.with_name(f"{PARTIAL_MARK}{os.getpid()}-{path.stem}{path.suffix}")


@contextlib.contextmanager
def atomic_path(path, *, overwrite=False):
    """Write a file under a temporary name and rename it when whole.

    Parameters
    ----------
    path : str or path-like
        The final name.
    overwrite : bool, default=False
        Replace an existing file; otherwise an existing file raises
        :class:`FileExistsError` before anything is written.

    Yields
    ------
    tmp : pathlib.Path
        The name to write to, in the same folder and with the same
        extension as ``path``. Renamed to ``path`` when the block ends
        normally; deleted when it raises (including KeyboardInterrupt).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from skpcd.io._atomic import atomic_path
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_path(out) as tmp:
    ...     _ = tmp.write_text("whole")
    >>> out.read_text()
    'whole'
    """
    path = Path(os.fspath(path))
    if path.exists() and not overwrite:
        raise FileExistsError(
            f"{path}: the file exists; pass overwrite=True to replace it."
        )
    tmp = _partial_name(path)
    entry = note("file", tmp)
    try:
        with _naming(path, tmp):
            yield tmp
            os.replace(tmp, path)
    finally:
        with deferred():
            discard(entry)


@contextlib.contextmanager
def _naming(path, tmp):
    """An OSError about the temporary ``tmp`` (or about no file: a full
    disk) raised as one about the output ``path``."""
    try:
        yield
    except OSError as exc:
        name = exc.filename
        if isinstance(exc, PointCloudFileError) or (
            name is not None and not str(name).startswith(str(tmp))
        ):
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


def check_writable(path):
    """Check, before any work, that the output ``path`` can be written.

    A temporary file is created where the output's temporary name will be
    (for a folder that does not exist yet: in the nearest folder that
    does), a byte written to it, and the file removed.

    Parameters
    ----------
    path : str or path-like
        The output, a file or a folder.

    Raises
    ------
    OSError
        Naming ``path``: a read-only folder, a full disk, a parent that
        is a file...
    """
    path = Path(os.fspath(path))
    where = path.parent
    while not where.exists() and where != where.parent:
        where = where.parent
    probe = where / f"{PARTIAL_MARK}{os.getpid()}-probe-{path.name}"
    entry = note("file", probe)
    try:
        with _naming(path, probe):
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            try:
                os.write(fd, b"\0")
            finally:
                os.close(fd)
    finally:
        with deferred():
            discard(entry)


def check_folder_output(path, *, overwrite=False, owned=None):
    """Check, before any work, that :func:`atomic_folder` may fill ``path``.

    Parameters are those of :func:`atomic_folder`.

    Returns
    -------
    path : pathlib.Path
        The folder.

    Raises
    ------
    FileExistsError
        If ``path`` is a file, a non-empty folder without ``overwrite``, or
        a folder holding entries that ``owned`` does not recognise.
    """
    path = Path(os.fspath(path))
    if path.exists() and not path.is_dir():
        raise FileExistsError(f"{path}: exists and is not a folder")
    existing = sorted(p.name for p in path.iterdir()) if path.is_dir() else []
    if existing and not overwrite:
        raise FileExistsError(
            f"{path}: the folder is not empty ({len(existing)} entries); pass "
            "overwrite=True to replace what an earlier run wrote"
        )
    foreign = [n for n in existing if owned is not None and not owned(n)]
    if foreign:
        shown = ", ".join(foreign[:5]) + (" ..." if len(foreign) > 5 else "")
        raise FileExistsError(
            f"{path}: holds {len(foreign)} file(s) skpcd did not write ({shown}); "
            "move them away or choose another output folder"
        )
    return path


@contextlib.contextmanager
def atomic_folder(path, *, overwrite=False, owned=None):
    """Fill a new folder under a temporary name and swap it in when whole.

    Parameters
    ----------
    path : str or path-like
        The final folder.
    overwrite : bool, default=False
        Replace an existing folder. Without it an existing non-empty folder
        raises :class:`FileExistsError` before anything is written.
    owned : callable, default=None
        ``owned(name) -> bool`` tells which entries of an existing folder
        an earlier run wrote. With ``overwrite``, a folder holding anything
        else raises :class:`FileExistsError` naming it: skpcd never deletes
        what it did not write. None treats every entry as owned.

    Yields
    ------
    tmp : pathlib.Path
        An empty folder beside ``path``. When the block ends normally the
        old folder (if any) is moved aside, ``tmp`` renamed to ``path`` and
        the old one deleted; when it raises, ``tmp`` is deleted and ``path``
        is as it was.
    """
    path = check_folder_output(path, overwrite=overwrite, owned=owned)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _partial_name(path)
    old = path.with_name(f"{PARTIAL_MARK}{os.getpid()}-old-{path.name}")
    entry = note("folder", tmp, final=path, old=old)
    try:
        with _naming(path, tmp):
            tmp.mkdir()
            yield tmp
            with deferred():  # both renames, or neither
                if path.is_dir():
                    os.replace(path, old)
                os.replace(tmp, path)
    finally:
        with deferred():
            discard(entry)


@contextlib.contextmanager
def scratch_folder(parent):
    """A hidden folder in ``parent`` for the intermediate files of a run,
    removed when the block ends (and by the ``skpcd`` command when its work
    process is killed).

    Parameters
    ----------
    parent : str or path-like
        Where to create it: beside the output, on the same disk.

    Yields
    ------
    folder : pathlib.Path
        The empty folder.
    """
    folder = Path(
        tempfile.mkdtemp(prefix=f"{PARTIAL_MARK}{os.getpid()}-work-", dir=parent)
    )
    entry = note("folder", folder)
    try:
        yield folder
    finally:
        with deferred():
            discard(entry)
