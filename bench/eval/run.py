"""The fault-injection evaluation: plan the runs, run them one after the other, run the peers, report.

``python -m bench.eval.run --short`` (minutes) or ``--full`` (hours); ``--report-only`` rescores
what is already in the output folder. Each run is its own process (bench.eval.run_one); the peers
run in ``bench/.peers-venv``. Results: ``<out>/results.md``, ``scores.csv``, ``summary.json``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from bench.eval.score import (
    BASELINE,
    OURS_LIVE,
    PEERS,
    accuracy_table,
    alerts_before,
    failed_peers,
    fault_matrix,
    fmt,
    latencies,
    score_run,
)

ROOT = Path(__file__).resolve().parents[2]
PEER_PY = ROOT / "bench/.peers-venv/bin/python"
FAULTS = ("crash", "hang", "degrade", "cpu", "leak", "delay", "errlog", "diag")
SHORT_TARGETS = {
    "crash": "/lidar_driver",
    "hang": "/localization",
    "degrade": "/lidar_driver",
    "cpu": "/global_planner",
    "leak": "/map_server",
    "delay": "/obstacle_detector",
    "errlog": "/controller",
    "diag": "/wheel_odometry",
}
FULL_TARGETS = {
    "crash": ("/lidar_driver", "/localization", "/map_server"),
    "hang": ("/localization", "/lidar_driver", "/global_planner"),
    "degrade": ("/lidar_driver", "/imu_driver", "/camera_driver"),
    "cpu": ("/global_planner", "/camera_driver", "/localization"),
    "leak": ("/map_server", "/obstacle_detector", "/controller"),
    "delay": ("/obstacle_detector", "/wheel_odometry", "/local_planner"),
    "errlog": ("/controller", "/lidar_driver", "/battery_monitor"),
    "diag": ("/wheel_odometry", "/map_server", "/local_planner"),
}


def plan(suite: str, warmup: float, post: float, sizes: list[int], reps: int) -> list[dict]:
    """The run specs of a suite (``short`` or ``full``)."""
    from bench.eval.systems import LARGE, pick_targets, system_topology

    base = {"warmup": warmup, "post": post}
    runs: list[dict] = []
    if suite == "short":
        runs += [{"system": "demo", "fault": f, "target": SHORT_TARGETS[f], **base} for f in FAULTS]
        runs += [{"system": "demo", "fault": None, "target": None, "rep": r, **base} for r in range(2)]
        topo = system_topology("gen20", 1)
        runs.append(
            {"system": "gen20", "seed": 1, "fault": "hang", "target": pick_targets(topo, 1)[0], **base}
        )
        return runs
    for r in range(reps):
        runs += [
            {"system": "demo", "fault": f, "target": t, "rep": r, **base}
            for f in FAULTS
            for t in FULL_TARGETS[f]
        ]
        runs.append({"system": "demo", "fault": None, "target": None, "rep": r, **base})
    for n in sizes:
        topo = system_topology(f"gen{n}", 1)
        targets = pick_targets(topo, 1 if n >= LARGE else 2)  # a 500-node run takes ~2 min
        runs += [
            {"system": f"gen{n}", "seed": 1, "fault": f, "target": t, **base} for f in FAULTS for t in targets
        ]
        runs.append({"system": f"gen{n}", "seed": 1, "fault": None, "target": None, **base})
    return runs


def run_id(spec: dict) -> str:
    t = (spec.get("target") or "none").removeprefix("node:").strip("/").replace("/", ".")
    return f"{spec['system']}_{spec.get('fault') or 'nofault'}_{t}_{spec.get('rep', 0)}"


def execute(specs: list[dict], out: Path) -> None:
    """Run every spec not yet done (``run.json`` present), one at a time."""
    for i, spec in enumerate(specs, 1):
        d = out / run_id(spec)
        if (d / "run.json").exists():
            continue
        t0 = time.time()
        print(f"[{i}/{len(specs)}] {run_id(spec)}  load {os.getloadavg()[0]:.1f}", flush=True)
        d.mkdir(parents=True, exist_ok=True)
        with open(d / "log.txt", "w") as log:
            rc = subprocess.run(
                [sys.executable, "-m", "bench.eval.run_one", "--spec", json.dumps(spec), "--out", str(d)],
                cwd=ROOT,
                stdout=log,
                stderr=subprocess.STDOUT,
                timeout=600,
            ).returncode
        print(f"    done rc={rc} in {time.time() - t0:.0f} s", flush=True)
    todo = [
        str(out / run_id(s))
        for s in specs
        if (out / run_id(s) / "run.json").exists() and not (out / run_id(s) / "peers.json").exists()
    ]
    if todo and PEER_PY.exists():
        print(f"peers on {len(todo)} runs …", flush=True)
        subprocess.run([str(PEER_PY), str(ROOT / "bench/eval/peers.py"), *todo], cwd=ROOT, timeout=3600)


def load(out: Path) -> list[tuple[dict, dict | None]]:
    runs = []
    for d in sorted(out.iterdir()):
        if (d / "run.json").exists():
            peers = json.loads((d / "peers.json").read_text()) if (d / "peers.json").exists() else None
            runs.append((json.loads((d / "run.json").read_text()), peers))
    return runs


def report(out: Path) -> str:
    """Score every recorded run; write ``scores.csv``, ``summary.json`` and ``results.md``; return the md."""
    runs = load(out)
    rows = [row for run, peers in runs for row in score_run(run, peers)]
    if rows:
        _write_scores(out / "scores.csv", rows)
    text = results_md(runs, rows)
    (out / "results.md").write_text(text)
    (out / "summary.json").write_text(json.dumps(summary(runs, rows)))
    _write_runs_jsonl(out / "runs.jsonl", runs)
    return text


def results_md(runs: list[tuple[dict, dict | None]], rows: list[dict]) -> str:
    """The text of ``results.md``: accuracy, detection latency, false alerts and cost tables."""
    faulty = [run for run, _ in runs if run["spec"].get("fault")]
    clean = [run for run, _ in runs if not run["spec"].get("fault")]
    loads = [run["loadavg"][0] for run, _ in runs]
    md = [
        f"Runs: {len(faulty)} with a fault, {len(clean)} fault-free; load average (1 min) during runs "
        f"{min(loads, default=0):.1f}–{max(loads, default=0):.1f} on {os.cpu_count()} cores.",
        "",
        *_accuracy_md(rows),
        *_latency_md(faulty),
        *_fault_free_md(clean, faulty),
        *_cost_md([run for run, _ in runs]),
    ]
    fails = failed_peers(p for _, p in runs)
    if fails:
        md += ["", "Peers that failed on some run: " + "; ".join(f"{k}: {v}" for k, v in fails.items())]
    return "\n".join(md) + "\n"


# The per-fault-kind tables of the demo runs: heading, truth level, score.
FAULT_MATRICES = (
    ("AC@1 per fault kind on the demo robot (strict: the target node)", "strict", "AC@1"),
    ("AC@1 per fault kind on the demo robot (as injected: the node for node faults, any node "
     "of its process for crash, cpu and leak)", "injected", "AC@1"),
    ("AC@1 per fault kind on the demo robot (process-level: any node of the target's process)",
     "process", "AC@1"),
    ("AC@3 per fault kind on the demo robot (strict)", "strict", "AC@3"),
)


def _accuracy_md(rows: list[dict]) -> list[str]:
    ours = sorted({r["method"] for r in rows if r["method"].startswith("ours ")})
    main = [OURS_LIVE, "ours both/trajectory", "ours both/pagerank", BASELINE, *PEERS]
    demo = [r for r in rows if r["system"] == "demo"]
    md = [
        "### Accuracy on the demo robot, every method",
        "",
        accuracy_table(demo, [OURS_LIVE, *ours, BASELINE, *PEERS]),
        "",
    ]
    for heading, level, key in FAULT_MATRICES:
        md += [f"### {heading}", "", fault_matrix(demo, main, level, key), ""]
    return [*md, "### Per system", "", accuracy_table(rows, main, by="system"), ""]


def _latency_md(faulty: list[dict]) -> list[str]:
    md = [
        "### Detection latency (s after injection; – = never)",
        "",
        "| system | fault | target | first alert | ours: truth first (strict) | (process) | (as injected) | "
        "rate monitor: first flag |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run in faulty:
        s, la = run["spec"], latencies(run)
        md.append(
            f"| {s['system']} | {s['fault']} | {s['target']} | {fmt(la['first_alert'])} | "
            f"{fmt(la['top1_strict'])} | {fmt(la['top1_process'])} | {fmt(la['top1_injected'])} | "
            f"{fmt(la['baseline_first_flag'])} |"
        )
    return md


def _fault_free_md(clean: list[dict], faulty: list[dict]) -> list[str]:
    """The false alerts: every alert of a fault-free run, and faulty runs' alerts before the injection."""
    md = [
        "",
        "### Fault-free runs (false alerts) and the alerts before injection",
        "",
        "| run | system | duration s | alerts | alerting members | rate-monitor flags |",
        "|---|---|---|---|---|---|",
    ]
    for run in clean:
        members = sorted({a["member"] + " (" + a["plugin"] + ")" for a in run["alerts"]})
        md.append(
            f"| {run_id(run['spec'])} | {run['spec']['system']} | {run['wall_s']:.0f} | "
            f"{len(run['alerts'])} | "
            f"{', '.join(members) or '–'} | {len(run['baseline_flags'])} |"
        )
    pre = [(run, len(alerts_before(run))) for run in faulty if alerts_before(run)]
    return [
        *md,
        "",
        f"Faulty runs with alerts before the injection: {len(pre)} of {len(faulty)}"
        + "".join(f"; {run_id(r['spec'])}: {n}" for r, n in pre),
        "",
    ]


