"""A command started in a child process, as from a terminal, returned once
it has reached a given moment (the tests of interrupts share it)."""

import os
import signal
import subprocess
import time


def start_until(args, marker, env, what):
    """Start ``args`` (stdout discarded, stderr kept) with SIGINT handled
    as from a terminal: a pytest-xdist worker ignores SIGINT, and a command
    started from there would keep ignoring it. Returns the process once it
    has written ``marker``; fails with ``what`` after 120 s, or with its
    stderr if it ended first."""
    proc = subprocess.Popen(
        args,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **env},
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not marker.exists():
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline, what
        time.sleep(0.01)
    return proc
