"""Start, observe and stop the demo robot (or a generated system): one OS process per group."""

from __future__ import annotations

import atexit
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from stream_viz.demo.child import WATCHDOG
from stream_viz.demo.faults import FAULTS, FaultSpec
from stream_viz.demo.topology import DEMO, GroupSpec, Topology
from stream_viz.errors import DemoError

__all__ = ["FAULTS", "FaultSpec", "Robot", "shm_clean"]

RESPAWN_DELAY = 1.0  # s between a respawning group's exit and its new process (launch's respawn_delay)


def shm_clean() -> None:
    """Remove Fast DDS shared-memory files of dead participants (``fastdds shm clean``)."""
    exe = Path(sys.executable).with_name("fastdds")
    if exe.exists():
        try:
            subprocess.run([str(exe), "shm", "clean"], capture_output=True, timeout=60, check=False)
        except (OSError, subprocess.TimeoutExpired):
            pass


class Robot:
    """The processes of a :class:`Topology`, with an optional fault injected at a chosen time.

    Parameters
    ----------
    env : dict, optional
        Environment of the children (default: ``os.environ``); set ``ROS_DOMAIN_ID`` here.
    fault : FaultSpec, optional
        What to inject, into which node, how many seconds after :meth:`start`.
    topology : Topology
        The system to run (default: the demo robot).
    run_dir : path, optional
        Where logs, ready and injection files go (default: a temporary directory removed by stop).
    """

    def __init__(self, env: dict | None = None, fault: FaultSpec | None = None,
                 topology: Topology = DEMO, run_dir: str | Path | None = None) -> None:
        if fault is not None:
            topology.check_fault(fault)
        self.env = dict(os.environ if env is None else env)
        self.fault, self.topology = fault, topology
        self._own_dir = run_dir is None
        self.run_dir = Path(run_dir) if run_dir else None
        self.procs: dict[str, subprocess.Popen] = {}
        self.hung: set[str] = set()  # groups whose teardown hung: their watchdog ended them (`stop`)
        self.started_at: float | None = None
        self.fault_at: float | None = None
        self._injected: dict = {}
        self._cmd: list[str] = []
        self._stopping = threading.Event()
        self._supervisor: threading.Thread | None = None
        self.pid_history: dict[str, list[int]] = {}  # group -> every pid it ran as (respawns add more)

    # -- life cycle -------------------------------------------------------------------------
    def start(self) -> Robot:
        """Start one process per group (own session each); returns self."""
        if self.procs:
            raise DemoError("robot already started")
        if self.run_dir is None:
            self.run_dir = Path(tempfile.mkdtemp(prefix="stream_viz_demo_"))
        self.run_dir.mkdir(parents=True, exist_ok=True)
        topo_file = self.topology.save(self.run_dir / "topology.json")
        self.started_at = time.time()
        cmd_fault: list[str] = []
        if self.fault is not None:
            self.fault_at = self.started_at + self.fault.at
            cmd_fault = ["--fault", self.fault.fault, "--target", self.fault.target,
                         "--at", repr(self.fault_at)]
            if self.fault.size is not None:
                cmd_fault += ["--size", repr(self.fault.size)]
        self._cmd = [sys.executable, "-m", self.topology.entry, "--topology", str(topo_file),
                     "--run-dir", str(self.run_dir), *cmd_fault]
        atexit.register(self.stop)
        try:
            for g in self.topology.groups:
                self._spawn(g)
        except OSError as exc:
            self.stop()
            raise DemoError(f"cannot start group {g.name!r}: {exc}") from exc
        if any(g.respawn for g in self.topology.groups):
            self._supervisor = threading.Thread(target=self._respawn, daemon=True, name="respawn")
            self._supervisor.start()
        return self

    def _spawn(self, g: GroupSpec) -> None:
        """Start (or restart) the process of group ``g``; its output is appended to ``<group>.log``."""
        with open(self.run_dir / f"{g.name}.log", "a") as log:
            p = subprocess.Popen([*self._cmd, "--group", g.name], env=self.env, stdout=log,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        self.procs[g.name] = p
        self.pid_history.setdefault(g.name, []).append(p.pid)

    def _respawn(self) -> None:
        """Restart every ``respawn`` group whose process has exited, until :meth:`stop`."""
        while not self._stopping.wait(0.2):
            for g in self.topology.groups:
                if g.respawn and self.procs[g.name].poll() is not None:
                    if self._stopping.wait(RESPAWN_DELAY):
                        return
                    try:
                        self._spawn(g)
                    except OSError:
                        pass  # tried again on the next round

    def inject(self, fault: FaultSpec) -> float:
        """Inject ``fault`` ``fault.at`` s from now into the running system; returns that unix time.

        One fault per run: DemoError if one was given to the constructor or injected already.
        """
        self.topology.check_fault(fault)
        if not self.procs or self.run_dir is None:
            raise DemoError("start the robot before injecting a fault")
        if self.fault is not None:
            raise DemoError(f"a fault is already set for this run: {self.fault}")
        self.fault, self.fault_at = fault, time.time() + fault.at
        tmp = self.run_dir / "fault.json.tmp"
        tmp.write_text(json.dumps({"fault": fault.fault, "target": fault.target, "at": self.fault_at,
                                   "size": fault.size}))
        os.replace(tmp, self.run_dir / "fault.json")
        return self.fault_at

    def wait_ready(self, timeout: float = 30.0) -> None:
        """Block until every process has created its nodes and spins (DemoError on death/timeout)."""
        deadline = time.monotonic() + timeout
        waiting = set(self.procs)
        while waiting:
            for g in list(waiting):
                if (self.run_dir / f"{g}.ready").exists():
                    waiting.discard(g)
                elif self.procs[g].poll() is not None:
                    raise DemoError(f"group {g!r} exited with {self.procs[g].returncode} before ready:\n"
                                    f"{self.log_tail(g)}")
            if waiting and time.monotonic() > deadline:
                raise DemoError(f"groups not ready after {timeout:.0f} s: {', '.join(sorted(waiting))}")
            if waiting:
                time.sleep(0.05)

    def stop(self, timeout: float = 8.0) -> None:
        """SIGINT every process group, SIGKILL what is left after ``timeout``, clean DDS shared memory.

        ``timeout`` outlasts a process's own watchdog (`child.end_process`: 5 s after it sees the
        signal), so a process slow to shut down on a loaded machine still ends itself, with code 0.
        """
        atexit.unregister(self.stop)
        self._stopping.set()
        if self._supervisor is not None:
            self._supervisor.join()
        live = [p for p in self.procs.values() if p.poll() is None]
        for p in live:
            _killpg(p.pid, signal.SIGINT)
        deadline = time.monotonic() + timeout
        for p in live:
            try:
                p.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        for p in self.procs.values():
            if p.poll() is None:
                _killpg(p.pid, signal.SIGKILL)
                p.wait(5)
        if self.procs:
            shm_clean()
        self.hung = {g for g, p in self.procs.items()
                     if p.returncode == 1 and WATCHDOG in self.log_tail(g, 200)}
        if self._own_dir and self.run_dir is not None:
            shutil.rmtree(self.run_dir, ignore_errors=True)
            self.run_dir = None

    def __enter__(self) -> Robot:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- what runs --------------------------------------------------------------------------
    def pids(self) -> dict[str, int]:
        """Group name → pid of its process."""
        return {g: p.pid for g, p in self.procs.items()}

    def node_pids(self) -> dict[str, int]:
        """Node fqn → pid of the process hosting it."""
        pids = self.pids()
        return {n.name: pids[g.name] for g in self.topology.groups for n in g.nodes if g.name in pids}

    def alive(self) -> dict[str, bool]:
        """Group name → whether its process still runs."""
        return {g: p.poll() is None for g, p in self.procs.items()}

    def injected(self) -> dict:
        """``{"fault", "target": "node:/..", "t": unix s}`` once the fault is injected, else ``{}``."""
        if self.run_dir is None or self._injected:
            return dict(self._injected)
        try:
            data = json.loads((self.run_dir / "injected.json").read_text())
        except (OSError, ValueError):
            return {}
        self._injected = {k: data[k] for k in ("fault", "target", "t")}
        return dict(self._injected)

    def log_tail(self, group: str, lines: int = 20) -> str:
        """The last ``lines`` of a group's output (stdout + stderr)."""
        try:
            return "\n".join((self.run_dir / f"{group}.log").read_text().splitlines()[-lines:])
        except (OSError, TypeError):
            return ""


def _killpg(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass
