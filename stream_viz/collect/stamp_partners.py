"""Topics whose messages carry the same ``header.stamp``: sensors triggered together, a
synchronizer's inputs, a filter passing its input's header on.

A camera trio on one hardware trigger stamps each frame with the trigger's time, so their
stamps are equal to the nanosecond; an approximate-time synchronizer downstream matches them.
When one camera's stamps move (its trigger lost, its clock re-synced), every topic still
publishes at its rate and the synchronizer's output stops: the moved topic no longer shares its
stamps with its partners. Pure: stamps in, partners out.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence, Set

COMPARED = 10  # the newest stamps of each topic compared: 2 s at 5 Hz, O(1) a topic
MIN_STAMPS = 3  # a topic with fewer stamps inside its partner's span is not compared with it
# A stamp this many topics or more carry is a clock's tick (simulated time stamps every sensor on
# its step), not a trigger: not counted, which keeps a sample's cost linear in the topics.
MAX_SHARING = 16
PAIR_SHARE = 0.5  # a pair shares this much of one's stamps at least to be compared from then on


def stamp_partners(stamps: Mapping[str, Sequence[int]], pairs: Set[frozenset[str]] = frozenset(),
                   min_stamps: int = MIN_STAMPS) -> dict[str, dict[str, float]]:
    """Return, per topic, the topics carrying its stamps and the share of its own they carry.

    A topic's stamps are compared with a partner's over the span the partner's stamps cover (its
    newest few may span 2 s where a bursty topic's span 30 s): the share is of the topic's stamps
    inside that span, judged only when ``min_stamps`` are.

    Parameters
    ----------
    stamps : mapping
        Topic -> its newest header stamps (ns), any order.
    pairs : set of frozenset
        Pairs of topics known to have shared stamps (`PAIR_SHARE`): compared even when they now
        share none.
    min_stamps : int
        The least stamps of a topic inside its partner's span for a share.

    Returns
    -------
    dict
        Topic -> {partner: share in [0, 1]}, for partners that share a stamp now (one fewer than
        `MAX_SHARING` topics carry) or are a known pair, where comparable; a topic without any is
        left out.
    """
    sets = {t: set(s) for t, s in stamps.items() if s}
    by_stamp: dict[int, list[str]] = {}
    for t, s in sets.items():
        for x in s:
            by_stamp.setdefault(x, []).append(t)
    for x, ts in by_stamp.items():
        if len(ts) >= MAX_SHARING:
            by_stamp[x] = []
    known: dict[str, set[str]] = {}
    for pair in pairs:
        if len(pair) == 2:
            a, b = tuple(pair)
            known.setdefault(a, set()).add(b)
            known.setdefault(b, set()).add(a)
    spans = {t: (min(s), max(s)) for t, s in sets.items()}
    out: dict[str, dict[str, float]] = {}
    for t, s in sets.items():
        shared: Counter[str] = Counter()
        for x in s:
            shared.update(u for u in by_stamp[x] if u != t)  # [] for a tick of many
        found: dict[str, float] = {}
        for u in sorted(set(shared) | (known.get(t, set()) & sets.keys())):
            lo, hi = spans[u]
            inside = sum(1 for x in s if lo <= x <= hi)
            if inside >= min_stamps:
                found[u] = round(min(shared[u], inside) / inside, 3)
        if found:
            out[t] = found
    return out
