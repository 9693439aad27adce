"""Helper processes of the viewer side (headless viewer, served viewer, browser): ports and ending."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time


def free_port() -> int:
    """Return a TCP port free on loopback now (the caller's child binds it soon after)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def end_group(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> None:
    """End ``proc``'s process group with ``sig``, SIGKILL after ``timeout``; close its stderr pipe.

    By group: the ``rerun`` on PATH is a wrapper that starts the real binary as a child, and
    Chromium runs a dozen; stopping only the first process leaves the rest holding their ports.
    """
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass
    if not _group_gone(proc, timeout):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        _group_gone(proc, timeout)
    if proc.stderr:
        proc.stderr.close()


def _group_gone(proc: subprocess.Popen, timeout: float) -> bool:
    # The leader can exit before its children: wait for the whole group, so its ports are free.
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        proc.poll()  # reap the leader
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False
