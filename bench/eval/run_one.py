"""One live evaluation run: a system, an optional fault, the in-process monitor, everything recorded.

Run as ``python -m bench.eval.run_one --spec '<json>' --out DIR`` (one process per run, so CPU
time and peak memory are this run's alone). Writes ``DIR/run.json`` (rankings of every policy ×
method, the baseline, latencies, cost), ``DIR/metrics.csv`` and ``DIR/meta.json`` for the peers.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import psutil

from bench.eval.baseline import culprits, flag_times
from bench.eval.export import SKIP_TOPICS, service_name, wide_table
from bench.eval.metrics import tie_blocks
from bench.eval.provenance import code_version, machine
from bench.eval.suites import DEFAULT_TIMING, INJECT_PHASE, TIMING
from bench.eval.systems import expand_map, fault_reach, sink_watchlist, system_topology, truth_sets
from stream_viz.testing import own_domain

if TYPE_CHECKING:  # imported where used, once this process has its ROS_DOMAIN_ID
    from stream_viz.config import Config
    from stream_viz.demo.topology import Topology
    from stream_viz.monitor import Monitor
    from stream_viz.records import Alert


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--spec", required=True, help="JSON: system, fault, target, size, warmup, post, seed")
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)
    spec = json.loads(args.spec)
    args.out.mkdir(parents=True, exist_ok=True)
    record = run(spec, args.out)
    (args.out / "run.json").write_text(json.dumps(record, indent=1))
    return 0


def run(spec: dict, out: Path) -> dict:
    """Run ``spec`` live, then rank offline; write the peers' files to ``out``; return run.json's record."""
    domain = own_domain()  # no test run or other benchmark holds it
    code = code_version()  # the code this process loads, not the checkout when the run ends
    from stream_viz.config import load_config

    topo = system_topology(spec["system"], spec.get("seed", 0))
    config = load_config(None)
    live = _live(spec, topo, config, domain, out)
    mon = live.mon
    injected = dict(mon.injected or {})
    expand = expand_map(topo, live.pids)
    rankings = _rerank(mon, live.stored, live.report, live.anomalous, config, topo)
    series, times, services = _export_metrics(out / "metrics.csv", mon, live.pids)
    flags, rankings["baseline"] = _baseline(series, times, expand)
    _write_meta(out / "meta.json", topo, live.pids, expand, services, injected.get("t"))
    return _record(spec, domain, topo, live, injected, expand, rankings, flags, code)


@dataclasses.dataclass
class Live:
    """What the live part of a run leaves: the closed monitor, its results, the run's times and cost."""

    mon: Monitor
    report: dict  # the monitor's final report (stream-viz.report/v2)
    stored: list[Alert]
    pids: dict[str, str]  # process member -> the system's process name (every pid a group ever had)
    alive: dict[str, bool]
    ticks: list[dict]
    anomalous: set[str]
    t_start: float
    t_ready: float
    cpu_s: float
    wall_s: float


