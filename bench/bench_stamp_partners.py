"""What listing the topics that share header stamps (`stamp_partners`) adds to a collector sample.

Side by side in one run, alternating: one sample's topic metrics (`TopicWindow` adds of one
second of messages, expire, metrics: what `TopicSubscriber.stats` does per topic) with and without
the stamp partners of every stamped topic (`TopicWindow.newest_stamps` and `stamp_partners`).
Topics: ``--topics`` stamped topics at the demo robot's rates (50, 20, 20, 15, 10 x4, 1 x3 Hz,
repeated), every third triple on one trigger (identical stamps; ``--tick``: every trio's on the
same steps, as simulated time stamps, the worst case), a 3 s window.
Figures are main-thread CPU time (medians); compare the ratio, the machine is shared.

    .venv/bin/python bench/bench_stamp_partners.py --topics 200 --rounds 200
"""

from __future__ import annotations

import argparse
import statistics
import time

from stream_viz.collect.stamp_partners import COMPARED, PAIR_SHARE, stamp_partners
from stream_viz.collect.window import TopicWindow

RATES = (50, 20, 20, 15, 10, 10, 10, 10, 1, 1, 1)
WINDOW_NS = 3_000_000_000
TICK = False


def topics(n: int) -> dict[str, tuple[TopicWindow, int]]:
    """``n`` windows and their rates; topics 3k, 3k+1, 3k+2 of every third k share a trigger."""
    out = {}
    for i in range(n):
        triple = (i // 3) % 3 == 0  # one rate for the three
        out[f"/t{i}"] = (TopicWindow(), RATES[(i // 3 * 3 if triple else i) % len(RATES)])
    return out


def one_sample(ts: dict[str, tuple[TopicWindow, int]], now: int, partners: bool,
               pairs: set[frozenset[str]]) -> float:
    t0 = time.thread_time()
    stamps = {}
    for i, (name, (w, hz)) in enumerate(ts.items()):
        period = 1_000_000_000 // hz
        shared = (i // 3) % 3 == 0
        for k in range(hz):
            recv = now - 1_000_000_000 + k * period + 1_000
            # a trigger's stamp: the same for its three cameras, its own phase per trio (--tick:
            # every stamp on one 1 ms step, as simulated time makes them)
            tick = (recv - 2_000_000) // period * period + (0 if TICK else (i // 3) * 1_000)
            stamp = tick if shared else recv - 2_000_000 - i
            w.add(recv, recv - 500, 1000, None, None, recv - stamp)
        w.expire(now - WINDOW_NS)
        w.metrics(now, 0, WINDOW_NS, 1)
        if partners and w.n_age:
            stamps[name] = w.newest_stamps(COMPARED)
    if partners:
        for t, found in stamp_partners(stamps, pairs).items():
            pairs.update(frozenset((t, u)) for u, share in found.items() if share >= PAIR_SHARE)
    return time.thread_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--topics", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=200)
    ap.add_argument("--tick", action="store_true", help="every trio's stamps on one step (simulated time)")
    a = ap.parse_args()
    global TICK
    TICK = a.tick
    runs = {False: topics(a.topics), True: topics(a.topics)}
    pairs: set[frozenset[str]] = set()
    took: dict[bool, list[float]] = {False: [], True: []}
    now = 10_000_000_000
    for _ in range(a.rounds):
        now += 1_000_000_000
        for partners in (False, True):
            took[partners].append(one_sample(runs[partners], now, partners, pairs))
    base, new = statistics.median(took[False][5:]), statistics.median(took[True][5:])
    print(f"{a.topics} stamped topics, {a.rounds} samples: topic metrics {base * 1e3:.2f} ms a sample, "
          f"with stamp partners {new * 1e3:.2f} ms ({new / base:.2f} x); {len(pairs)} pairs found")


if __name__ == "__main__":
    main()
