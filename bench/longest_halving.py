"""The longest run of samples in which a topic's recent rate was below half its own median rate.

``.venv/bin/python bench/longest_halving.py bench/results/*/healthy.jsonl.gz`` reads recorded
samples files (docs/replay.md) and prints, per file, the topics whose recent rate
(``rate_recent_hz``, else ``rate_hz``) stayed below half the median of their previous 60 samples
for 2 s or more, longest first, with the spread of their intervals (median jitter × rate, the
``irregular_cv`` of plugins/topic_rate.py) and their median rate. Behind ``irregular_drop_s``.
"""

from __future__ import annotations

import sys

import numpy as np

from stream_viz.collect.samples_file import read_samples
from stream_viz.model.theta import SCHEMAS

RATE, RECENT, JITTER = (SCHEMAS["topic"].index(a) for a in ("rate_hz", "rate_recent_hz", "jitter_ms"))


def longest_halvings(path: str) -> list[tuple[float, str, float, float]]:
    """``(seconds, topic, interval spread, median rate)`` per topic that halved for ≥ 2 s."""
    _, samples, _ = read_samples(path)
    series: dict[str, list[tuple[float, float, float, float]]] = {}
    for s in samples:
        for n, d in s.graph.nodes(data=True):
            th = d.get("theta")
            if d.get("kind") == "topic" and th is not None:
                series.setdefault(n, []).append((s.t, th[RATE], th[RECENT], th[JITTER]))
    out = []
    for topic, rows in series.items():
        a = np.array(rows)
        rate = a[:, 1]
        if np.isfinite(rate).sum() < 40 or np.nanmedian(rate) < 0.5:
            continue
        longest, start = 0.0, None
        for i in range(len(a)):
            past = rate[max(0, i - 60):i]
            past = past[np.isfinite(past)]
            if len(past) < 10:
                continue
            now = a[i, 2] if np.isfinite(a[i, 2]) else a[i, 1]
            if 0 < now < 0.5 * np.median(past):
                start = a[i, 0] if start is None else start
                longest = max(longest, a[i, 0] - start + 1)
            else:
                start = None
        if longest >= 2:
            spread = float(np.nanmedian(a[:, 3]) / 1000 * np.nanmedian(rate))
            out.append((longest, topic, spread, float(np.nanmedian(rate))))
    return sorted(out, reverse=True)


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(p)
        for secs, topic, spread, hz in longest_halvings(p):
            print(f"  {secs:5.1f} s  {topic}  spread {spread:.2f}  {hz:.2f} Hz")