def _live(spec: dict, topo: Topology, config: Config, domain: int, out: Path) -> Live:
    """Start the system, inject the fault, monitor it; keep the alert database in ``out``."""
    from stream_viz.demo.robot import FaultSpec, Robot
    from stream_viz.monitor import Monitor

    w0, p0 = TIMING.get(spec["system"], DEFAULT_TIMING)
    warmup, post = float(spec.get("warmup", w0)), float(spec.get("post", p0))
    if spec.get("fault"):
        warmup += INJECT_PHASE * config.monitor.period
    fault = spec.get("fault")
    tmp = Path(tempfile.mkdtemp(prefix="stream_eval_"))
    me = psutil.Process()
    samples = out / "samples.jsonl.gz" if spec.get("samples") else None  # for `stream-viz replay`
    mon = Monitor(config, db=tmp / "alerts.sqlite", viewer="none", domain_id=domain, samples=samples)
    robot = Robot(env=dict(os.environ), topology=topo, run_dir=tmp / "robot")
    ticks: list[dict] = []
    anomalous: set[str] = set()  # members process monitoring flagged at some tick
    t_start = time.time()
    try:
        robot.start()
        robot.wait_ready(timeout=120.0 + 0.5 * len(topo.node_names()))
        t_ready = time.time()
        if fault:
            robot.inject(FaultSpec(fault, spec["target"], warmup, spec.get("size")))

        def on_tick() -> None:
            if mon.injected is None and fault:
                mon.injected = robot.injected() or None
            anomalous.update(mon.evidence)
            top = mon.engine.result().root_causes
            ticks.append(
                {
                    "t": time.time(),
                    "top": _tied(top)[:3],
                    "alerts": mon.n_alerts,
                    "rss": me.memory_info().rss,
                }
            )

        cpu0, wall0 = me.cpu_times(), time.monotonic()
        mon.run(warmup + post, threading.Event(), on_tick=on_tick)
        cpu1, wall1 = me.cpu_times(), time.monotonic()
        if fault and mon.injected is None:
            mon.injected = robot.injected() or None
        # a respawned group (the restart fault) ran as several processes: each pid is that group
        pids = {f"process:{pid}": g for g, history in robot.pid_history.items() for pid in history}
        stored = mon.store.alerts()  # the monitor keeps its alerts in the database only
        alive = robot.alive()
    finally:
        try:
            report = mon.close()
        finally:
            robot.stop()
    # Keep the alert database beside the results (`stream-viz analyze --db` reruns the RCA on it).
    for f in tmp.glob("alerts.sqlite*"):
        shutil.move(str(f), out / f.name)
    shutil.rmtree(tmp, ignore_errors=True)
    cpu = (cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)
    return Live(mon=mon, report=report, stored=stored, pids=pids, alive=alive, ticks=ticks,
                anomalous=anomalous, t_start=t_start, t_ready=t_ready, cpu_s=cpu, wall_s=wall1 - wall0)


def _rerank(mon: Monitor, stored: list[Alert], report: dict, anomalous: set[str], config: Config,
            topo: Topology) -> dict:
    """Every policy × method ranking of the run's alerts, the live one first (name -> members)."""
    from stream_viz.rca.engine import analyze
    from stream_viz.rca.settings import METHODS, POLICIES

    # Our rankings: live (what the user saw) and offline re-ranks of the same alerts; members of
    # equal score are tied (scored like a peer's multi-node member: expected AC@k).
    rankings = {"live": tie_blocks((rc["member"], rc["score"]) for rc in report["root_causes"])}
    evidence = {m: 1.0 for m in mon.evidence}
    w0 = {m for m, k in mon.seen.nodes(data="kind") if k == "process"} | anomalous | sink_watchlist(topo)
    for policy in POLICIES:
        for method in METHODS:
            s = dataclasses.replace(config.rca, policy=policy, method=method, top_k=30)
            t0 = time.perf_counter()
            res = analyze(mon.seen, stored, s, set(mon.watchlist.external), evidence or None)
            rankings[f"{policy}/{method}"] = _tied(res.root_causes)
            rankings.setdefault("_cost_ms", {})[f"{policy}/{method}"] = 1e3 * (time.perf_counter() - t0)
            # W_0 as `auto` builds it above its member limit (processes, process anomalies, the
            # configured members — here the system's outputs): on small systems `auto` watches
            # everything and the policy cannot make a difference.
            res = analyze(mon.seen, stored, s, w0, evidence or None)
            rankings[f"{policy}/{method} W0=outputs"] = _tied(res.root_causes)
    return rankings


def _tied(causes: list) -> list:
    """The RCA's root causes (best first) as a ranking whose members of equal score are tied."""
    return tie_blocks((rc.member, rc.score) for rc in causes)


def _export_metrics(path: Path, mon: Monitor, pids: dict[str, str]) -> tuple[dict, np.ndarray, dict]:
    """Write the metric series the monitor saw as the peers' table; return them, the times, the services."""
    from stream_viz.model.theta import SCHEMAS

    hist = mon.history
    members = [m for m in mon.seen.nodes if m in hist]
    series = {m: (hist.times(m), hist.values(m)) for m in members}
    times, columns, matrix, services = wide_table(series, SCHEMAS, pids)
    _write_csv(path, times, columns, matrix)
    return series, times, services


