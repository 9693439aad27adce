"""The θ history store: memory and time, the ring (``stream_viz.model.history``) beside a deque.

The deque of ``(t, θ)`` tuples is what History was before; both hold the last ``--maxlen``
samples of ``--members`` members (θ of 8 numbers, like a topic's). Measured in one run, side by
side: memory held (tracemalloc, in a separate pass), time to add one sample, time to read the
newest 120 samples of every member (what baselines and process checks read).

Run: ``.venv/bin/python bench/bench_history.py`` (a few seconds).
"""

from __future__ import annotations

import argparse
import os
import time
import tracemalloc
from collections import deque

import numpy as np

from stream_viz.model.history import History


class DequeHistory:
    """The reference: one deque of (t, θ) per member, stacked on read."""

    def __init__(self, maxlen: int) -> None:
        self.maxlen = maxlen
        self.q: dict[str, deque] = {}

    def add(self, m: str, t: float, theta: np.ndarray) -> None:
        self.q.setdefault(m, deque(maxlen=self.maxlen)).append((t, theta))

    def times(self, m: str, last: int | None = None) -> np.ndarray:
        return np.array([t for t, _ in list(self.q[m])[-last:]])

    def values(self, m: str, last: int | None = None) -> np.ndarray:
        return np.vstack([v for _, v in list(self.q[m])[-last:]])


def fill(h, members: int, samples: int, thetas: list[np.ndarray]) -> float:
    t0 = time.perf_counter()
    for t in range(samples):
        for k in range(members):
            h.add(f"m{k}", float(t), thetas[k] + t)
    return (time.perf_counter() - t0) / (samples * members)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=1000)
    ap.add_argument("--maxlen", type=int, default=600)
    args = ap.parse_args()
    thetas = [np.random.default_rng(k).random(8) for k in range(args.members)]
    print(f"history: {args.members} members x {args.maxlen} samples, θ of 8 numbers, {os.cpu_count()} cores")
    print(f"{'store':>8} {'MB held':>8} {'add µs':>7} {'read 120 ms (all members)':>26}")
    res = {}
    for name, cls in (("ring", History), ("deque", DequeHistory)):
        tracemalloc.start()
        h = cls(maxlen=args.maxlen)
        fill(h, args.members, args.maxlen, thetas)
        mb = tracemalloc.get_traced_memory()[0] / 2**20
        tracemalloc.stop()
        del h
        h = cls(maxlen=args.maxlen)
        add = fill(h, args.members, args.maxlen, thetas)
        t0 = time.perf_counter()
        for k in range(args.members):
            h.times(f"m{k}", 120)
            h.values(f"m{k}", 120)
        read = time.perf_counter() - t0
        res[name] = (mb, add, read)
        print(f"{name:>8} {mb:8.1f} {1e6 * add:7.2f} {1e3 * read:26.1f}")
    r, d = res["ring"], res["deque"]
    print(f"ring / deque: memory {r[0] / d[0]:.2f}x, add {r[1] / d[1]:.2f}x, read {r[2] / d[2]:.2f}x")


if __name__ == "__main__":
    main()
