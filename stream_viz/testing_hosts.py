"""Several "computers" on one machine for tests and benchmarks: Linux namespaces, no root.

A `Lab` is a user namespace (``unshare -r``) whose network namespace holds a bridge; each `Host`
has its own network, mount, PID and UTS namespaces (so its PIDs collide with the others' and it
sees only its own ``/proc``, its own ``/dev/shm`` and host name) and a veth link on the bridge
with the address ``10.77.0.<i>/24`` and a multicast route, so ROS 2 discovers across hosts over
UDP as on a real robot's network. Commands run in a host through ``nsenter``. All traffic stays
inside the namespaces the lab created; ending the lab ends every process in it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

NSENTER = ("nsenter", "--preserve-credentials")

# A node publishing /<name>/out at 10 Hz, subscribed to /<other>/out of the names after it.
NODE = """
import sys
import rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node(sys.argv[1])
pub = n.create_publisher(String, '/' + sys.argv[1] + '/out', 10)
subs = [n.create_subscription(String, '/' + t + '/out', lambda m: None, 10) for t in sys.argv[2:]]
n.create_timer(0.1, lambda: pub.publish(String(data='x')))
print('ready', flush=True)
rclpy.spin(n)
"""

# The collector, sampled every argv[2] s; one JSON line per sample to argv[1]: the nodes',
# processes' and hosts' placement, the process tree, the exit events, the unreadable members.
OBSERVER = """
import json, sys, time
from stream_viz.collect.collector import Collector
out = open(sys.argv[1], 'w')
period = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
keep = ('host', 'pid', 'pid_status', 'alive', 'agent', 'process_unknown', 'unknown')
with Collector(topic_metrics=False) as c:
    while True:
        s = c.sample()
        G = s.graph
        members = {m: {k: d[k] for k in keep if k in d} for m, d in G.nodes(data=True)
                   if d['kind'] in ('node', 'process', 'host')}
        tree = [[u, v] for u, v, k in G.edges(keys=True) if k == 1]
        events = [[e.kind, e.member, e.level, e.t, e.text] for e in s.events if e.kind == 'exit']
        out.write(json.dumps({'t': s.t, 'members': members, 'tree': tree, 'events': events,
                              'unreadable': s.unreadable}) + '\\n')
        out.flush()
        time.sleep(period)
"""


def why_not() -> str | None:
    """Return why a lab cannot be made here (no ``unshare``/``nsenter``/``ip``, namespaces
    refused), or None when it can."""
    for exe in ("unshare", "nsenter", "ip"):
        if shutil.which(exe) is None:
            return f"`{exe}` is not installed"
    try:
        r = subprocess.run(["unshare", "-rn", "--fork", "-p", "--mount-proc", "-m", "true"],
                           capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"unshare failed: {e}"
    if r.returncode != 0:
        return f"unprivileged user/network/PID namespaces are not allowed here: {r.stderr.strip()}"
    return None


def _child(pid: int, timeout: float = 5.0) -> int:
    """The (first) child of ``pid``: the process ``unshare --fork`` or ``nsenter`` started."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
        except OSError:
            kids = []
        if kids:
            return int(kids[0])
        time.sleep(0.02)
    raise RuntimeError(f"process {pid} started no child within {timeout} s")