def _baseline(series: dict, times: np.ndarray, expand: dict[str, list[str]]) -> tuple[dict, list]:
    """The rule-based baseline from the topic rates: flag times, and its ranking of publishers."""
    from stream_viz.model.theta import SCHEMAS

    rate_j = SCHEMAS["topic"].index("rate_hz")
    rates = {
        m: (t, v[:, rate_j])
        for m, (t, v) in series.items()
        if m.startswith("topic:") and m not in SKIP_TOPICS and len(t)
    }
    t_end = float(times[-1]) if len(times) else time.time()
    flags = flag_times(rates, end=t_end)
    publishers = {m: ns for m, ns in expand.items() if m.startswith("topic:")}
    return flags, [list(x) for x in culprits(flags, publishers)]


def _write_meta(path: Path, topo: Topology, pids: dict[str, str], expand: dict[str, list[str]],
                services: dict, t_inj: float | None) -> None:
    """What the peers need beside the table: injection time, services and their call graph."""
    svc_edges = sorted(
        {(service_name(a, pids), service_name(b, pids)) for a, b, _ in topo.edges()}
        | {(service_name(p, pids), service_name(n, pids)) for p, g in pids.items() for n in expand.get(p, ())}
    )
    meta = {"inject_time": t_inj, "services": services, "service_edges": svc_edges}
    path.write_text(json.dumps(meta))


def _record(spec: dict, domain: int, topo: Topology, live: Live, injected: dict,
            expand: dict[str, list[str]], rankings: dict, flags: dict, code: dict) -> dict:
    """The run's record (``run.json``): truth, rankings, alerts, latencies, cost."""
    t_inj = injected.get("t")
    faulty = bool(spec.get("fault"))
    strict, proc = truth_sets(topo, spec["target"]) if faulty else (set(), set())
    alerts = [
        {"member": a.member, "plugin": a.plugin, "t": a.t, "severity": a.severity, "message": a.message[:160]}
        for a in live.stored
    ]
    after = [a for a in alerts if t_inj is not None and a["t"] >= t_inj]
    return {
        "spec": spec,
        "domain": domain,
        "nodes": len(topo.node_names()),
        "t_start": live.t_start,
        "t_ready": live.t_ready,
        "ready_s": live.t_ready - live.t_start,
        "injected": injected,
        "truth_strict": sorted(strict),
        "truth_process": sorted(proc),
        "reach": sorted(fault_reach(topo, spec["target"], live.pids)) if faulty else [],
        "expand": expand,
        "rankings": rankings,
        "ticks": live.ticks,
        "alerts": alerts,
        "baseline_flags": flags,
        "first_alert_s": (min(a["t"] for a in after) - t_inj) if after else None,
        "baseline_first_flag_s": (
            min((t for t in flags.values() if t >= t_inj), default=None) - t_inj
            if t_inj is not None and any(t >= t_inj for t in flags.values())
            else None
        ),
        "alerts_before_injection": sum(1 for a in alerts if t_inj is None or a["t"] < t_inj),
        "cpu_s": live.cpu_s,
        "wall_s": live.wall_s,
        "cpu_share": live.cpu_s / live.wall_s,
        "samples": live.mon.samples,
        "peak_rss_mb": max((x["rss"] for x in live.ticks), default=0) / 2**20,
        "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "loadavg": os.getloadavg(),
        "code": code,
        "machine": machine(),
        "alive_at_end": live.alive,
    }


def _write_csv(path: Path, times: np.ndarray, columns: list[str], matrix: np.ndarray) -> None:
    with open(path, "w") as f:
        f.write(",".join(["time", *columns]) + "\n")
        for i, t in enumerate(times):
            f.write(",".join([f"{t:.3f}", *(f"{x:.6g}" for x in matrix[i])]) + "\n")


if __name__ == "__main__":
    sys.exit(main())
