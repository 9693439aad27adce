"""What the hand-written robots' runners share (`bench.station.run`, `bench.fleet.run`).

A robot is its processes (``process -> its nodes``), a module that runs one process
(``python -m MODULE PROCESS FAULT_DIR [RUN_FOR]``), one process an operator opens and closes (it
joins, exits with code 0 and is started again by a launcher thread) and its faults
(``fault -> (how, target node, its process)``). Each run starts the robot's processes on the
ROS_DOMAIN_ID of the runner, the in-process monitor with the default configuration, and, for a
fault, injects it ``--warmup`` s after the start (the monitor is not told) and monitors
``--post`` s more. Writes ``OUT/runs.jsonl`` (per run: the fault, its truth, every alert, the
live ranking with its scores, strict = the node, process = any node of its process) and
``OUT/summary.json`` (AC@1/AC@3 strict and process level, as in `bench.eval.metrics`; alerts in
the healthy run and before each injection).

Faults: ``kill`` SIGKILLs the process; ``cpu`` / ``leak`` write ``FAULT_DIR/<process>.<how>``
(the process starts its CPU burner or its leak); ``file:<what>`` writes ``<what>`` to the
target node's fault file (`Robot.fault_file`); `LaunchedRobot` adds launch's ``respawn:<word>``
(a crash loop) and ``restart:<word>`` (a redeployment with a new configuration); a robot adds its
own kinds in `Robot.inject`.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from bench.eval.metrics import hit_at, tie_blocks, to_blocks
from bench.eval.provenance import code_version
from stream_viz.testing import own_domain

HOST = "the computer"  # the truth of a fault of the computer itself: the host member
ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Design:
    """A hand-written robot: its module, processes, operator process and faults."""

    module: str  # runs one process: python -m MODULE PROCESS FAULT_DIR [RUN_FOR]
    nodes: dict[str, tuple[str, ...]]  # process -> its nodes (fully qualified)
    faults: dict[str, tuple[str, str, str]]  # fault -> (how, target node, its process)
    operator: str  # the process that joins late, exits cleanly and comes back
    join_s: float
    run_s: float
    again_s: float


SLACK_S = 1.0  # an alert this close before the injection is its sample's (sampled as it happened)

class Robot:
    """A robot's processes; its operator process started, ended and started again by a thread."""

    def __init__(self, design: Design, fault_dir: Path, logs: Path) -> None:
        self.design, self.fault_dir, self.logs = design, fault_dir, logs
        self.procs: dict[str, subprocess.Popen] = {}
        self.pids: dict[int, str] = {}  # every pid a process ran as
        self.transient: list[subprocess.Popen] = []  # short-lived ones beside (spawners, CLI tools)
        self.stop = threading.Event()

    def spawn(self, process: str, run_for: float = 0.0) -> subprocess.Popen:
        log = open(self.logs / f"{process}.log", "a")
        cmd = [sys.executable, "-m", self.design.module, process, str(self.fault_dir), str(run_for)]
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)
        self.procs[process] = p
        self.pids[p.pid] = process
        return p

    def start(self) -> None:
        for process in self.design.nodes:
            if process != self.design.operator:
                self.spawn(process)
        threading.Thread(target=self._operator, daemon=True).start()

    def _operator(self) -> None:
        d = self.design
        if self.stop.wait(d.join_s):
            return
        while not self.stop.is_set():
            p = self.spawn(d.operator, d.run_s)
            while p.poll() is None and not self.stop.wait(0.2):
                pass
            if self.stop.wait(d.again_s):
                return

    def end(self) -> None:
        """End the robot's processes and the short-lived ones beside them: Ctrl-C, then SIGKILL."""
        self.stop.set()
        every = [*self.procs.values(), *self.transient]
        for p in every:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in every:
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(5)

    def fault_file(self, target: str) -> Path:
        """The file the target node reads its fault from."""
        return self.fault_dir / target.rsplit("/", 1)[1]

    def inject(self, fault: str) -> None:
        how, target, process = self.design.faults[fault]
        if how == "kill":
            os.killpg(self.procs[process].pid, signal.SIGKILL)
        elif how in ("cpu", "leak"):
            (self.fault_dir / f"{process}.{how}").write_text("1")
        elif how.startswith("file:"):
            self.fault_file(target).write_text(how.split(":", 1)[1])
        else:
            raise ValueError(f"fault {fault}: unknown kind {how!r}")


