"""The monitor's own CPU per sample against system size, replayed; the RCA update at ~1,000 alerts.

For each size, a generated system (`stream_viz.demo.generated`) is recorded without running it
(`stream_viz.demo.synthetic`: the collector's `build_model` on made-up readings, one sample a
second; at ``--crash-at`` the process whose loss silences the most topics is killed), written as
a samples file, then replayed through the real `Monitor` (default configuration, a ``.rrd``
written to a temporary file, plugins isolated with the replay's deadline) as fast as it goes.

Measured: process CPU time (``time.process_time``: every thread, not wall time) around each step's
call in `Monitor.step` — record, detect, store, diagnose, show (and reading the sample from the
file, which is the replay's cost, not the monitor's) — per sample, before and after the crash;
the whole loop's process CPU per sample (the background threads' work between steps included);
the slope (main-loop CPU per member at the largest size / at the smallest); and the diagnose step
once ~1,000 alerts are stored. Prints markdown tables; figures go into docs/replay.md.

    .venv/bin/python bench/bench_replay.py                         # 25, 100, 250, 500, 1000 nodes
    .venv/bin/python bench/bench_replay.py --sizes 25 100 --samples 60 --crash-at 30
    .venv/bin/python bench/bench_replay.py --replay run.jsonl.gz    # a real recording instead
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

STEPS = (("read", "collector", "sample"), ("record", "shadow", "record"), ("detect", "detector", "detect"),
         ("store", "store", "add_sample"), ("diagnose", "engine", "update"), ("show", "view", "update"))
MONITOR_STEPS = ("record", "detect", "store", "diagnose", "show")


def record(nodes: int, samples: int, crash_at: int, path: Path) -> tuple[int, float, str]:
    """Write the synthetic recording of a ``nodes``-node system; return its members, the writer's
    CPU per sample (encode + compress, ms) and the crashed process."""
    from stream_viz.collect.samples_file import SampleEncoder, SamplesWriter
    from stream_viz.demo.generated import generate
    from stream_viz.demo.synthetic import Crash, silenced
    from stream_viz.demo.synthetic import samples as synthesise

    topo = generate(nodes)
    group = max((g.name for g in topo.groups), key=lambda g: (len(silenced(topo, g)), g))
    writer = SamplesWriter(path, {"started_at": 1.7e9 - 1, "generated": topo.name, "crash": group})
    encoder, cpu, members = SampleEncoder(), 0.0, 0
    for s in synthesise(topo, samples, Crash(group, crash_at)):
        t0 = time.process_time()
        writer.write(s)
        encoder.encode(s)
        cpu += (time.process_time() - t0) / 2  # written once, encoded once more: half is one write
        members = max(members, s.graph.number_of_nodes())
    writer.close()
    return members, 1e3 * cpu / samples, group


def replay(path: Path, workdir: Path, crash_at: int | None, config: Path | None = None,
           after: Callable[[Any, int], None] | None = None) -> dict:
    """Replay ``path`` through a real Monitor, timing each step; return what was measured.

    ``after(monitor, i)`` is called after sample ``i`` (untimed)."""
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.commands.replay import PLUGIN_TIMEOUT_S, replay_config
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress

    source = ReplayCollector(path)
    mon = Monitor(replay_config(config, source.header), db=workdir / "a.sqlite", save=workdir / "r.rrd",
                  collector=source, started_at=source.header.get("started_at"),
                  plugin_timeout_s=PLUGIN_TIMEOUT_S, progress=Progress(open(os.devnull, "w")))
    cpu: dict[str, list[float]] = {name: [] for name, _, _ in STEPS}
    for name, owner, method in STEPS:
        obj = getattr(mon, owner)
        setattr(obj, method, _timed(getattr(obj, method), cpu[name]))
    loop, alerts, members = [], [], []
    while not source.done:
        t0 = time.process_time()
        mon.step()
        loop.append(time.process_time() - t0)
        alerts.append(mon.n_alerts)
        members.append(mon.seen.number_of_nodes())
        if after is not None:
            after(mon, len(loop) - 1)
    nodes = sum(1 for _, k in mon.seen.nodes(data="kind") if k == "node")
    report = mon.close()
    return {"cpu": cpu, "loop": loop, "alerts": alerts, "members": members, "nodes": nodes,
            "causes": [rc["member"] for rc in report["root_causes"][:8]], "crash_at": crash_at,
            "size": path.stat().st_size, "report": report}


def _timed(fn: Callable, into: list[float]) -> Callable:
    def timed(*a, **kw):
        t0 = time.process_time()
        try:
            return fn(*a, **kw)
        finally:
            into.append(time.process_time() - t0)

    return timed


def _ms(xs: list[float]) -> float:
    return 1e3 * statistics.fmean(xs) if xs else float("nan")


def phases(run: dict, warmup: int = 5) -> dict[str, slice]:
    """The healthy samples (after a warm-up) and the faulted ones."""
    n, at = len(run["loop"]), run["crash_at"]
    if at is None or at >= n:
        return {"all": slice(warmup, n)}
    return {"healthy": slice(warmup, at), "faulted": slice(at, n)}


def table(runs: list[tuple[int, dict]]) -> str:
    head = ("| nodes | members | phase | " + " | ".join(MONITOR_STEPS) + " | main loop | per member | "
            "whole step, all threads | read (replay) |")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for nodes, run in runs:
        for phase, sl in phases(run).items():
            steps = [_ms(run["cpu"][s][sl]) for s in MONITOR_STEPS]
            main = sum(steps)
            members = statistics.fmean(run["members"][sl])
            rows.append(f"| {nodes} | {members:.0f} | {phase} | " + " | ".join(f"{x:.1f}" for x in steps)
                        + f" | **{main:.1f}** | {1e3 * main / members:.1f} µs | "
                        f"{_ms(run['loop'][sl]) - _ms(run['cpu']['read'][sl]):.1f} | "
                        f"{_ms(run['cpu']['read'][sl]):.1f} |")
    return "\n".join(rows)


def slope(runs: list[tuple[int, dict]]) -> str:
    out = []
    for phase in ("healthy", "faulted", "all"):
        per = []
        for _, run in runs:
            sl = phases(run).get(phase)
            if sl is None:
                continue
            main = sum(_ms(run["cpu"][s][sl]) for s in MONITOR_STEPS)
            per.append((statistics.fmean(run["members"][sl]), main / statistics.fmean(run["members"][sl])))
        if len(per) >= 2:
            (m0, c0), (m1, c1) = per[0], per[-1]
            out.append(f"{phase}: main-loop CPU per member {1e3 * c1:.1f} µs at {m1:.0f} members / "
                       f"{1e3 * c0:.1f} µs at {m0:.0f} = {c1 / c0:.2f} (≤ 1: linear or better)")
    return "\n".join(out)


def step_slopes(runs: list[tuple[int, dict]]) -> str:
    """Per step: the cost ratio largest/smallest size over the member ratio (1: linear)."""
    (_, a), (_, b) = runs[0], runs[-1]
    sa, sb = phases(a).get("faulted", phases(a).get("all")), phases(b).get("faulted", phases(b).get("all"))
    ratio = statistics.fmean(b["members"][sb]) / statistics.fmean(a["members"][sa])
    parts = []
    for s in MONITOR_STEPS:
        grow = _ms(b["cpu"][s][sb]) / _ms(a["cpu"][s][sa])
        parts.append(f"{s} ×{grow:.0f} ({grow / ratio:.2f})")
    return f"members ×{ratio:.0f}; per step, cost × (÷ member ratio): " + ", ".join(parts)


def diagnose_at(run: dict, alerts: int = 1000) -> str:
    """The diagnose step once ``alerts`` alerts are stored."""
    i = next((k for k, n in enumerate(run["alerts"]) if n >= alerts), None)
    if i is None:
        return f"never {alerts} alerts (at most {run['alerts'][-1]})"
    xs = run["cpu"]["diagnose"][i:i + 10]
    return (f"{run['members'][i]} members, {run['alerts'][i]} alerts stored (sample {i}): diagnose "
            f"{_ms(xs):.1f} ms mean over the next {len(xs)} samples, max {1e3 * max(xs):.1f} ms")


def commit() -> str:
    """This tree's short commit, ``-dirty`` with uncommitted changes (`provenance.short_version`)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench.eval.provenance import short_version

    return short_version()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[25, 100, 250, 500, 1000], help="nodes")
    ap.add_argument("--samples", type=int, default=90, help="samples per recording (one a second)")
    ap.add_argument("--crash-at", type=int, default=40, help="the sample at which the process dies")
    ap.add_argument("--replay", type=Path, help="replay this recording instead (no synthetic ones)")
    ap.add_argument("--watch", choices=("auto", "all"), default="auto",
                    help="[watchlist] mode: auto (the default: every member up to 2,000, then processes "
                         "and nodes, the rest as the RCA grows) or all (every member)")
    args = ap.parse_args(argv)
    print(f"commit {commit()}, {platform.node()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}; {' '.join(sys.argv)}")
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        config = work / "watch.toml"
        config.write_text(f'[watchlist]\nmode = "{args.watch}"\n')
        if args.replay:
            run = replay(args.replay, work, None, config)
            runs.append((run["nodes"], run))
        for nodes in [] if args.replay else args.sizes:
            path = work / f"g{nodes}.jsonl.gz"
            members, write_ms, group = record(nodes, args.samples, args.crash_at, path)
            run = replay(path, work, args.crash_at, config)
            runs.append((nodes, run))
            print(f"{nodes} nodes, {members} members: samples file {run['size'] / 1e3 / args.samples:.1f} kB "
                  f"a sample, writing it {write_ms:.1f} ms a sample; crash of {group}: "
                  f"{run['alerts'][-1]} alerts; top causes {run['causes'][:3]}", flush=True)
    print()
    print(table(runs))
    print()
    if len(runs) >= 2:
        print(slope(runs))
        print(step_slopes(runs))
    print("RCA update at ~1,000 alerts:", diagnose_at(runs[-1][1]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
