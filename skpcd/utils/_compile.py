"""One line on stderr when skpcd's numba kernels compile, and for how long.

numba compiles a kernel on its first call and, with ``cache=True``, keeps
the machine code on disk (in ``__pycache__`` beside the source, or in
``NUMBA_CACHE_DIR``). The first call of an estimator after an installation
therefore spends seconds compiling, the later ones load the kernels in
milliseconds. So that this wait is not a silent one, the public entry
points (the transformers' ``transform``, the estimators' ``fit``, the
command line, the simulators) run inside :func:`compile_notice`, most
through the :func:`entry_point` decorator; a listener on numba's
``"numba:compile"`` events, which numba broadcasts only when it actually
compiles (a cache miss), prints

.. code-block:: text

    skpcd: compiling numba kernels for PFHTransformer (first use in this environment; cached afterwards)...
    skpcd: kernels compiled in 12.3 s

on standard error: the first line when the first of skpcd's kernels starts
compiling in that call, the second when the call ends, with the seconds
spent compiling (not those computing). Nested entry points (a transformer
inside ``skpcd evaluate``) share the outermost one's message: one per
command, one per estimator call that compiles in Python. A call that
compiles nothing says nothing. Kernels compiled outside every entry point
(internal functions called directly) get the first line, worded without a
name, once per process, and no second line: nothing tells when such a
series of compilations ends.

``SKPCD_QUIET_COMPILE=1`` in the environment silences the lines (checked
at every call); so does ``--quiet`` on the command line.
"""  # noqa: E501

import contextlib
import functools
import os
import sys
import threading
import time

from numba.core import event

__all__ = ["QUIET_ENV", "compile_notice", "entry_point"]

#: The environment variable that silences the messages (any value but
#: "", "0", "false", "no").
QUIET_ENV = "SKPCD_QUIET_COMPILE"


def _quiet():
    return os.environ.get(QUIET_ENV, "").strip().lower() not in ("", "0", "false", "no")


def _say(line):
    stream = sys.stderr
    if stream is None:  # pythonw: nowhere to say it
        return
    try:
        print(line, file=stream, flush=True)
    except (OSError, ValueError):  # closed or broken stderr: not worth failing
        pass


class _Call:
    """An entry point being run: what it is, and what it compiled."""

    def __init__(self, what, quiet):
        self.what = what
        self.quiet = quiet
        self.announced = False
        self.seconds = 0.0


class _CompileListener(event.Listener):
    """Times the compilations of skpcd's kernels and announces the first.

    Compile events nest (a kernel compiles the functions it calls); only
    the outermost one of each thread counts. Compilations outside every
    entry point belong to one call that never ends (``_lone``).
    """

    def __init__(self):
        self._lock = threading.Lock()
        self._calls = []  # the entry points running, outermost first
        self._lone = None  # compilations outside them, once announced
        self._local = threading.local()  # this thread's compile nesting

    def enter(self, what, quiet):
        call = _Call(what, quiet)
        with self._lock:
            self._calls.append(call)
        return call

    def leave(self, call):
        with self._lock:
            self._calls.remove(call)
        if call.announced and not call.quiet:
            _say(f"skpcd: kernels compiled in {call.seconds:.1f} s")

    def on_start(self, ev):
        local = self._local
        depth = getattr(local, "depth", 0)
        local.depth = depth + 1
        if depth:
            return
        local.timed = _is_ours(ev.data)
        if not local.timed:
            return
        local.start = time.perf_counter()
        with self._lock:
            if self._calls:
                call = self._calls[0]
            else:
                if self._lone is None:
                    self._lone = _Call(None, False)
                call = self._lone
            local.call = call
            announce = not call.announced
            call.announced = True
        if announce and not (call.quiet or _quiet()):
            named = "" if call.what is None else f" for {call.what}"
            _say(
                f"skpcd: compiling numba kernels{named} (first use in this "
                "environment; cached afterwards)..."
            )

    def on_end(self, ev):
        local = self._local
        local.depth -= 1
        if local.depth or not local.timed:
            return
        with self._lock:
            local.call.seconds += time.perf_counter() - local.start
        local.call = None


def _is_ours(data):
    func = getattr((data or {}).get("dispatcher"), "py_func", None)
    return getattr(func, "__module__", "").startswith("skpcd.")


_LISTENER = _CompileListener()
event.register("numba:compile", _LISTENER)


@contextlib.contextmanager
def compile_notice(what, *, quiet=False):
    """Announce on stderr the kernels that compile within the block.

    Parameters
    ----------
    what : str
        The entry point, as printed: ``"PFHTransformer"``,
        ``"skpcd evaluate"``.
    quiet : bool, default=False
        Say nothing (also when the environment sets ``SKPCD_QUIET_COMPILE``).
        Inside another ``compile_notice`` block, the outermost block's
        ``what`` and ``quiet`` apply.

    Yields
    ------
    None

    Examples
    --------
    >>> from skpcd.utils._compile import compile_notice
    >>> with compile_notice("an example"):  # nothing compiles: nothing said
    ...     pass
    """
    call = _LISTENER.enter(what, quiet or _quiet())
    try:
        yield
    finally:
        _LISTENER.leave(call)


def entry_point(func):
    """Run ``func`` inside :func:`compile_notice`, named after the
    estimator's class for a method, after the function otherwise.

    Parameters
    ----------
    func : callable
        A public function or method that may compile kernels.

    Returns
    -------
    wrapped : callable
        The same function, announcing its compilations.
    """
    method = "." in func.__qualname__

    @functools.wraps(func)
    def wrapped(*args, **kwargs):
        what = type(args[0]).__name__ if method and args else func.__name__
        with compile_notice(what):
            return func(*args, **kwargs)

    return wrapped
