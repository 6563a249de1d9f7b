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
    skpcd: kernels compiled in 12.3 s: neighbour search 4.1 s, normals 2.0 s, PFH/FPFH 6.2 s

on standard error: the first line when the first of skpcd's kernels starts
compiling in that call, the second when the call ends, with the seconds
spent compiling (not those computing) and what compiled: the stage each
kernel serves (``STAGES``), in the order they first compiled, so that a
command can be seen to compile the stages it runs and no other. Nested
entry points (a transformer
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

__all__ = ["QUIET_ENV", "STAGES", "compile_notice", "entry_point", "stage_of"]

#: The environment variable that silences the messages (any value but
#: "", "0", "false", "no").
QUIET_ENV = "SKPCD_QUIET_COMPILE"

#: The stage that the kernels of a module serve, as the closing line names
#: it; a module not listed is named after itself (``_octree_kernels``:
#: "octree").
STAGES = {
    "skpcd.datasets._street._raycast": "street simulator",
    "skpcd.features._improved_kernels": "improved PFH",
    "skpcd.features._pfh_kernels": "PFH/FPFH",
    "skpcd.features._fpfh_kernels": "PFH/FPFH",
    "skpcd.features._pair_kernels": "PFH/FPFH",
    "skpcd.features._vertical_kernels": "vertical profile",
    "skpcd.io._lzf": "PCD reading",
    "skpcd.io._ply": "PLY reading",
    "skpcd.neighbors._grid_kernels": "neighbour search",
    "skpcd.preprocessing._normals_kernels": "normals",
    "skpcd.preprocessing._sampling_kernels": "grid sampling",
    "skpcd.segmentation._cluster_kernels": "clustering",
    "skpcd.segmentation._range_kernels": "range image",
    "skpcd.segmentation._structure_kernels": "structures",
    "skpcd.segmentation.ground._cloth_kernels": "ground (CSF)",
    "skpcd.segmentation.ground._raster_kernels": "ground (raster)",
    "skpcd.segmentation.ground._smrf_kernels": "ground (SMRF)",
}


def stage_of(module):
    """The stage named for the kernels of ``module`` (a module name).

    Parameters
    ----------
    module : str
        The module defining the kernel, ``"skpcd.neighbors._grid_kernels"``.

    Returns
    -------
    stage : str
        ``STAGES[module]``, or the module's own name without its leading
        underscore and ``_kernels`` suffix, underscores as spaces.

    Examples
    --------
    >>> from skpcd.utils._compile import stage_of
    >>> stage_of("skpcd.neighbors._grid_kernels")
    'neighbour search'
    >>> stage_of("skpcd.segmentation.tiling._octree_kernels")
    'octree'
    """
    if module in STAGES:
        return STAGES[module]
    name = module.rpartition(".")[2].strip("_").removesuffix("_kernels")
    return name.replace("_", " ")


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
        self.stages = {}  # seconds compiling for each stage, first compiled first

    def add(self, stage, seconds):
        self.seconds += seconds
        self.stages[stage] = self.stages.get(stage, 0.0) + seconds

    def summary(self):
        """The closing line: the seconds, then those of each stage."""
        stages = ", ".join(f"{name} {s:.1f} s" for name, s in self.stages.items())
        return f"skpcd: kernels compiled in {self.seconds:.1f} s: {stages}"


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
            _say(call.summary())

    def on_start(self, ev):
        local = self._local
        depth = getattr(local, "depth", 0)
        local.depth = depth + 1
        if depth:
            return
        module = _module_of(ev.data)
        local.timed = module.startswith("skpcd.")
        if not local.timed:
            return
        local.stage = stage_of(module)
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
            local.call.add(local.stage, time.perf_counter() - local.start)
        local.call = None


def _module_of(data):
    """The module of the kernel a compile event is about ("" if unknown)."""
    func = getattr((data or {}).get("dispatcher"), "py_func", None)
    return getattr(func, "__module__", None) or ""


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
