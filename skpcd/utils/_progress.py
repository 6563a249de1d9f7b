"""Progress on standard error (tqdm): bars for loops, timers for stages.

Both draw only on a terminal, and never while :func:`silenced` is active
(the ``skpcd`` command's ``--quiet``). :func:`stage` reports a step that has
no items to count (reading a scene, the ground filter); the library marks
its long steps with it, and they show only inside :func:`reporting` (the
``skpcd`` command turns it on), so that a script calling the library sees
nothing it did not ask for.
"""

import contextlib
import sys
import threading

__all__ = ["progress", "reporting", "silenced", "stage", "steps"]

# seconds between two redraws of a stage's elapsed time
_TICK = 0.5
# set by reporting() and silenced()
_state = {"report": False, "silent": False, "loops": 0}


def _enabled(enabled, stream):
    if _state["silent"]:
        return False
    if enabled is None:
        return hasattr(stream, "isatty") and stream.isatty()
    return bool(enabled)


def progress(iterable, *, total=None, desc="", enabled=None, stream=None, leave=True):
    """Iterate over ``iterable`` while drawing a progress bar with its ETA.

    Parameters
    ----------
    iterable : iterable
        What to iterate over.
    total : int, default=None
        Number of items; taken from ``len(iterable)`` when possible.
    desc : str, default=""
        Label printed before the bar.
    enabled : bool, default=None
        Draw the bar. None draws it only when ``stream`` is a terminal.
        Never drawn inside :func:`silenced`.
    stream : file-like, default=None
        Where to draw; standard error by default.
    leave : bool, default=True
        Keep the finished bar on its line; False erases it.

    Returns
    -------
    iterator
        The items of ``iterable``, unchanged.
    """
    stream = sys.stderr if stream is None else stream
    if not _enabled(enabled, stream):
        return iter(iterable)
    from tqdm import tqdm

    return tqdm(
        iterable, total=total, desc=desc, file=stream, mininterval=0.2, leave=leave
    )


def steps(iterable, desc, *, total=None, stream=None):
    """Progress of a loop of the library (the tiles of a pass): a bar with
    its ETA, erased when the loop ends, drawn only inside
    :func:`reporting`, from the main thread, on a terminal. The
    :func:`stage` steps inside the loop (a ground filter per tile) are not
    drawn meanwhile.

    Parameters
    ----------
    iterable : iterable
        What to iterate over.
    desc : str
        Label printed before the bar.
    total : int, default=None
        Number of items; taken from ``len(iterable)`` when possible.
    stream : file-like, default=None
        Where to draw; standard error by default.

    Yields
    ------
    item
        The items of ``iterable``, unchanged.
    """
    stream = sys.stderr if stream is None else stream
    main = threading.current_thread() is threading.main_thread()
    if not (_state["report"] and main and _enabled(None, stream)):
        yield from iterable
        return
    _state["loops"] += 1
    try:
        yield from progress(
            iterable, total=total, desc=desc, enabled=True, stream=stream, leave=False
        )
    finally:
        _state["loops"] -= 1


@contextlib.contextmanager
def stage(desc, *, enabled=None, stream=None):
    """Report a step without items to count: its name and elapsed time.

    Parameters
    ----------
    desc : str
        What the step does, e.g. ``"ground (csf)"``.
    enabled : bool, default=None
        Draw. None draws only inside :func:`reporting` and when ``stream``
        is a terminal. Never drawn inside :func:`silenced`.
    stream : file-like, default=None
        Where to draw; standard error by default.

    Yields
    ------
    None
        The elapsed time is redrawn every half second while the step runs
        Python or numba code (a C extension that keeps the interpreter
        busy, such as the cloth simulation, freezes it until it returns);
        the line is erased when the step ends. Drawn from the main thread
        only (not by tiles run in threads), and not inside another stage or
        a :func:`steps` loop (the clusterings of the structures step).
    """
    stream = sys.stderr if stream is None else stream
    if enabled is None and not _state["report"]:
        enabled = False
    main = threading.current_thread() is threading.main_thread()
    if not main or _state["loops"] or not _enabled(enabled, stream):
        yield
        return
    _state["loops"] += 1  # the steps inside it are not drawn
    from tqdm import tqdm

    bar = tqdm(
        total=None,
        desc=desc,
        file=stream,
        bar_format="{desc}: {elapsed}",
        leave=False,
    )
    stop = threading.Event()

    def tick():
        while not stop.wait(_TICK):
            bar.refresh()

    ticker = threading.Thread(target=tick, name="skpcd-stage", daemon=True)
    ticker.start()
    try:
        yield
    finally:
        _state["loops"] -= 1
        stop.set()
        ticker.join()
        bar.close()


@contextlib.contextmanager
def reporting():
    """Show the library's :func:`stage` steps (on a terminal)."""
    before = _state["report"]
    _state["report"] = True
    try:
        yield
    finally:
        _state["report"] = before


@contextlib.contextmanager
def silenced(active=True):
    """Draw no bar and no stage while active (``--quiet``)."""
    before = _state["silent"]
    _state["silent"] = before or bool(active)
    try:
        yield
    finally:
        _state["silent"] = before
