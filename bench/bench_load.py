"""Load and duration: the monitor on a large generated system for a long time, and an alert storm.

``duration``: starts a generated system (``stream_viz.demo.generated.generate(n)`` run by
``stream_viz.demo.robot.Robot``) on its own ROS_DOMAIN_ID and runs the real `Monitor` pipeline
(collector → plugins → alert store → RCA → recording) in this process, one sample per period,
recording per sample: elapsed time, step time, the monitor process's RSS and CPU share (all its
threads: the topic drain, the plugin workers), model size and alerts. Writes a CSV and prints a
summary per time slice (no growth = the last slice looks like the first).

``storm``: a flood plugin offering ``--rate`` alerts per second (one call per simulated second)
for ``--seconds`` through `PluginSet` → `AlertStore` (a real SQLite file) → `RcaEngine`, every
member watched, side by side with the plugin set's cap per call (default 200) and without a cap.
Counts what each stage passes on and sheds; "keeps up" means one second of alerts is handled in
less than one second of wall time.

Run: ``.venv/bin/python bench/bench_load.py duration --nodes 100 --minutes 8``
     ``.venv/bin/python bench/bench_load.py duration --nodes 0 --minutes 10 --save`` (healthy demo)
     ``.venv/bin/python bench/bench_load.py storm --rate 10000 --seconds 60``
The issue's figure: ``duration --nodes 500 --minutes 30 --rate 0.5 1 --per-process 25 --save``
(at the default 2-5 Hz and 8 nodes per process a 500-node system does not fit on 2 cores: docs/demo.md)
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import psutil

from stream_viz.testing import claim_domain

OUT = Path(__file__).parent / "out" / "load"


# --------------------------------------------------------------------------- duration

def run_duration(nodes: int, minutes: float, domain: int, period: float, save: bool,
                 history: int | None = None, rate: tuple[float, float] = (2.0, 5.0),
                 per_process: int = 8) -> None:
    from dataclasses import replace

    from stream_viz.config import load_config
    from stream_viz.demo.generated import generate
    from stream_viz.demo.robot import Robot
    from stream_viz.demo.topology import DEMO
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress

    OUT.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    # nodes = 0: the demo robot, fault-free (the healthy-run figures: false alerts, .rrd per hour)
    topo = generate(nodes, rate=rate, nodes_per_process=per_process) if nodes else DEMO
    robot = Robot(env=env, topology=topo).start()
    tag = (f"{nodes}n" if nodes else "demo") + (f"_h{history}" if history else "")
    csv_path = OUT / f"duration_{tag}.csv"
    db = OUT / f"duration_{tag}.sqlite"
    rrd = OUT / f"duration_{tag}.rrd" if save else None
    for f in [db, *(OUT.glob(f"duration_{tag}*.rrd") if rrd else ())]:
        f.unlink(missing_ok=True)
    me = psutil.Process()
    rows: list[dict[str, float]] = []
    try:
        robot.wait_ready(timeout=600)
        cfg = load_config(None)
        cfg = replace(cfg, monitor=replace(cfg.monitor, period=period,
                                           history=history or cfg.monitor.history))
        mon = Monitor(cfg, db=db, save=rrd, viewer="none", domain_id=domain,
                      progress=Progress(open(os.devnull, "w")))
        robot_procs = [psutil.Process(p.pid) for p in robot.procs.values()]
        start = time.monotonic()
        end = start + minutes * 60
        next_t = start
        cpu0, wall0 = sum(me.cpu_times()[:2]), time.monotonic()
        rcpu0 = _cpu(robot_procs)
        while time.monotonic() < end:
            t0 = time.perf_counter()
            mon.step()
            step = time.perf_counter() - t0
            now = time.monotonic()
            cpu1, rcpu1 = sum(me.cpu_times()[:2]), _cpu(robot_procs)
            kinds: dict[str, int] = {}
            for _, k in mon.seen.nodes(data="kind"):
                kinds[k] = kinds.get(k, 0) + 1
            rows.append({
                "elapsed_s": now - start, "step_ms": step * 1000, "rss_mb": me.memory_info().rss / 2**20,
                "cpu_pct": 100 * (cpu1 - cpu0) / max(now - wall0, 1e-9),
                "robot_cpu_pct": 100 * (rcpu1 - rcpu0) / max(now - wall0, 1e-9),
                "nodes": kinds.get("node", 0), "topics": kinds.get("topic", 0), "members": len(mon.seen),
                "alerts": mon.n_alerts, "rca_alerts": mon.engine.result().alerts,
            })
            cpu0, rcpu0, wall0 = cpu1, rcpu1, now
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
            if next_t < time.monotonic():
                next_t = time.monotonic()
        mon.close()
    finally:
        robot.stop()
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"[monitor] history = {cfg.monitor.history} samples per member")
    what = f"{nodes}-node generated system (rates {rate[0]}-{rate[1]} Hz, {per_process} nodes per process)" \
        if nodes else "demo robot, fault-free"
    _summary_duration(rows, what, minutes, period, csv_path, db, mon.recording_parts)


def _cpu(procs: list[psutil.Process]) -> float:
    total = 0.0
    for p in procs:
        try:
            for q in [p, *p.children(recursive=True)]:
                c = q.cpu_times()
                total += c.user + c.system
        except psutil.Error:
            pass
    return total


def _summary_duration(rows, what, minutes, period, csv_path, db, rrd_parts) -> None:
    print(f"\nduration: {what}, {minutes} min, period {period} s, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores")
    print(f"samples: {len(rows)}; model: {rows[-1]['nodes']} nodes, {rows[-1]['topics']} topics, "
          f"{rows[-1]['members']} members; alerts stored {rows[-1]['alerts']}")
    slices = max(1, min(8, int(minutes)))
    span = rows[-1]["elapsed_s"] / slices
    print(f"{'slice':>12} {'step ms p50':>11} {'p95':>7} {'max':>7} {'RSS MB':>8} {'CPU %':>6} "
          f"{'robot CPU %':>11} {'late':>5}")
    for i in range(slices):
        part = [r for r in rows if i * span <= r["elapsed_s"] < (i + 1) * span or
                (i == slices - 1 and r["elapsed_s"] >= i * span)]
        if not part:
            continue
        steps = sorted(r["step_ms"] for r in part)
        late = sum(1 for s in steps if s > period * 1000)
        print(f"{i * span / 60:5.1f}-{(i + 1) * span / 60:4.1f} min {steps[len(steps) // 2]:11.1f} "
              f"{steps[int(0.95 * (len(steps) - 1))]:7.1f} {steps[-1]:7.1f} "
              f"{statistics.mean(r['rss_mb'] for r in part):8.1f} "
              f"{statistics.mean(r['cpu_pct'] for r in part):6.1f} "
              f"{statistics.mean(r['robot_cpu_pct'] for r in part):11.1f} {late:5d}")
    rss = [r["rss_mb"] for r in rows]
    hours = rows[-1]["elapsed_s"] / 3600
    sizes = f"db {db.stat().st_size / 2**20:.2f} MB"
    if rrd_parts:
        mb = sum(p.stat().st_size for p in rrd_parts) / 2**20
        sizes += f", rrd {mb:.1f} MB in {len(rrd_parts)} parts ({mb / hours:.1f} MB/h)"
    print(f"alerts stored: {rows[-1]['alerts']} ({rows[-1]['alerts'] / hours:.1f}/h)")
    print(f"RSS: start {rss[0]:.1f} MB, max {max(rss):.1f} MB, end {rss[-1]:.1f} MB; {sizes}")
    print(f"CSV: {csv_path}")


# --------------------------------------------------------------------------- storm

def run_storm(rate: int, seconds: int, members: int) -> None:
    from stream_viz.config import load_config
    from stream_viz.detect.api import Plugin
    from stream_viz.detect.plugin_set import PluginSet
    from stream_viz.detect.store import AlertStore
    from stream_viz.model.diff import GraphDiff
    from stream_viz.model.history import History
    from stream_viz.rca.engine import RcaEngine
    from stream_viz.viz.sample import chain_graph

    G = chain_graph(members)
    ids = sorted(G.nodes)

    class Flood(Plugin):
        name = "flood"
        kinds = ("node", "topic", "process")

        def check(self, ctx):
            sev = ("warn", "error")
            return [ctx.alert(ids[i % len(ids)], sev[i % 2], f"storm {i}") for i in range(rate)]

    print(f"\nstorm: {rate} alerts/s offered for {seconds} s (one call per simulated second), "
          f"{len(ids)} members all watched, {os.cpu_count()} cores")
    head = (f"{'cap/call':>9} {'offered':>9} {'shed cap':>9} {'passed':>8} {'rows':>6} {'episodes':>8} "
            f"{'rca saw':>8} {'plugin ms':>9} {'store ms':>8} {'rca ms':>7} {'rca ms last10':>13} "
            f"{'keeps up':>8} {'flood probs':>11}")
    print(head)
    for cap in (200, rate):
        store = AlertStore(Path(tempfile.mkdtemp()) / "storm.sqlite")
        ps = PluginSet([(Flood(), "flood", "bench")], max_alerts_per_call=cap, timeout_s=30.0)
        eng = RcaEngine(load_config(None).rca, watchlist=set(ids))
        hist = History(maxlen=10)
        t0 = time.time()
        passed = rows = shed = probs = 0
        tp, ts, tr, rca_each = [], [], [], []
        for i in range(seconds):
            t = t0 + i
            a = time.perf_counter()
            fired, problems = ps.run(t, G, ids, hist, (), GraphDiff())
            b = time.perf_counter()
            kept = store.add(fired)
            store.add_problems(problems, t=t)
            c = time.perf_counter()
            eng.update(G, kept)
            d = time.perf_counter()
            tp.append(b - a)
            ts.append(c - b)
            tr.append(d - c)
            rca_each.append(d - c)
            passed += len(fired)
            rows += len(kept)
            for p in problems:
                if p.kind == "flood":
                    probs += 1
                    shed += p.count
        ps.close()
        episodes = len(store.episodes())
        stored_probs = sum(1 for p in store.problems() if p["kind"] == "flood")
        store.close()
        total = [x + y + z for x, y, z in zip(tp, ts, tr, strict=True)]
        keeps = sum(1 for x in total if x < 1.0) == len(total)
        print(f"{cap:9d} {rate * seconds:9d} {shed:9d} {passed:8d} {rows:6d} {episodes:8d} "
              f"{eng.result().alerts:8d} {1000 * statistics.mean(tp):9.1f} {1000 * statistics.mean(ts):8.1f} "
              f"{1000 * statistics.mean(tr):7.1f} {1000 * statistics.mean(rca_each[-10:]):13.1f} "
              f"{'yes' if keeps else 'NO':>8} {stored_probs:11d}")
        assert passed + shed == rate * seconds, "every offered alert is either passed on or counted as shed"
        assert stored_probs == probs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    d = sub.add_parser("duration")
    d.add_argument("--nodes", type=int, default=100,
                   help="generated system size; 0 = the demo robot, fault-free")
    d.add_argument("--rate", type=float, nargs=2, default=(2.0, 5.0), metavar=("LO", "HI"),
                   help="source timer rates of the generated system, Hz")
    d.add_argument("--per-process", type=int, default=8, help="nodes per process of the generated system")
    d.add_argument("--minutes", type=float, default=8.0)
    d.add_argument("--domain", type=int, help="ROS_DOMAIN_ID (default: one no test run holds)")
    d.add_argument("--period", type=float, default=1.0)
    d.add_argument("--save", action="store_true", help="also write the .rrd (as `monitor --save`)")
    d.add_argument("--history", type=int, help="[monitor] history (samples kept per member)")
    s = sub.add_parser("storm")
    s.add_argument("--rate", type=int, default=10_000)
    s.add_argument("--seconds", type=int, default=60)
    s.add_argument("--members", type=int, default=100, help="nodes of the synthetic graph")
    args = ap.parse_args()
    if args.what == "duration":
        if args.domain is None:
            args.domain = claim_domain()
        run_duration(args.nodes, args.minutes, args.domain, args.period, args.save, args.history,
                     tuple(args.rate), args.per_process)
    else:
        run_storm(args.rate, args.seconds, args.members)


if __name__ == "__main__":
    main()
