"""Time in the evidence: episodes of alerts, and metric evidence with a since/until like an alert's.

An *episode* of a member is a run of its alerts with gaps of at most ``gap`` seconds: a flapping
symptom (alerts on, off, on) is one episode, and an episode is over once ``gap`` seconds passed
after its last alert. Metric evidence (a process's CPU or memory out of its normal range) gets
the same shape: `Evidence` holds its strength and since when (``since``) and until when
(``until``, None while it lasts) it held, so it is judged in time like an alert.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

INF = float("inf")

Episode = tuple[float, float]  # (first alert, last alert); the end is INF while a state lasts


def merge(times: Sequence[float] | np.ndarray, gap: float) -> list[Episode]:
    """Return the episodes of the sorted alert ``times``: runs whose gaps are at most ``gap``.

    Parameters
    ----------
    times : array-like of float
        Alert times, sorted ascending.
    gap : float
        The longest silence (s) inside one episode.
    """
    out: list[Episode] = []
    for t in times:
        t = float(t)
        if out and t - out[-1][1] <= gap:
            out[-1] = (out[-1][0], t)
        else:
            out.append((t, t))
    return out


def overlaps(episodes: Sequence[Episode], t0: float, t1: float) -> bool:
    """True when one of ``episodes`` meets the interval ``[t0, t1]``."""
    return any(s <= t1 and e >= t0 for s, e in episodes)


@dataclass(frozen=True)
class Evidence:
    """Metric evidence of one member: ``strength`` in [0, 1], held from ``since`` until ``until``.

    ``since`` None: no time known (it counts at any time, as untimed evidence always did);
    ``until`` None: it still holds.
    """

    strength: float
    since: float | None = None
    until: float | None = None

    @property
    def timed(self) -> bool:
        """Whether the evidence has a time (a ``since``)."""
        return self.since is not None

    def episode(self) -> Episode | None:
        """Its episode (``until`` INF while it holds); None when it has no time."""
        if self.since is None:
            return None
        return (self.since, INF if self.until is None else self.until)

    def meets(self, t0: float, t1: float) -> bool:
        """True when it held at some time in ``[t0, t1]`` (always, when it has no time)."""
        ep = self.episode()
        return ep is None or overlaps([ep], t0, t1)


def as_evidence(x: float | Evidence) -> Evidence:
    """Return ``x`` as `Evidence` (a plain number: untimed evidence of that strength)."""
    return x if isinstance(x, Evidence) else Evidence(float(x))


def stamp(
    previous: Mapping[str, Evidence],
    current: Mapping[str, float | Evidence],
    t: float | None,
    keep: float = INF,
) -> dict[str, Evidence]:
    """Return the evidence after an update at time ``t``: what holds now, and what held before.

    A member in ``current`` holds since its ``previous`` entry's ``since`` when that one still
    held, else since ``t``; a member that held in ``previous`` and is missing from ``current``
    ended at ``t``. Ended entries are kept ``keep`` seconds after their end, so a later fault is
    judged against them in time instead of forgetting them. ``t`` None (no time known): plain
    numbers stay untimed. `Evidence` values in ``current`` are taken as they are.

    Parameters
    ----------
    previous : mapping
        The evidence after the last update.
    current : mapping
        Strength per member now (a number in [0, 1], or `Evidence` with its own times).
    t : float or None
        The time of this update.
    keep : float
        Seconds an ended entry is kept (the RCA's window).
    """
    out: dict[str, Evidence] = {}
    for m, x in current.items():
        if isinstance(x, Evidence):
            out[m] = x
            continue
        p = previous.get(m)
        since = p.since if p is not None and p.until is None and p.since is not None else t
        out[m] = Evidence(float(x), since)
    for m, p in previous.items():
        if m in out or p.since is None:
            continue
        until = p.until if p.until is not None else (t if t is not None else p.since)
        if t is None or until >= t - keep:
            out[m] = Evidence(p.strength, p.since, until)
    return out
