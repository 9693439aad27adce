"""The longest run of samples in which a topic's recent rate was below a share of its own median rate.

``.venv/bin/python bench/longest_halving.py [--ratio R] bench/results/*/healthy.jsonl.gz`` reads
recorded samples files (docs/replay.md) and prints, per file, the topics whose recent rate
(``rate_recent_hz``, else ``rate_hz``) stayed below ``R`` (default 0.5: half) × the median of their
previous 60 samples for 2 s or more, longest first, with the spread of their intervals (median
jitter × rate, the ``irregular_cv`` of plugins/topic_rate.py) and their median rate. Behind
``irregular_drop_s`` and the drop ratio of regular topics. With ``--pace``: per file, the lowest
simulation pace (``/clock``'s ``sim_pace``) over its median, behind ``sim_slow_ratio``.
"""

from __future__ import annotations

import sys

import numpy as np

from stream_viz.collect.samples_file import read_samples
from stream_viz.model.theta import SCHEMAS

RATE, RECENT, JITTER, PACE = (SCHEMAS["topic"].index(a)
                              for a in ("rate_hz", "rate_recent_hz", "jitter_ms", "sim_pace"))


def longest_halvings(path: str, ratio: float = 0.5) -> list[tuple[float, str, float, float]]:
    """``(seconds, topic, interval spread, median rate)`` per topic below ``ratio`` × its median for ≥ 2 s."""
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
            if 0 < now < ratio * np.median(past):
                start = a[i, 0] if start is None else start
                longest = max(longest, a[i, 0] - start + 1)
            else:
                start = None
        if longest >= 2:
            spread = float(np.nanmedian(a[:, 3]) / 1000 * np.nanmedian(rate))
            out.append((longest, topic, spread, float(np.nanmedian(rate))))
    return sorted(out, reverse=True)


def lowest_pace(path: str) -> tuple[float, float] | None:
    """``(median pace, lowest pace / median)`` of a recording's ``/clock``; None without one."""
    _, samples, _ = read_samples(path)
    paces = np.array([s.graph.nodes["topic:/clock"]["theta"][PACE] for s in samples
                      if s.graph.nodes.get("topic:/clock", {}).get("theta") is not None], dtype=float)
    paces = paces[np.isfinite(paces)]
    if not len(paces):
        return None
    med = float(np.median(paces))
    return med, float(paces.min()) / med


if __name__ == "__main__":
    args = sys.argv[1:]
    share = 0.5
    if args[:1] == ["--pace"]:
        for p in args[1:]:
            print(p, lowest_pace(p))
        sys.exit(0)
    if args[:1] == ["--ratio"]:
        share, args = float(args[1]), args[2:]
    for p in args:
        print(p)
        for secs, topic, spread, hz in longest_halvings(p, share):
            print(f"  {secs:5.1f} s  {topic}  spread {spread:.2f}  {hz:.2f} Hz")
