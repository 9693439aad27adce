"""How ended processes ended: their exit codes, from the kernel's process events connector.

A process seen gone with its nodes still in the DDS graph looks like a crash whether it was
killed or called ``exit(0)`` without shutting ROS down (``os._exit``, a GUI toolkit's quit, a
launch file's ``sys.exit`` in a signal handler): the goodbye that removes its nodes at once was
never sent, and they stay listed until their lease ends. Only its parent reads its exit status.
Linux tells it to any listener with ``CAP_NET_ADMIN`` (the monitor run as root, as on many robots
and in most containers) through the netlink process events connector (``cn_proc``): one message
per exit with the status ``waitpid`` would give. `ExitCodes` listens in a thread of its own and
keeps the newest `KEEP`; without the capability (or off Linux) it says why and knows none.

`parse` and `describe_exit` are pure: one netlink message → the ``(pid, exit code)`` it reports,
if any; an exit code → words.
"""

from __future__ import annotations

import os
import signal
import socket
import struct
import threading
import time
from collections import OrderedDict

NETLINK_CONNECTOR = 11
CN_IDX_PROC = CN_VAL_PROC = 1
PROC_CN_MCAST_LISTEN = 1
PROC_EVENT_EXIT = 0x80000000
NLMSG_DONE = 3
KEEP = 4096  # exits remembered: a sample or two of the busiest machine's
_NLMSG = struct.Struct("=IHHII")  # len, type, flags, seq, pid
_CN_MSG = struct.Struct("=IIIIHH")  # idx, val, seq, ack, len, flags
_EVENT = struct.Struct("=IIQ")  # what, cpu, timestamp_ns
_EXIT = struct.Struct("=IIII")  # pid, tgid, exit_code (waitpid status), exit_signal


def exit_code(status: int) -> int:
    """The exit code of a ``waitpid`` status as `subprocess` gives it: ``exit(n)`` → n, killed by
    signal s → -s."""
    return -(status & 0x7F) if status & 0x7F else (status >> 8) & 0xFF


def describe_exit(code: int | None) -> str:
    """How a process ended, for an event's text: ``exited``, ``exited with code 1``, ``was killed
    by SIGKILL``."""
    if code is None:
        return "exited"
    if code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with code {code}"


def note_exit_code(code: int | None, level: str, still_listed: bool, data: dict) -> str:
    """Put a known exit ``code`` in an exit event's ``data`` and return the event's level: an
    ``exit(0)`` without ROS's goodbye leaves its nodes listed, but nothing crashed (info)."""
    if code is None:
        return level
    data["exit_code"] = code
    return "info" if code == 0 and still_listed else level


def stamp_ns(data: bytes) -> int:
    """When the kernel sent a process event (``CLOCK_MONOTONIC``, ns; `parse` checked the size)."""
    return _EVENT.unpack_from(data, _NLMSG.size + _CN_MSG.size)[2]


def parse(data: bytes) -> tuple[int, int] | None:
    """Return ``(pid, exit code)`` of a process exit in one netlink message, or None (another
    event, a thread's exit, a short message)."""
    head = _NLMSG.size + _CN_MSG.size
    if len(data) < head + _EVENT.size + _EXIT.size:
        return None
    what, _, _ = _EVENT.unpack_from(data, head)
    if what != PROC_EVENT_EXIT:
        return None
    pid, tgid, status, _ = _EXIT.unpack_from(data, head + _EVENT.size)
    if pid != tgid:
        return None  # a thread ended, not the process
    return pid, exit_code(status)


class ExitCodes:
    """Exit codes of the processes that end on this machine, as the kernel reports them.

    ``reason`` is None while listening, else why not (no ``CAP_NET_ADMIN``, not Linux).
    """

    def __init__(self) -> None:
        self._codes: OrderedDict[int, tuple[int, float]] = OrderedDict()  # pid → (code, when seen)
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self.reason: str | None = None
        try:
            sock = socket.socket(socket.AF_NETLINK, socket.SOCK_DGRAM, NETLINK_CONNECTOR)
            sock.bind((0, CN_IDX_PROC))
            op = struct.pack("=I", PROC_CN_MCAST_LISTEN)
            cn = _CN_MSG.pack(CN_IDX_PROC, CN_VAL_PROC, 0, 0, len(op), 0) + op
            sock.send(_NLMSG.pack(_NLMSG.size + len(cn), NLMSG_DONE, 0, 0, os.getpid()) + cn)
        except (OSError, AttributeError) as exc:
            self.reason = f"no process events from the kernel ({exc}; needs CAP_NET_ADMIN on Linux)"
            return
        self._sock = sock
        threading.Thread(target=self._listen, name="stream-viz-exit-codes", daemon=True).start()

    def _listen(self) -> None:
        sock = self._sock
        while sock is not None:
            try:
                data = sock.recv(4096)
            except OSError:  # closed, or the buffer overran (ENOBUFS): exits lost, go on
                if self._sock is None:
                    return
                continue
            got = parse(data)
            if got is None:
                continue
            # When it ended, by the kernel's clock: this thread may read it late on a busy monitor.
            ended = time.time() - max(0, time.monotonic_ns() - stamp_ns(data)) / 1e9
            with self._lock:
                self._codes[got[0]] = (got[1], ended)
                self._codes.move_to_end(got[0])
                while len(self._codes) > KEEP:
                    self._codes.popitem(last=False)

    def take(self, pid: int) -> int | None:
        """The exit code of process ``pid`` if its exit was seen (forgotten once taken: pids are
        reused), else None."""
        return self.take_exit(pid)[0]

    def take_exit(self, pid: int) -> tuple[int | None, float | None]:
        """``(exit code, when the kernel's event came, unix s)`` of process ``pid`` if its exit was
        seen (forgotten once taken), else ``(None, None)``."""
        with self._lock:
            return self._codes.pop(pid, (None, None))

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