class NamespacedRobot(Robot):
    """A robot whose nodes share base names across namespaces: a node's fault file is named by its
    namespace and name (``r1.planner``, ``arm.left.controller``)."""

    def fault_file(self, target: str) -> Path:
        return self.fault_dir / target.strip("/").replace("/", ".")


RESPAWN_DELAY_S = 1.0  # the launch file's respawn_delay


class LaunchedRobot(NamespacedRobot):
    """The hand-written robot plus two launch-file behaviours: ``respawn:<word>`` (the word goes to the
    node's fault file, the process dies by itself and is started again ``RESPAWN_DELAY_S`` after each
    exit) and ``restart:<word>`` (the word goes to the node's fault file, a redeployment ends the
    process with Ctrl-C and starts it again once, reading its new configuration)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._threads: list[threading.Thread] = []
        self._spawn_lock = threading.Lock()

    def inject(self, fault: str) -> None:
        how, target, process = self.design.faults[fault]
        kind, _, word = how.partition(":")
        if kind not in ("respawn", "restart"):
            super().inject(fault)
            return
        self.fault_file(target).write_text(word)
        body = self._respawn if kind == "respawn" else self._restart
        t = threading.Thread(target=body, args=(process,), daemon=True)
        t.start()
        self._threads.append(t)

    def _respawn(self, process: str) -> None:
        while not self.stop.is_set():
            p = self.procs[process]
            while p.poll() is None and not self.stop.wait(0.1):
                pass
            if self.stop.wait(RESPAWN_DELAY_S):
                return
            with self._spawn_lock:
                if self.stop.is_set():
                    return
                self.spawn(process)

    def _restart(self, process: str) -> None:
        p = self.procs[process]
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)
        try:
            p.wait(5)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(5)
        if self.stop.wait(RESPAWN_DELAY_S):
            return
        with self._spawn_lock:
            if not self.stop.is_set():
                self.spawn(process)

    def end(self) -> None:
        with self._spawn_lock:
            self.stop.set()
        for t in self._threads:
            t.join(7.0)
        super().end()


def run(robot: Robot, fault: str | None, seconds_before: float, post: float,
        samples: Path | None = None, healthy: Path | None = None) -> dict:
    """One run of ``robot`` (not started yet) under the monitor, ``fault`` injected
    ``seconds_before`` s after the start; every sample written to ``samples`` when given; the
    monitor started from the healthy run's database ``healthy`` when given (``--healthy``)."""
    from stream_viz.config import load_config
    from stream_viz.monitor import Monitor

    d = robot.design
    mon = Monitor(load_config(None), db=robot.logs / "alerts.sqlite", viewer="none",
                  domain_id=int(os.environ["ROS_DOMAIN_ID"]), samples=samples, healthy=healthy)
    injected_at = None
    try:
        robot.start()
        t0 = time.time()
        stop = threading.Event()
        if fault:
            def inject() -> None:
                nonlocal injected_at
                if not stop.wait(seconds_before):
                    robot.inject(fault)
                    injected_at = time.time()
            threading.Thread(target=inject, daemon=True).start()
        mon.run(seconds_before + (post if fault else 0.0), stop)
        stop.set()
        alerts = mon.store.alerts()
        expand = _expand(mon.seen, robot.pids, d.nodes)
    finally:
        report = mon.close()
        robot.end()
    ranked = tie_blocks((rc["member"], rc["score"]) for rc in report["root_causes"])
    record = {"fault": fault, "t_start": t0, "injected_at": injected_at,
              "alerts": [{"t": round(a.t - t0, 2), "member": a.member, "plugin": a.plugin,
                          "severity": a.severity, "message": a.message} for a in alerts],
              "ranking": [list(b) if isinstance(b, tuple) else b for b in ranked][:10]}
    if fault:
        _, target, process = d.faults[fault]
        blocks = to_blocks(ranked, expand)
        group = d.nodes.get(process, (target,))
        record["truth"] = {"strict": target, "process": sorted(group)}
        record["before"] = [a for a in record["alerts"]
                            if a["t"] < injected_at - t0 - SLACK_S] if injected_at else record["alerts"]
        record["first_alert_s"] = min((a.t - injected_at for a in alerts if a.t >= injected_at - SLACK_S),
                                      default=None) if injected_at else None
        for level, truth in (("strict", {target}), ("process", set(group))):
            record[level] = {f"AC@{k}": hit_at(blocks, truth, k) for k in (1, 3)}
    return record


