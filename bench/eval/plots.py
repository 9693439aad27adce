"""Plots of the evaluation (run in the peer venv, which has matplotlib): summary.json → eval_*.png."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

MAIN = [
    "stream-viz (live)",
    "ours both/trajectory",
    "ours downstream/trajectory",
    "ours upstream/trajectory",
    "ours both/pagerank",
    "ours both/hypothesis",
    "ours both/count",
    "rate monitor + first alert",
    "BARO",
    "n-sigma",
    "ε-Diagnosis",
    "PyRCA-HT",
    "PyRCA-RW",
]


def mean(xs):
    xs = list(xs)
    return sum(xs) / len(xs) if xs else float("nan")


ROBOTS = {"demo": ("eval_", "the demo robot"), "amr": ("eval_amr_", "the warehouse AMR")}


def main(summary_path: str, out_dir: str) -> int:
    s = json.loads(Path(summary_path).read_text())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [r for r in s["rows"] if r.get("size") is None]  # not the sweep's sized runs
    lat = [x for x in s["latency"] if x.get("size") is None]
    pick: list[str] = []
    for robot, (prefix, name) in ROBOTS.items():
        if any(r["system"] == robot for r in rows):
            pick = robot_plots([r for r in rows if r["system"] == robot],
                               [x for x in lat if x["system"] == robot], out, prefix, name)
    size_plot(rows, pick, out)
    return 0


def robot_plots(rows: list[dict], lat: list[dict], out: Path, prefix: str, name: str) -> list[str]:
    """Accuracy per method, AC@1 per fault kind, detection latency per fault kind of one robot's runs."""
    methods = [m for m in MAIN if any(r["method"] == m for r in rows)]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    w = 0.16
    for i, (key, level) in enumerate(
        [("AC@1", "strict"), ("AC@1", "injected"), ("AC@1", "process"), ("AC@3", "strict"),
         ("Avg@5", "strict")]
    ):
        vals = [mean(r[key] for r in rows if r["method"] == m and r["level"] == level) for m in methods]
        ax.bar([j + (i - 2) * w for j in range(len(methods))], vals, w, label=f"{key} {level}")
    ax.set_xticks(range(len(methods)), methods, rotation=35, ha="right", fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.axhline(0.9, color="grey", lw=0.8, ls="--")
    ax.set_title(f"Root-cause accuracy on {name} (same runs for every method)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"{prefix}accuracy.png", dpi=110)
    plt.close(fig)

    faults = sorted({r["fault"] for r in rows})
    pick = [
        m
        for m in ["stream-viz (live)", "rate monitor + first alert", "BARO", "PyRCA-HT", "n-sigma"]
        if m in methods
    ]
    fig, ax = plt.subplots(figsize=(10, 4))
    w = 0.8 / max(1, len(pick))
    for i, m in enumerate(pick):
        vals = [
            mean(r["AC@1"] for r in rows if r["method"] == m and r["fault"] == f and r["level"] == "strict")
            for f in faults
        ]
        ax.bar([j + (i - (len(pick) - 1) / 2) * w for j in range(len(faults))], vals, w, label=m)
    ax.set_xticks(range(len(faults)), faults, fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_title(f"AC@1 (strict) per fault kind, {name}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"{prefix}per_fault.png", dpi=110)
    plt.close(fig)

    faults = sorted({x["fault"] for x in lat})
    fig, ax = plt.subplots(figsize=(10, 4))
    series = [
        ("first_alert", "first alert"),
        ("top1_strict", "ours: target ranked first"),
        ("top1_process", "ours: target's process first"),
        ("baseline_first_flag", "rate monitor: first flag"),
    ]
    w = 0.2
    for i, (key, label) in enumerate(series):
        vals = [mean(x[key] for x in lat if x["fault"] == f and x.get(key) is not None) for f in faults]
        ax.bar([j + (i - 1.5) * w for j in range(len(faults))], vals, w, label=label)
    ax.set_xticks(range(len(faults)), faults, fontsize=8)
    ax.set_ylabel("s after injection (missing bar: never)")
    ax.axhline(3, color="grey", lw=0.8, ls="--")
    ax.set_title(f"Detection latency, {name}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"{prefix}latency.png", dpi=110)
    plt.close(fig)
    return pick


def size_plot(rows: list[dict], pick: list[str], out: Path) -> None:
    """AC@1 (strict) against system size: the demo robot, then the generated systems by size."""
    systems = sorted({r["system"] for r in rows if r["system"] == "demo" or r["system"].startswith("gen")},
                     key=lambda x: (x != "demo", int(x[3:]) if x != "demo" else 0))
    if len(systems) < 2:
        return
    fig, ax = plt.subplots(figsize=(7, 4))
    for m in [m for m in MAIN if any(r["method"] == m for r in rows)][:1] + pick[1:]:
        vals = [
            mean(r["AC@1"] for r in rows if r["method"] == m and r["system"] == sy and r["level"] == "strict")
            for sy in systems
        ]
        ax.plot(systems, vals, marker="o", label=m)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("AC@1 (strict)")
    ax.set_title("Accuracy against system size")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "eval_size.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
