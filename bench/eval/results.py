"""The results page (``results.md``) and ``summary.json`` of a suite, from its recorded runs (pure)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from statistics import median

from bench.eval.score import (
    BASELINE,
    OURS_LIVE,
    PEERS,
    accuracy_table,
    alerts_before,
    failed_peers,
    fault_matrix,
    floor_rows,
    fmt,
    latencies,
    sweep_rows,
)
from bench.eval.suites import run_id

Runs = Sequence[tuple[dict, dict | None]]  # (run.json, peers.json or None) per run
ROBOTS = {"demo": "the demo robot", "amr": "the warehouse AMR"}


def results_md(runs: Runs, rows: list[dict]) -> str:
    """The text of ``results.md``: accuracy, latency, false alerts, the sweep and the cost."""
    all_runs = [run for run, _ in runs]
    faulty = [run for run in all_runs if run["spec"].get("fault")]
    clean = [run for run in all_runs if not run["spec"].get("fault")]
    loads = [run["loadavg"][0] for run in all_runs]
    sweep = sweep_rows(faulty)
    md = [
        f"Runs: {len(faulty)} with a fault, {len(clean)} fault-free; load average (1 min) during runs "
        f"{min(loads, default=0):.1f}–{max(loads, default=0):.1f} on {os.cpu_count()} cores.",
        "",
        *_code_md(all_runs),
        *_accuracy_md([r for r in rows if not _sized(r)]),
        *_latency_md([run for run in faulty if run["spec"].get("size") is None]),
        *_fault_free_md(clean),
        *_early_md(faulty),
        *_control_md([run for run in clean if run["spec"].get("control")]),
        *(_sweep_md(sweep) if sweep else []),
        *_cost_md(all_runs),
    ]
    fails = failed_peers(p for _, p in runs)
    if fails:
        md += ["", "Peers that failed on some run: " + "; ".join(f"{k}: {v}" for k, v in fails.items())]
    return "\n".join(md) + "\n"


def _sized(row: Mapping) -> bool:
    return row.get("size") not in (None, "")


def _code_md(runs: list[dict]) -> list[str]:
    """Which code the runs measured (commit, uncommitted changes) and on which machine."""
    commits: dict[str, int] = {}
    for run in runs:
        code = run.get("code") or {}
        key = (code.get("commit") or "unknown")[:10] + (" + uncommitted changes" if code.get("dirty") else "")
        commits[key] = commits.get(key, 0) + 1
    machines = {tuple(sorted((run.get("machine") or {}).items())) for run in runs}
    md = ["Code: " + "; ".join(f"{k} ({n} runs)" for k, n in sorted(commits.items())) + "."]
    for m in sorted(machines):
        if m:
            d = dict(m)
            md.append(f"Machine: {d.get('cores')} cores ({d.get('cpu')}), {d.get('ram_gb')} GB RAM, "
                      f"{d.get('os')}, Python {d.get('python')}.")
    return [*md, ""]


def _fault_matrices(robot: str) -> tuple[tuple[str, str, str], ...]:
    """The per-fault-kind tables of a robot's runs: heading, truth level, score."""
    name = ROBOTS.get(robot, robot)
    return (
        (f"AC@1 per fault kind on {name} (strict: the target node)", "strict", "AC@1"),
        (f"AC@1 per fault kind on {name} (as injected: the node for node faults, any node "
         "of its process for crash, cpu and leak)", "injected", "AC@1"),
        (f"AC@1 per fault kind on {name} (process-level: any node of the target's process)",
         "process", "AC@1"),
        (f"AC@3 per fault kind on {name} (strict)", "strict", "AC@3"),
    )


def _accuracy_md(rows: list[dict]) -> list[str]:
    ours = sorted({r["method"] for r in rows if r["method"].startswith("ours ")})
    main = [OURS_LIVE, "ours both/trajectory", "ours both/pagerank", BASELINE, *PEERS]
    md: list[str] = []
    for robot in [r for r in ROBOTS if any(x["system"] == r for x in rows)]:
        sel = [r for r in rows if r["system"] == robot]
        md += [f"### Accuracy on {ROBOTS[robot]}, every method", "",
               accuracy_table(sel, [OURS_LIVE, *ours, BASELINE, *PEERS]), ""]
        for heading, level, key in _fault_matrices(robot):
            md += [f"### {heading}", "", fault_matrix(sel, main, level, key), ""]
    if not rows:
        return md
    return [*md, "### Per system", "", accuracy_table(rows, main, by="system"), ""]