def _expand(G, pids: dict[int, str], processes: dict[str, tuple[str, ...]]) -> dict[str, list[str]]:
    """Member → the robot's nodes it stands for: a node itself, a topic its publishers, a service
    its servers, a process (every pid a process ran as) its nodes, a host the computer; from the
    monitor's model ``G``."""
    from stream_viz.model.queries import publishers, servers

    nodes = {n for ns in processes.values() for n in ns}
    out: dict[str, list[str]] = {f"node:{n}": [n] for n in nodes}
    for m in G.nodes:
        if m.startswith("topic:"):
            out[m] = [p.removeprefix("node:") for p in publishers(G, m) if p.removeprefix("node:") in nodes]
        elif m.startswith("service:"):
            out[m] = [p.removeprefix("node:") for p in servers(G, m) if p.removeprefix("node:") in nodes]
    for pid, process in pids.items():
        out[f"process:{pid}"] = list(processes[process])
    out.update({h: [HOST] for h in G.nodes if h.startswith("host:")})  # one computer
    return out


def main(argv: list[str] | None, doc: str, name: str, make: type[Robot], design: Design,
         warmup: float, warmup_help: str) -> int:
    """The runner's command line (``--healthy --warmup --post --faults --out --samples
    --from-healthy``)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--healthy", type=float, default=600.0, help="s of the healthy run (0: none)")
    ap.add_argument("--warmup", type=float, default=warmup, help=warmup_help)
    ap.add_argument("--post", type=float, default=30.0, help="s monitored after the injection")
    ap.add_argument("--faults", default=",".join(design.faults), help="comma list (none: no fault runs)")
    ap.add_argument("--out", type=Path, default=Path(f"bench/out/{name}"))
    ap.add_argument("--samples", type=Path, help="keep each run's samples here (<run>.jsonl.gz)")
    ap.add_argument("--from-healthy", type=Path, metavar="RUN.sqlite",
                    help="start every run's monitor from this healthy run's database (stream-viz --healthy)")
    args = ap.parse_args(argv)
    code = code_version()  # the code this process loads now, not the checkout when a run ends
    own_domain()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.samples:
        args.samples.mkdir(parents=True, exist_ok=True)
    runs = []
    faults = [f for f in args.faults.split(",") if f and f != "none"]
    plan = ([None] if args.healthy > 0 else []) + faults
    for fault in plan:
        print(f"run {fault or 'healthy'}", flush=True)
        keep = args.samples / f"{fault or 'healthy'}.jsonl.gz" if args.samples else None
        tmp = Path(tempfile.mkdtemp(prefix=f"{name}_"))
        (tmp / "faults").mkdir()
        print(f"  logs {tmp}", flush=True)
        rec = run(make(design, tmp / "faults", tmp), fault, args.healthy if fault is None else args.warmup,
                  args.post, keep, args.from_healthy)
        rec["code"] = code
        if args.from_healthy:
            rec["healthy_from"] = str(args.from_healthy)
        runs.append(rec)
        with open(args.out / "runs.jsonl", "a") as f:
            f.write(json.dumps(rec) + "\n")
        print(f"  alerts {len(rec['alerts'])}  strict {rec.get('strict')}  process {rec.get('process')}",
              flush=True)
    faulty = [r for r in runs if r["fault"]]
    summary = {
        "healthy_alerts": sum(len(r["alerts"]) for r in runs if not r["fault"]),
        "alerts_before_injection": sum(len(r["before"]) for r in faulty),
        **{f"{lvl} AC@{k}": round(sum(r[lvl][f"AC@{k}"] for r in faulty) / len(faulty), 3)
           for lvl in ("strict", "process") for k in (1, 3) if faulty},
        "runs": len(runs),
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary))
    return 0