def _cost_md(runs: list[dict]) -> list[str]:
    md = [
        "### Cost of the monitor (in-process, this machine)",
        "",
        "| system | runs | CPU share of one core (mean / max) | peak RSS MB (max) | samples/run |",
        "|---|---|---|---|---|",
    ]
    for system in sorted({run["spec"]["system"] for run in runs}):
        sel = [run for run in runs if run["spec"]["system"] == system]
        cpu = [run["cpu_share"] for run in sel]
        md.append(
            f"| {system} | {len(sel)} | {100 * sum(cpu) / len(cpu):.1f} % / {100 * max(cpu):.1f} % | "
            f"{max(run['peak_rss_mb'] for run in sel):.0f} | "
            f"{sum(run['samples'] for run in sel) / len(sel):.0f} |"
        )
    return md


def summary(runs: list[tuple[dict, dict | None]], rows: list[dict]) -> dict:
    """The content of ``summary.json`` (the plots read it): score rows, latencies, cost per run."""
    return {
        "rows": rows,
        "latency": [
            {"system": r["spec"]["system"], "fault": r["spec"]["fault"], **latencies(r)}
            for r, _ in runs
            if r["spec"].get("fault")
        ],
        "cost": [
            {
                "system": r["spec"]["system"],
                "cpu_share": r["cpu_share"],
                "peak_rss_mb": r["peak_rss_mb"],
                "nodes": r["nodes"],
            }
            for r, _ in runs
        ],
    }


