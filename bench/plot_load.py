"""Plot the per-sample curves of `bench_load.py duration` runs (RSS and step time against time).

Needs matplotlib, which the benchmark's peer venv has (never a project dependency):

    bench/.peers-venv/bin/python bench/plot_load.py docs/img/load_500n.png \
        "before=bench/out/load/duration_500n_before.csv" "after=bench/out/load/duration_500n.csv"
"""

from __future__ import annotations

import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main(argv: list[str]) -> int:
    out, runs = argv[0], [a.split("=", 1) for a in argv[1:]]
    fig, (ax_rss, ax_step) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for label, path in runs:
        with open(path) as f:
            rows = list(csv.DictReader(f))
        minutes = [float(r["elapsed_s"]) / 60 for r in rows]
        ax_rss.plot(minutes, [float(r["rss_mb"]) for r in rows], label=label)
        ax_step.plot(minutes, [float(r["step_ms"]) for r in rows], label=label, lw=0.6, alpha=0.8)
    ax_rss.set_ylabel("monitor RSS (MB)")
    ax_rss.axvline(10, color="grey", ls=":", lw=1)
    ax_rss.text(10.2, ax_rss.get_ylim()[0], "θ history full (600 samples)", color="grey", va="bottom")
    ax_step.set_ylabel("one sample (ms, log)")
    ax_step.set_yscale("log")
    ax_step.set_xlabel("minutes of monitoring")
    ax_rss.legend()
    ax_rss.set_title("stream-viz monitor on a 500-node generated system (1 Hz, .rrd written)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
