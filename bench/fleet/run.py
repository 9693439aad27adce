"""Run the simulated delivery fleet under the monitor: a healthy run and injected faults.

``python -m bench.fleet.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

Each run starts the fleet's processes (`bench.fleet.robot`) on a ROS_DOMAIN_ID of its own, the
in-process monitor with the default configuration, and, for a fault, injects it ``--warmup`` s
after the start (the monitor is not told) and monitors ``--post`` s more. The teleop joins 20 s
after the start, exits cleanly (code 0) 40 s later and its launcher starts it again 15 s after
that. Writes ``OUT/runs.jsonl`` (per run: the fault, its truth, every alert, the live ranking
with its scores, strict = the node, process = any node of its process) and ``OUT/summary.json``
(AC@1/AC@3 strict and process level, as in `bench.eval.metrics`; alerts in the healthy run and
before each injection), as `bench.fleet.run` does for the pick fleet.
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
from pathlib import Path

from bench.eval.metrics import hit_at, tie_blocks, to_blocks
from bench.eval.provenance import code_version
from stream_viz.testing import own_domain

# process -> its nodes (fully qualified), in the order they start
NODES = {
    "sim": ("/sim/world", "/sim/bridge", "/sim/map_server"),
    "r1_nav": ("/r1/localizer", "/r1/planner", "/r1/controller"),
    "r2_odom_filter": ("/r2/odom_filter",),
    "r2_localizer": ("/r2/localizer",),
    "r2_planner": ("/r2/planner",),
    "r2_controller": ("/r2/controller",),
    "dispatcher": ("/fleet/dispatcher",),
    "fleet": ("/fleet/manager", "/fleet/battery"),
    "tools": ("/tools/recorder", "/tools/diag"),
    "teleop": ("/r1/teleop",),
}
# fault -> (how, target node, its process): "file:<what>" writes the node's fault file, "kill"
# SIGKILLs the process, "cpu" starts the process's CPU burner, "leak" its memory leak
HOST = "the computer"
FAULTS = {
    "crash_r2_localizer": ("kill", "/r2/localizer", "r2_localizer"),
    "hang_r1_planner": ("file:hang", "/r1/planner", "r1_nav"),
    "degrade_r1_scan": ("file:degrade", "/sim/bridge", "sim"),
    "stale_r2_odom": ("file:stale", "/r2/odom_filter", "r2_odom_filter"),
    "slow_assign": ("file:slow_service", "/fleet/manager", "fleet"),
    "errlog_r1_controller": ("file:errlog", "/r1/controller", "r1_nav"),
    "leak_fleet": ("leak", "/fleet/manager", "fleet"),
    "stop_r1_tf": ("file:stop_tf", "/r1/localizer", "r1_nav"),
    "cpu_tools": ("cpu", "/tools/recorder", "tools"),
    "crash_sim": ("kill", "/sim/world", "sim"),
}
TELEOP_JOIN, TELEOP_RUN, TELEOP_AGAIN = 20.0, 40.0, 15.0  # joins before a fault at 40 s


class Fleet:
    """The fleet's processes; the teleop started, ended and started again by a launcher thread."""

    def __init__(self, fault_dir: Path, logs: Path) -> None:
        self.fault_dir, self.logs = fault_dir, logs
        self.procs: dict[str, subprocess.Popen] = {}
        self.pids: dict[int, str] = {}  # every pid a process ran as
        self.stop = threading.Event()

    def spawn(self, process: str, run_for: float = 0.0) -> subprocess.Popen:
        log = open(self.logs / f"{process}.log", "a")
        cmd = [sys.executable, "-m", "bench.fleet.robot", process, str(self.fault_dir), str(run_for)]
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                             cwd=Path(__file__).resolve().parents[2])
        self.procs[process] = p
        self.pids[p.pid] = process
        return p

    def start(self) -> None:
        for process in NODES:
            if process != "teleop":
                self.spawn(process)
        threading.Thread(target=self._teleop, daemon=True).start()

    def _teleop(self) -> None:
        if self.stop.wait(TELEOP_JOIN):
            return
        while not self.stop.is_set():
            p = self.spawn("teleop", TELEOP_RUN)
            while p.poll() is None and not self.stop.wait(0.2):
                pass
            if self.stop.wait(TELEOP_AGAIN):
                return

    def end(self) -> None:
        self.stop.set()
        for p in self.procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in self.procs.values():
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(5)

    def inject(self, fault: str) -> None:
        how, target, process = FAULTS[fault]
        if how == "kill":
            os.killpg(self.procs[process].pid, signal.SIGKILL)
        elif how in ("cpu", "leak"):
            (self.fault_dir / f"{process}.{how}").write_text("1")
        else:
            (self.fault_dir / target.strip("/").replace("/", ".")).write_text(how.split(":", 1)[1])