class Host:
    """One computer of a `Lab`: ``name`` (its host name), ``address``, the pid of its init, and
    the CPUs its commands may run on (``cpus``, all when None: a computer of its own cores)."""

    def __init__(self, lab: Lab, name: str, index: int, log: Path, cpus: Sequence[int] | None = None) -> None:
        self.lab, self.name, self.address, self.cpus = lab, name, f"10.77.0.{index}", cpus
        cmd = [*lab.enter(), "unshare", "-n", "-m", "-u", "-p", "--fork", "--mount-proc", "sh", "-c",
               f"hostname {name} && mount -t tmpfs tmpfs /dev/shm && exec sleep 100000"]
        self._outer = subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT,
                                       start_new_session=True)
        self.init = _child(self._outer.pid)
        self._wait_ready()
        veth = f"v{index}"
        lab.sh(f"ip link add {veth} type veth peer name eth0 netns {self.init} && "
               f"ip link set {veth} master br0 && ip link set {veth} up")
        self.sh(f"ip link set lo up && ip addr add {self.address}/24 dev eth0 && ip link set eth0 up && "
                "ip route add 224.0.0.0/4 dev eth0")

    def _wait_ready(self) -> None:
        # `hostname` has run once /proc/<init> is the final `sleep`, in namespaces of its own.
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            try:
                if Path(f"/proc/{self.init}/comm").read_text().strip() == "sleep":
                    return
            except OSError:
                pass
            time.sleep(0.02)
        raise RuntimeError(f"host {self.name} did not start")

    def enter(self) -> list[str]:
        """The command prefix that runs a command inside this host (on its CPUs)."""
        pin = ["taskset", "-c", ",".join(map(str, self.cpus))] if self.cpus is not None else []
        return [*NSENTER, "-t", str(self.init), "-U", "-n", "-m", "-p", "-u", f"--wd={os.getcwd()}", *pin]

    def sh(self, script: str) -> str:
        """Run a shell script in this host; return its output (raises when it fails)."""
        return subprocess.run([*self.enter(), "sh", "-c", script], check=True, capture_output=True,
                              text=True, timeout=20).stdout

    def run(self, argv: Sequence[str], env: dict[str, str], log: Path) -> subprocess.Popen:
        """Start ``argv`` in this host (output to ``log``); `inner` gives the started process."""
        return subprocess.Popen([*self.enter(), *argv], env=env, stdout=log.open("w"),
                                stderr=subprocess.STDOUT, start_new_session=True)

    def close(self) -> None:
        """End the host: its init's death kills every process of its PID namespace."""
        for pid in (self.init, self._outer.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self._outer.wait(timeout=10)


def inner(p: subprocess.Popen) -> int:
    """The pid (as this process sees it) of the command a `Host.run` started: nsenter's child."""
    return _child(p.pid)


class Lab:
    """A user namespace with a bridged network; `add` puts a computer on it.

    Parameters
    ----------
    workdir : Path
        Where the lab's own logs go.
    """

    def __init__(self, workdir: Path) -> None:
        self.workdir = workdir
        self.hosts: list[Host] = []
        self._hub = subprocess.Popen(["unshare", "-rn", "sleep", "100000"], start_new_session=True)
        deadline = time.monotonic() + 5.0
        while os.readlink(f"/proc/{self._hub.pid}/ns/net") == os.readlink("/proc/self/ns/net"):
            if time.monotonic() > deadline:
                raise RuntimeError("unshare -rn did not start")
            time.sleep(0.02)
        self.sh("ip link add br0 type bridge && ip link set br0 up && ip link set lo up")

    def enter(self) -> list[str]:
        """The command prefix that runs a command in the lab's user and network namespace."""
        return [*NSENTER, "-t", str(self._hub.pid), "-U", "-n"]

    def sh(self, script: str) -> None:
        """Run a shell script in the lab's network namespace (raises when it fails)."""
        subprocess.run([*self.enter(), "sh", "-c", script], check=True, capture_output=True, timeout=20)

    def add(self, name: str, cpus: Sequence[int] | None = None) -> Host:
        """Add a computer called ``name`` to the network, its commands held to ``cpus`` if given
        (the only per-computer CPU limit an unprivileged user has: no cgroups)."""
        host = Host(self, name, len(self.hosts) + 1, self.workdir / f"host_{name}.log", cpus)
        self.hosts.append(host)
        return host

    def close(self) -> None:
        """End every host and the lab."""
        for h in self.hosts:
            h.close()
        self._hub.kill()
        self._hub.wait(timeout=10)

    def __enter__(self) -> Lab:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Samples:
    """The `OBSERVER`'s JSON lines, read back as they come."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def all(self) -> list[dict]:
        """Every complete line so far."""
        if not self.path.exists():
            return []
        return [json.loads(x) for x in self.path.read_text().splitlines() if x.endswith("}")]

    def last(self) -> dict | None:
        """The newest sample, None before the first."""
        s = self.all()
        return s[-1] if s else None

    def until(self, pred: Callable[[dict], bool], timeout: float) -> dict:
        """Wait for a sample for which ``pred`` holds; return it (raises TimeoutError)."""
        deadline = time.monotonic() + timeout
        while True:
            s = self.last()
            if s is not None and pred(s):
                return s
            if time.monotonic() > deadline:
                raise TimeoutError(f"no such sample within {timeout} s (last: {s})")
            time.sleep(0.3)


def lab_env(domain: int) -> dict[str, str]:
    """The environment of ROS 2 processes in a lab: discovery over the lab's subnet."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", PYTHONUNBUFFERED="1")
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.pop("ROS_STATIC_PEERS", None)
    return env
