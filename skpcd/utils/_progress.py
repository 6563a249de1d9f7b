"""A minimal progress bar on standard error, silent when not on a terminal."""

import sys
import time

__all__ = ["progress"]


def progress(iterable, *, total=None, desc="", enabled=None, stream=None):
    """Yield from ``iterable`` while drawing a one-line progress bar.

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
    stream : file-like, default=None
        Where to draw; standard error by default.

    Yields
    ------
    item
        The items of ``iterable``, unchanged.
    """
    stream = sys.stderr if stream is None else stream
    if enabled is None:
        enabled = hasattr(stream, "isatty") and stream.isatty()
    if not enabled:
        yield from iterable
        return
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    start = time.perf_counter()
    last = 0.0
    done = 0

    def draw(final=False):
        elapsed = time.perf_counter() - start
        if total:
            filled = int(30 * done / total)
            bar = "#" * filled + "-" * (30 - filled)
            stream.write(f"\r{desc} [{bar}] {done}/{total} {elapsed:5.1f}s")
        else:
            stream.write(f"\r{desc} {done} {elapsed:5.1f}s")
        if final:
            stream.write("\n")
        stream.flush()

    for item in iterable:
        yield item
        done += 1
        now = time.perf_counter()
        if now - last > 0.1:
            draw()
            last = now
    draw(final=True)
