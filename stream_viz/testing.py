"""Helpers for tests and benchmarks that start real ROS 2 processes (as ``numpy.testing`` for numpy).

Not used by the monitor itself. Each run takes a ROS_DOMAIN_ID no other test or benchmark run on
this machine holds (`claim_domain`; `ros_env` for children, `own_domain` for this process), starts
its children in process groups of their own and always ends them (`Children`), polls for a
condition (`wait_for`) and removes Fast DDS shared-memory files of dead participants
(`shm_clean`). `EXE` is the installed ``stream-viz`` command beside this Python; `TALKER` a small
system to point the monitor at.
"""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import MutableMapping
from pathlib import Path

from stream_viz.viz.children import end_group

_LOCKS: list[int] = []


def claim_domain() -> int:
    """Take a ROS_DOMAIN_ID no other test or benchmark run on this machine holds (flock, released on exit)."""
    for domain in range(11, 100):
        fd = os.open(f"/tmp/stream_viz_test_domain_{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _LOCKS.append(fd)
        return domain
    raise RuntimeError("no free ROS_DOMAIN_ID in 11..99")


def ros_env(domain: int) -> dict[str, str]:
    """This process's environment for ROS 2 children on ``domain`` (localhost discovery only)."""
    env = dict(os.environ)
    _set_domain(env, domain)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def own_domain() -> int:
    """Claim a ROS_DOMAIN_ID and make it this process's (and its children's): set in ``os.environ``."""
    domain = claim_domain()
    _set_domain(os.environ, domain)
    return domain


def _set_domain(env: MutableMapping[str, str], domain: int) -> None:
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy, replaced by the discovery range


class Children:
    """Starts Python children in their own process group and ends them all."""

    def __init__(self, env: dict[str, str], workdir: Path) -> None:
        self.env, self.workdir, self.procs = env, workdir, []

    def python(self, code: str, *args: str, name: str = "child") -> subprocess.Popen:
        """Run ``code`` (dedented) in a new Python process; stdout/stderr go to a log file."""
        script = self.workdir / f"{name}_{len(self.procs)}.py"
        script.write_text(textwrap.dedent(code))
        return self.run([sys.executable, str(script), *args], name=name)

    def run(self, cmd: list[str], name: str = "child", env: dict[str, str] | None = None) -> subprocess.Popen:
        """Start ``cmd`` (environment ``env`` or the run's); stdout/stderr go to a log file."""
        log = open(self.workdir / f"{name}_{len(self.procs)}.log", "w")
        p = subprocess.Popen(cmd, env=env or self.env, stdout=log, stderr=subprocess.STDOUT,
                             start_new_session=True)
        self.procs.append(p)
        return p

    def end(self, p: subprocess.Popen, sig: int = signal.SIGINT, timeout: float = 5.0) -> None:
        """End ``p``'s process group with ``sig``, then SIGKILL if it is still there after ``timeout``."""
        end_group(p, sig, timeout)

    def end_all(self) -> None:
        """End every child started so far."""
        for p in self.procs:
            self.end(p)


def wait_for(pred, timeout: float = 10.0, period: float = 0.1):
    """Poll ``pred()`` until it returns something truthy; return it, or raise after ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"condition not met within {timeout} s")
        time.sleep(period)


def shm_clean() -> None:
    """Remove Fast DDS shared-memory files of dead participants (``fastdds shm clean``)."""
    exe = Path(sys.executable).with_name("fastdds")
    if exe.exists():
        subprocess.run([str(exe), "shm", "clean"], capture_output=True, timeout=60, check=False)


EXE = str(Path(sys.executable).with_name("stream-viz"))

# A talker and a listener in one process (the system the monitor is pointed at).
TALKER = """
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
rclpy.init()
a = rclpy.create_node("talker"); b = rclpy.create_node("listener")
pub = a.create_publisher(String, "/chatter", 10)
b.create_subscription(String, "/chatter", lambda m: None, 10)
a.create_timer(0.1, lambda: pub.publish(String(data="hi")))
ex = SingleThreadedExecutor(); ex.add_node(a); ex.add_node(b)
try:
    ex.spin()
except (KeyboardInterrupt, Exception):
    pass
"""
