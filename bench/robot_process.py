"""How a hand-written robot's process runs, and what its nodes share (`bench.concierge.robot`,
`bench.retail.robot`).

Its executor spins until Ctrl-C, or ``run_for`` s when > 0 (an operator's session); an uncaught
exception in a callback ends the process with code 1, its traceback printed, at once, its nodes
still listed (as a C++ node's abort ends it); with ``ROBOT_PYTHON_EXIT=1`` in the environment, as
Python ends it: the nodes deregister on the way out, then code 1. The harness's ``cpu`` and
``leak`` faults (`bench.handwritten.Robot.inject`) write
``FAULT_DIR/<process>.cpu`` / ``.leak``: the process then runs a hook of its own (a log line, its
own leak) and a CPU burner thread or, without a leak hook of its own, a generic leak.
"""

from __future__ import annotations

import functools
import os
import sys
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Header

PYTHON_EXIT = "ROBOT_PYTHON_EXIT"


def burn() -> None:
    """Keep one thread busy for good."""
    x = 0
    while True:
        for i in range(10_000):
            x = (x * 31 + i) % 1_000_003


def leak() -> None:
    """Grow by ~3 MB/s for good."""
    keep = []
    while True:
        keep.append(b"x" * 300_000)
        time.sleep(0.1)


def watch_faults(fault_dir: Path, process: str, hooks: dict[str, Callable[[], None]]) -> None:
    """Start the process's burner or leak once its fault file appears (polled every 0.5 s)."""
    done: set[str] = set()
    while True:
        time.sleep(0.5)
        for how in ("cpu", "leak"):
            if how not in done and (fault_dir / f"{process}.{how}").exists():
                done.add(how)
                hook = hooks.get(how)
                if hook:
                    hook()
                if how == "cpu":
                    threading.Thread(target=burn, daemon=True).start()
                elif how == "leak" and hook is None:
                    threading.Thread(target=leak, daemon=True).start()


def spin(ex: Executor, fault_dir: Path, process: str, run_for: float,
         hooks: dict[str, Callable[[], None]]) -> NoReturn:
    """Spin ``ex`` as the process's life (module docstring) and exit with its code."""
    threading.Thread(target=watch_faults, args=(fault_dir, process, hooks), daemon=True).start()
    if run_for > 0:
        threading.Timer(run_for, rclpy.try_shutdown).start()
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # an uncaught exception in a callback ends the process
        traceback.print_exc()
        sys.stderr.flush()
        if os.environ.get(PYTHON_EXIT):  # what Python's exit does to rclpy's nodes, then code 1
            for node in ex.get_nodes():
                node.destroy_node()
            rclpy.try_shutdown()
        os._exit(1)
    try:
        ex.shutdown(timeout_sec=1.0)
    except Exception:
        pass
    rclpy.try_shutdown()
    os._exit(0)


# What both robots' nodes use: stamps, headers, diagnostic_updater-like statuses, futures.

RELIABLE = QoSProfile(depth=10)


def stamp(t: float | None = None) -> TimeMsg:
    """``t`` (default now, wall time) as a ROS time."""
    t = time.time() if t is None else t
    sec = int(t)
    return TimeMsg(sec=sec, nanosec=int((t - sec) * 1e9))


def to_s(ts: TimeMsg) -> float:
    """A ROS time in seconds."""
    return ts.sec + ts.nanosec * 1e-9


def header(frame: str, t: float | None = None) -> Header:
    """A header of ``frame`` stamped ``t`` (default now)."""
    return Header(stamp=stamp(t), frame_id=frame)


def status(level: bytes, name: str, message: str, hardware_id: str = "", **values) -> DiagnosticStatus:
    """One diagnostic status, its values as strings."""
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


class Diagnostics:
    """A node's diagnostic_updater: ``fill()`` -> statuses published on /diagnostics every ``period`` s."""

    def __init__(self, node: Node, fill, period: float = 1.0, group=None) -> None:
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self.fill = fill
        node.create_timer(period, self.publish, callback_group=group)

    def publish(self) -> None:
        self.pub.publish(DiagnosticArray(header=header(""), status=list(self.fill())))


def single_threaded(*nodes: Node) -> SingleThreadedExecutor:
    """One SingleThreadedExecutor running ``nodes``: a process's, or a component container's."""
    ex = SingleThreadedExecutor()
    for n in nodes:
        ex.add_node(n)
    return ex


def wait_future(fut, timeout: float):
    """Wait for an rclpy future spun by another thread; its result or None on timeout."""
    ev = threading.Event()
    fut.add_done_callback(lambda _f: ev.set())
    if not ev.wait(timeout):
        return None
    return fut.result()


def on_shutdown_quiet(fn):
    """A thread's body that ends quietly when rclpy shuts down under it (Ctrl-C)."""

    @functools.wraps(fn)
    def run(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except Exception:
            if rclpy.ok():
                raise

    return run