def _write_scores(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _write_runs_jsonl(path: Path, runs: list[tuple[dict, dict | None]]) -> None:
    with open(path, "w") as f:  # one line per run, without the per-tick trace
        for run, peers in runs:
            slim = {k: v for k, v in run.items() if k not in ("ticks", "expand")}
            f.write(json.dumps({**slim, "latency": latencies(run) if run["spec"].get("fault") else None,
                                "peers": peers}) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--short", action="store_const", const="short", dest="suite")
    g.add_argument("--full", action="store_const", const="full", dest="suite")
    ap.add_argument("--out", type=Path, help="output folder (default bench/out/<suite>)")
    ap.add_argument("--warmup", type=float, default=20.0, help="s from ready to the injection")
    ap.add_argument("--post", type=float, default=25.0, help="s monitored after the injection")
    ap.add_argument("--sizes", default="20,100", help="generated system sizes for --full (e.g. 20,100,500)")
    ap.add_argument("--reps", type=int, default=3, help="repetitions of the demo runs in --full")
    ap.add_argument("--only", help="run only these systems (comma list, e.g. demo or gen100)")
    ap.add_argument("--report-only", action="store_true", help="rescore what is in --out")
    ap.add_argument("--plots", type=Path, help="write eval_*.png here (peer venv matplotlib)")
    args = ap.parse_args(argv)
    suite = args.suite or "short"
    out = args.out or ROOT / "bench/out" / suite
    out.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        sizes = [int(x) for x in args.sizes.split(",") if x]
        specs = plan(suite, args.warmup, args.post, sizes, args.reps)
        if args.only:
            specs = [s for s in specs if s["system"] in args.only.split(",")]
        execute(specs, out)
    print(report(out))
    if args.plots and PEER_PY.exists():
        subprocess.run(
            [str(PEER_PY), str(ROOT / "bench/eval/plots.py"), str(out / "summary.json"), str(args.plots)],
            cwd=ROOT,
            check=False,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
