"""What a user does today: ``ros2 topic hz`` on every topic, and "the first alerting node is it".

A topic is flagged the first time its rate is zero (having been alive) or below ``ratio`` × the
median of its own earlier rates; the culprits are the publishers of the flagged topics in the order
they were flagged (topics flagged in the same sample tie).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

IGNORED = ("topic:/rosout", "topic:/parameter_events")  # event-driven; users know to ignore them


def flag_times(
    rates: Mapping[str, tuple[np.ndarray, np.ndarray]],
    ratio: float = 0.5,
    min_samples: int = 5,
    end: float | None = None,
) -> dict[str, float]:
    """First time each topic looks silent or slow.

    Parameters
    ----------
    rates : mapping
        Topic id → ``(times, rate_hz)``.
    ratio : float
        Flag below this share of the earlier median.
    min_samples : int
        Earlier samples needed before a topic can be flagged (its own warm-up).
    end : float, optional
        End of the run: a topic whose samples stop before it vanished, i.e. is silent from then.
    """
    out: dict[str, float] = {}
    for topic, (t, r) in rates.items():
        if topic in IGNORED:
            continue
        t = np.asarray(t, float)
        r = np.nan_to_num(np.asarray(r, float), nan=0.0)
        for i in range(min_samples, len(r)):
            med = float(np.median(r[:i]))
            if med > 0 and (r[i] <= 0 or r[i] < ratio * med):
                out[topic] = float(t[i])
                break
        else:
            if end is not None and len(t) > min_samples and t[-1] < end - 2.5 and np.median(r) > 0:
                out[topic] = float(t[-1]) + 1.0  # vanished: the next look finds nothing
    return out


def culprits(flags: Mapping[str, float], publishers: Mapping[str, Sequence[str]]) -> list[tuple[str, ...]]:
    """Ranked items (tuples of tied members) : the publishers of flagged topics, first flagged first."""
    by_t: dict[float, list[str]] = {}
    for topic, t in flags.items():
        by_t.setdefault(t, []).append(topic)
    ranked: list[tuple[str, ...]] = []
    for t in sorted(by_t):
        nodes = tuple(dict.fromkeys(n for topic in sorted(by_t[t]) for n in publishers.get(topic, ())))
        if nodes:
            ranked.append(nodes)
    return ranked