def _latency_md(faulty: list[dict]) -> list[str]:
    if not faulty:
        return []
    md = [
        "### Detection latency (s after injection; – = never)",
        "",
        "| system | fault | target | first alert | detected (reach) | ours: truth first (strict) | "
        "(process) | (as injected) | rate monitor: first flag |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    firsts: dict[tuple[str, str], list[float]] = {}
    for run in faulty:
        s, la = run["spec"], latencies(run)
        md.append(
            f"| {s['system']} | {s['fault']} | {s['target']} | {fmt(la['first_alert'])} | "
            f"{fmt(la['detected'])} | {fmt(la['top1_strict'])} | {fmt(la['top1_process'])} | "
            f"{fmt(la['top1_injected'])} | {fmt(la['baseline_first_flag'])} |"
        )
        for key in ("first_alert", "detected"):
            if la[key] is not None:
                firsts.setdefault((s["system"], key), []).append(la[key])
    md += ["", "Median s after injection (runs with one / faulty runs):"]
    for system in sorted({r["spec"]["system"] for r in faulty}):
        n = sum(1 for r in faulty if r["spec"]["system"] == system)
        parts = [f"{label} {median(v):.1f} s ({len(v)}/{n})" if (v := firsts.get((system, key))) else
                 f"{label} – (0/{n})" for key, label in (("first_alert", "first alert"),
                                                          ("detected", "detected (reach)"))]
        md.append(f"- {system}: " + ", ".join(parts))
    return md


def _fault_free_md(clean: list[dict]) -> list[str]:
    """The false alerts of the fault-free runs (every alert of such a run is one)."""
    if not clean:
        return []
    md = [
        "",
        "### Fault-free runs (false alerts)",
        "",
        "| run | system | duration s | alerts | alerting members | rate-monitor flags |",
        "|---|---|---|---|---|---|",
    ]
    for run in clean:
        md.append(
            f"| {run_id(run['spec'])} | {run['spec']['system']} | {run['wall_s']:.0f} | "
            f"{len(run['alerts'])} | {_members(run['alerts']) or '–'} | {len(run['baseline_flags'])} |"
        )
    return [*md, ""]


def _early_md(faulty: list[dict]) -> list[str]:
    """The false alerts of the faulty runs: those at least a sample before the injection."""
    if not faulty:
        return []
    md = [
        "",
        "### Alerts before the injection in the faulty runs (every run)",
        "",
        "| system | faulty runs | runs with alerts before | alerts before | alerting members |",
        "|---|---|---|---|---|",
    ]
    pre = {id(run): alerts_before(run) for run in faulty}
    for system in sorted({run["spec"]["system"] for run in faulty}):
        sel = [run for run in faulty if run["spec"]["system"] == system]
        early = [a for run in sel for a in pre[id(run)]]
        md.append(f"| {system} | {len(sel)} | {sum(1 for run in sel if pre[id(run)])} | {len(early)} | "
                  f"{_members(early) or '–'} |")
    return [
        *md,
        "",
        f"Faulty runs with alerts before the injection: {sum(1 for run in faulty if pre[id(run)])} of "
        f"{len(faulty)}" + "".join(f"; {run_id(r['spec'])}: {len(pre[id(r)])}" for r in faulty if pre[id(r)]),
        "",
    ]


def _members(alerts: list[Mapping]) -> str:
    """``member (plugin) ×n`` for each alerting member and plugin."""
    count: dict[str, int] = {}
    for a in alerts:
        key = f"{a['member']} ({a['plugin']})"
        count[key] = count.get(key, 0) + 1
    return ", ".join(k + (f" ×{n}" if n > 1 else "") for k, n in sorted(count.items()))


def _control_md(control: list[dict]) -> list[str]:
    """Every alert of each healthy-dynamics control run (each is a false alert)."""
    md: list[str] = []
    for run in control:
        t0 = run["t_ready"]
        md += [f"### Healthy-dynamics control run {run_id(run['spec'])}: {len(run['alerts'])} alerts "
               f"in {run['wall_s']:.0f} s (0 is the goal)", ""]
        if run["alerts"]:
            md += ["| s after ready | member | plugin | severity | message |", "|---|---|---|---|---|"]
            md += [f"| {a['t'] - t0:.0f} | {a['member']} | {a['plugin']} | {a.get('severity', '')} | "
                   f"{a['message'][:100].replace('|', '/')} |" for a in run["alerts"]]
        md.append("")
    return md


def _sweep_md(sweep: list[dict]) -> list[str]:
    md = [
        "### Fault size sweep (per run; weakest size first)",
        "",
        "| system | fault | target | size | detected s | first alert s | live rank strict | "
        "live rank process | truth first s (process) | alerts before |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    md += [f"| {r['system']} | {r['fault']} | {r['target']} | {r['size']:g} | {fmt(r['detected'])} | "
           f"{fmt(r['first_alert'])} | {fmt(r['rank_strict'])} | {fmt(r['rank_process'])} | "
           f"{fmt(r['top1_process'])} | {r['alerts_before']} |" for r in sweep]
    md += [
        "",
        "### Detection floor per fault kind",
        "",
        "| system | fault | target | sizes run (weakest first) | weakest detected | its detection s | "
        "its live rank (strict / process) | weakest ranked first (process) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    md += [f"| {r['system']} | {r['fault']} | {r['target']} | {', '.join(f'{s:g}' for s in r['sizes'])} | "
           f"{_size(r['weakest_detected'])} | {fmt(r['detected_s'])} | "
           f"{fmt(r['rank_strict'])} / {fmt(r['rank_process'])} | {_size(r['weakest_first'])} |"
           for r in floor_rows(sweep)]
    return [*md, ""]


def _size(x: float | None) -> str:
    return "none" if x is None else f"{x:g}"


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


def summary(runs: Runs, rows: list[dict]) -> dict:
    """The content of ``summary.json`` (the plots read it): score rows, latencies, the sweep, cost per run."""
    faulty = [r for r, _ in runs if r["spec"].get("fault")]
    sweep = sweep_rows(faulty)
    return {
        "rows": rows,
        "latency": [
            {"system": r["spec"]["system"], "fault": r["spec"]["fault"], "size": r["spec"].get("size"),
             **latencies(r)}
            for r in faulty
        ],
        "sweep": sweep,
        "floor": floor_rows(sweep),
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