def run(fault: str | None, seconds_before: float, post: float, samples: Path | None = None) -> dict:
    """One run: the fleet, the monitor, ``fault`` injected ``seconds_before`` s after the start;
    every sample written to ``samples`` when given (`stream-viz replay` reads it)."""
    from stream_viz.config import load_config
    from stream_viz.monitor import Monitor

    tmp = Path(tempfile.mkdtemp(prefix="fleet_"))
    (tmp / "faults").mkdir()
    fleet = Fleet(tmp / "faults", tmp)
    print(f"  logs {tmp}", flush=True)
    mon = Monitor(load_config(None), db=tmp / "alerts.sqlite", viewer="none",
                  domain_id=int(os.environ["ROS_DOMAIN_ID"]), samples=samples)
    injected_at = None
    try:
        fleet.start()
        t0 = time.time()
        stop = threading.Event()
        if fault:
            def inject() -> None:
                nonlocal injected_at
                if not stop.wait(seconds_before):
                    fleet.inject(fault)
                    injected_at = time.time()
            threading.Thread(target=inject, daemon=True).start()
        mon.run(seconds_before + (post if fault else 0.0), stop)
        stop.set()
        alerts = mon.store.alerts()
        expand = _expand(mon.seen, fleet.pids)
    finally:
        report = mon.close()
        fleet.end()
    ranked = tie_blocks((rc["member"], rc["score"]) for rc in report["root_causes"])
    record = {"fault": fault, "t_start": t0, "injected_at": injected_at,
              "alerts": [{"t": round(a.t - t0, 2), "member": a.member, "plugin": a.plugin,
                          "severity": a.severity, "message": a.message} for a in alerts],
              "ranking": [list(b) if isinstance(b, tuple) else b for b in ranked][:10]}
    if fault:
        _, target, process = FAULTS[fault]
        blocks = to_blocks(ranked, expand)
        record["truth"] = {"strict": target, "process": sorted(NODES.get(process, (target,)))}
        record["before"] = [a for a in record["alerts"] if a["t"] < injected_at - t0 - 1.0] if injected_at \
            else record["alerts"]
        record["first_alert_s"] = min((a.t - injected_at for a in alerts if a.t >= injected_at - 1.0),
                                      default=None) if injected_at else None
        for level, truth in (("strict", {target}), ("process", set(NODES.get(process, (target,))))):
            record[level] = {f"AC@{k}": hit_at(blocks, truth, k) for k in (1, 3)}
    return record


def _expand(G, pids: dict[int, str]) -> dict[str, list[str]]:
    """Member → the fleet's nodes it stands for: a node itself, a topic its publishers, a service
    its servers, a process (every pid a process ran as) its nodes; from the monitor's model ``G``."""
    from stream_viz.model.queries import publishers, servers

    nodes = {n for ns in NODES.values() for n in ns}
    out: dict[str, list[str]] = {f"node:{n}": [n] for n in nodes}
    for m in G.nodes:
        if m.startswith("topic:"):
            out[m] = [p.removeprefix("node:") for p in publishers(G, m) if p.removeprefix("node:") in nodes]
        elif m.startswith("service:"):
            out[m] = [p.removeprefix("node:") for p in servers(G, m) if p.removeprefix("node:") in nodes]
    for pid, process in pids.items():
        out[f"process:{pid}"] = list(NODES[process])
    out.update({h: [HOST] for h in G.nodes if h.startswith("host:")})  # one computer
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--healthy", type=float, default=600.0, help="s of the healthy run (0: none)")
    ap.add_argument("--warmup", type=float, default=40.0,
                    help="s from the start to the injection (40: the teleop joined, goals under way)")
    ap.add_argument("--post", type=float, default=30.0, help="s monitored after the injection")
    ap.add_argument("--faults", default=",".join(FAULTS), help="comma list (none: no fault runs)")
    ap.add_argument("--out", type=Path, default=Path("bench/out/fleet"))
    ap.add_argument("--samples", type=Path, help="keep each run's samples here (<run>.jsonl.gz)")
    args = ap.parse_args(argv)
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
        rec = run(fault, args.healthy if fault is None else args.warmup, args.post, keep)
        rec["code"] = code_version()
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


if __name__ == "__main__":
    sys.exit(main())
